"""Live Rerun viewers for ``corraoi record``: probe a running one, spawn one, serve the web one.

Kept apart from the sinks: these start processes and open sockets. Nothing here imports
rerun at module level.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import TracebackType
from urllib.parse import quote, urlsplit

from corraoi.errors import UsageError, ViewerError
from corraoi.forked import death_signal

DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090
DEFAULT_URL = f"rerun+http://127.0.0.1:{DEFAULT_GRPC_PORT}/proxy"
_SCHEMES = {"rerun": 443, "rerun+http": 80, "rerun+https": 443}


def normalize_url(url: str) -> str:
    """A viewer URL, accepting a bare port (``9876``) as ``rerun+http://127.0.0.1:9876/proxy``."""
    text = url.strip()
    if text.isdigit():
        port = int(text)
        if not 0 < port < 65536:
            raise UsageError(f"--connect: port {port} is out of range")
        return f"rerun+http://127.0.0.1:{port}/proxy"
    parts = urlsplit(text)
    try:
        parts.port  # noqa: B018 - validates the port
    except ValueError:
        raise UsageError(f"--connect {url}: the port is not a number in 1..65535") from None
    if parts.scheme not in _SCHEMES or not parts.hostname or parts.path != "/proxy":
        raise UsageError(
            f"--connect {url}: expected a Rerun viewer URL such as {DEFAULT_URL} "
            "(scheme rerun+http, rerun+https or rerun; path /proxy) or a port number"
        )
    return text


def probe(url: str, *, timeout: float = 2.0) -> str | None:
    """Try a TCP connection to the viewer at ``url``; None if it answers, else why not."""
    parts = urlsplit(url)
    host = parts.hostname or "127.0.0.1"
    port = parts.port or _SCHEMES.get(parts.scheme, 80)
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None
    except TimeoutError:
        return f"no answer within {timeout:g} s"
    except OSError as exc:
        return (exc.strerror or str(exc)).lower()


def display_problem() -> str | None:
    """Why a native viewer window cannot open here (None if it probably can)."""
    if sys.platform.startswith("linux") or "bsd" in sys.platform:
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
            return "no display (DISPLAY and WAYLAND_DISPLAY are not set)"
    return None


def rerun_executable() -> str:
    """The ``rerun`` command of this environment (beside the Python running us, else PATH)."""
    beside = Path(sys.executable).parent / ("rerun.exe" if os.name == "nt" else "rerun")
    if beside.exists():
        return str(beside)
    return shutil.which("rerun") or "rerun"


def rerun_binary() -> str:
    """The Rerun binary itself (not the Python wrapper script, which does not pass signals on)."""
    try:
        import rerun_cli

        exe = Path(rerun_cli.__file__).parent / ("rerun.exe" if os.name == "nt" else "rerun")
        if exe.exists():
            return str(exe)
    except ImportError:
        pass
    return rerun_executable()


def view_command(paths: list[str]) -> str:
    """The shell command that opens ``paths`` in the Rerun viewer."""
    import shlex

    exe = rerun_executable()
    if shutil.which("rerun") == exe:
        exe = "rerun"  # on PATH: the plain name
    elif os.path.isabs(exe):
        try:
            rel = os.path.relpath(exe)
            if not rel.startswith(".."):
                exe = rel if os.sep in rel else f".{os.sep}{rel}"
        except ValueError:  # another drive (Windows)
            pass
    return " ".join(shlex.quote(p) for p in [exe, *paths])


def spawn_viewer(*, port: int = DEFAULT_GRPC_PORT) -> str:
    """Start the native viewer (or reuse one on ``port``); returns the URL to stream to."""
    problem = display_problem()
    if problem:
        raise ViewerError(f"--spawn: {problem}, so no viewer was started")
    from rerun.sinks import spawn

    try:
        spawn(port=port, connect=False, executable_path=rerun_executable())
    except Exception as exc:  # noqa: BLE001 - rerun raises several kinds here
        raise ViewerError(f"--spawn: cannot start the Rerun viewer: {exc}") from None
    return f"rerun+http://127.0.0.1:{port}/proxy"


def free_port(preferred: int, host: str = "127.0.0.1") -> int:
    """``preferred`` if nothing listens there, else a free port the OS picks."""
    for candidate in (preferred, 0):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((host, candidate))
            except OSError:
                continue
            return int(s.getsockname()[1])
    raise ViewerError("no free TCP port on 127.0.0.1")


class WebViewer:
    """``rerun --serve-web`` bound to 127.0.0.1: a gRPC proxy plus the web viewer.

    ``with WebViewer() as web: ...stream to web.grpc_url...; web.wait()``. The server is
    a child process, stopped when the ``with`` block ends.
    """

    def __init__(self, *, web_port: int = DEFAULT_WEB_PORT, grpc_port: int = DEFAULT_GRPC_PORT):
        self.grpc_port = free_port(grpc_port)
        self.web_port = web_port if web_port == 0 else free_port(web_port)
        if self.web_port == self.grpc_port:
            self.web_port = free_port(0)
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def grpc_url(self) -> str:
        return f"rerun+http://127.0.0.1:{self.grpc_port}/proxy"

    @property
    def web_url(self) -> str:
        return f"http://127.0.0.1:{self.web_port}/?url={quote(self.grpc_url, safe='')}"

    def start(self, *, timeout: float = 15.0) -> WebViewer:
        cmd = [
            rerun_binary(),
            "--serve-web",
            "--bind",
            "127.0.0.1",
            "--port",
            str(self.grpc_port),
            "--web-viewer-port",
            str(self.web_port),
        ]
        env = dict(os.environ, RERUN_APP_ONLY="true")
        env.setdefault("RUST_LOG", "warn")
        try:
            self.process = subprocess.Popen(
                cmd,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env=env,
                start_new_session=True,  # Ctrl-C goes to us; we stop the server ourselves
                preexec_fn=death_signal(signal.SIGTERM),  # dies with us, even by SIGKILL
            )
        except OSError as exc:
            raise ViewerError(f"--serve-web: cannot run {cmd[0]}: {exc.strerror or exc}") from None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                code = self.process.returncode
                raise ViewerError(f"--serve-web: the Rerun web server exited with status {code}")
            if probe(self.grpc_url, timeout=0.5) is None and (
                probe(f"rerun+http://127.0.0.1:{self.web_port}/proxy", timeout=0.5) is None
            ):
                return self
            time.sleep(0.1)
        self.stop()
        raise ViewerError(f"--serve-web: the Rerun web server did not start within {timeout:g} s")

    def wait(self) -> None:
        """Block until the server exits (or Ctrl-C)."""
        if self.process is not None:
            self.process.wait()

    def stop(self) -> None:
        proc, self.process = self.process, None
        if proc is None or proc.poll() is not None:
            return
        _signal_group(proc, signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            _signal_group(proc, signal.SIGKILL)
            proc.wait()

    def __enter__(self) -> WebViewer:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


def _signal_group(proc: subprocess.Popen[bytes], sig: int) -> None:
    """Signal the server's process group (it runs in its own session), else the process."""
    try:
        os.killpg(proc.pid, sig)
    except (AttributeError, ProcessLookupError, PermissionError):
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            pass
