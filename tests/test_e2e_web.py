"""End to end in a real viewer: ``corraoi compare --serve-web`` opened in headless Chromium.

The Rerun web viewer bundled in rerun-sdk is served on 127.0.0.1 by ``corraoi compare
--serve-web``; headless Chromium (Debian's ``chromium``, driven over the DevTools protocol
on a pipe: no extra Python package) opens it, and the screenshot must look like a
comparison a person can read: every run's series colour, the success and failure markers,
the arms' colours in the means panels and enough drawn (non-background) pixels -- a blank,
error or welcome page has none of them. The test stops the browser and the server itself
and checks that the ports are closed again.

``CORRAOI_SCREENSHOT_TO=docs/compare-screenshot.png pytest tests/test_e2e_web.py`` also
keeps the screenshot (as a 256-colour palette PNG).
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from urllib.parse import unquote, urlsplit

import numpy as np
import pytest

from recorder import style

POLICIES = ("ucb", "ts", "cts-gauss")  # colours unlike any arm, success or failure colour
WIDTH, HEIGHT = 1400, 900
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str:
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    pytest.skip(
        "no Chromium found (looked for " + ", ".join(CHROMIUM_NAMES) + "); .ci/run installs "
        "Debian's chromium where it can (apt-get install chromium)"
    )


class Chromium:
    """Headless Chromium driven over ``--remote-debugging-pipe`` (fds 3 and 4)."""

    def __init__(self, exe: str, extra_args: list[str] | None = None) -> None:
        self.profile = tempfile.mkdtemp(prefix="corraoi-chromium-")
        to_r, self._to_w = os.pipe()
        self._from_r, from_w = os.pipe()

        def child_fds() -> None:  # runs in the child: put the pipe ends at fds 3 and 4
            a, b = os.dup(to_r), os.dup(from_w)
            os.dup2(a, 3)
            os.dup2(b, 4)

        self.proc = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--enable-unsafe-swiftshader",
             "--use-angle=swiftshader", "--remote-debugging-pipe", "--no-first-run",
             "--disable-dev-shm-usage", f"--user-data-dir={self.profile}",
             f"--window-size={WIDTH},{HEIGHT}", *(extra_args or []), "about:blank"],
            preexec_fn=child_fds,
            close_fds=False,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )  # fmt: skip
        os.close(to_r)
        os.close(from_w)
        self._buf = b""
        self._id = 0
        self.session = ""

    def call(self, method: str, params: dict | None = None, *, timeout: float = 30) -> dict:
        self._id += 1
        msg: dict = {"id": self._id, "method": method, "params": params or {}}
        if self.session:
            msg["sessionId"] = self.session
        os.write(self._to_w, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + timeout
        while True:
            while b"\0" not in self._buf:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"Chromium did not answer {method}")
                chunk = os.read(self._from_r, 1 << 20)
                if not chunk:
                    raise RuntimeError("Chromium closed the DevTools pipe")
                self._buf += chunk
            line, self._buf = self._buf.split(b"\0", 1)
            reply = json.loads(line)
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def open(self, url: str) -> None:
        target = self.call("Target.createTarget", {"url": "about:blank"})["targetId"]
        self.session = self.call("Target.attachToTarget", {"targetId": target, "flatten": True})[
            "sessionId"
        ]
        metrics = {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False}
        self.call("Emulation.setDeviceMetricsOverride", metrics)
        self.call("Page.navigate", {"url": url})

    def screenshot(self, clip: dict | None = None) -> bytes:
        """The page (or the ``clip`` rectangle: x, y, width, height in CSS pixels) as PNG."""
        params: dict = {"format": "png"}
        if clip is not None:
            params["clip"] = {**clip, "scale": 1}
        return base64.b64decode(self.call("Page.captureScreenshot", params)["data"])

    def close(self) -> None:
        try:
            self.session = ""
            self.call("Browser.close", timeout=5)
        except Exception:  # noqa: BLE001 - it may be gone already
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        for fd in (self._to_w, self._from_r):
            try:
                os.close(fd)
            except OSError:
                pass
        shutil.rmtree(self.profile, ignore_errors=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _pixels(png: bytes) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def colour_pixels(png: bytes, rgb: tuple[int, int, int], tol: int = 14) -> int:
    img = _pixels(png)
    return int((np.abs(img - np.array(rgb, dtype=np.int16)) <= tol).all(axis=2).sum())


def drawn_share(png: bytes) -> float:
    """Share of pixels that differ from the page background (its most common colour)."""
    flat = _pixels(png).reshape(-1, 3)
    values, counts = np.unique(flat, axis=0, return_counts=True)
    background = values[counts.argmax()]
    return float((np.abs(flat - background).max(axis=1) > 24).mean())


#: What a readable compare screenshot shows besides the run colours: (name, colour).
MARKS = (
    ("success marker", style.SUCCESS_COLOR),
    ("failure marker", style.FAILURE_COLOR),
    *((f"arm {k + 1}", style.arm_color(k)) for k in range(4)),
)


@pytest.mark.slow
def test_compare_shows_every_run_in_the_web_viewer(tmp_path, record_mcap):
    exe = find_chromium()
    logs = [str(record_mcap(p, seed=2, horizon=1500)[0]) for p in POLICIES]
    web_port = free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "corraoi.cli", "compare", *logs, "--serve-web",
         "--web-port", str(web_port)],
        cwd=tmp_path,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )  # fmt: skip
    lines: list[str] = []
    ready = threading.Event()

    def read_stderr() -> None:
        assert server.stderr is not None
        for line in server.stderr:
            lines.append(line)
            if line.startswith("serving the web viewer at"):
                ready.set()

    threading.Thread(target=read_stderr, daemon=True).start()
    browser = None
    grpc_port = None
    try:
        assert ready.wait(60), "".join(lines) or "corraoi compare --serve-web said nothing"
        url = lines[-1].split(" at ", 1)[1].split(" (Ctrl-C", 1)[0].strip()
        parts = urlsplit(url)
        assert parts.hostname == "127.0.0.1" and parts.port == web_port
        grpc_url = unquote(parts.query.split("url=", 1)[1])
        grpc_port = urlsplit(grpc_url).port
        assert urlsplit(grpc_url).hostname == "127.0.0.1"
        assert listening(web_port) and grpc_port and listening(grpc_port)
        browser = Chromium(exe)
        browser.open(url)
        wanted = {p: style.policy_color(p) for p in POLICIES} | dict(MARKS)
        found: dict[str, int] = {}
        png = b""
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            time.sleep(2)
            png = browser.screenshot()
            found = {p: colour_pixels(png, rgb) for p, rgb in wanted.items()}
            if all(n >= 40 for n in found.values()):
                time.sleep(2)  # let the last panels finish drawing
                png = browser.screenshot()
                found = {p: colour_pixels(png, rgb) for p, rgb in wanted.items()}
                break
        (tmp_path / "compare.png").write_bytes(png)
        keep = os.environ.get("CORRAOI_SCREENSHOT_TO")
        if keep:
            from PIL import Image

            Image.open(tmp_path / "compare.png").convert("RGB").quantize(colors=256).save(
                keep, optimize=True
            )
        missing = {p: n for p, n in found.items() if n < 40}
        assert not missing, f"colours missing from the screenshot: {missing} (all: {found})"
        # a page with a few coloured dots is not a comparison: most of a blank, error or
        # welcome page is background, a drawn compare view has about 8% other pixels
        share = drawn_share(png)
        assert share >= 0.04, f"the screenshot is nearly blank ({share:.1%} drawn pixels)"
    finally:
        if browser is not None:
            browser.close()
        if server.poll() is None:
            server.send_signal(signal.SIGINT)  # corraoi stops the web viewer it started
            try:
                server.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(server.pid, signal.SIGKILL)
                server.wait()
    assert server.returncode == 0, "".join(lines)
    time.sleep(0.5)
    assert not listening(web_port), "the web viewer is still serving after Ctrl-C"
    assert grpc_port is not None and not listening(grpc_port), "the gRPC server is still up"
