"""The Rerun viewer that :func:`corraoi.show`, ``Run.show`` and ``Sweep.show`` open on
existing ``.rrd`` files (nothing is simulated), and the :class:`Shown` handle. Where:

* in Jupyter (an IPython kernel runs this): the viewer as a widget (``rerun-notebook``, the
  ``notebook`` extra), its JavaScript and WebAssembly served from the installed package on
  127.0.0.1, so no network is needed;
* elsewhere: the Rerun web viewer served on 127.0.0.1 by a ``rerun --serve-web`` child
  process (:class:`corraoi.recorder.live.viewers.WebViewer`, what ``--serve-web`` starts), which
  keeps serving until :meth:`Shown.close`;
* ``spawn=True``: the native viewer, only where there is a display.
"""

from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from corraoi import arguments
from corraoi.errors import LogError, UsageError, ViewerError

if TYPE_CHECKING:
    from corraoi.recorder.live.viewers import WebViewer

#: The first bytes of every Rerun recording file (0.41: ``RRF2``).
RRD_MAGIC = b"RRF2"
#: The environment variable rerun-notebook reads, once, when it is imported: where the
#: browser loads the widget from (rerun-notebook 0.41, ``rerun_notebook/__init__.py``).
ASSET_ENV = "RERUN_NOTEBOOK_ASSET"


class Shown:
    """A viewer that :func:`corraoi.show` opened: ``.kind`` (``notebook``, ``web`` or
    ``native``), ``.url`` (the web viewer's address; the native viewer's none), ``.recordings``
    (the ``.rrd`` files shown), ``.widget`` (in Jupyter, the ``rerun_notebook.Viewer``).
    :meth:`close` stops what was started (also at the end of a ``with`` block, and when
    Python exits)."""

    def __init__(self, kind: str, recordings: list[Path], *, url: str | None = None,
                 widget: Any = None, server: WebViewer | None = None,
                 process: subprocess.Popen[bytes] | None = None) -> None:  # fmt: skip
        self.kind, self.recordings, self.url, self.widget = kind, recordings, url, widget
        self._server, self._process = server, process
        self._cell = _execution_count()
        atexit.register(self.close)

    @property
    def process(self) -> subprocess.Popen[bytes] | None:
        """The native viewer's process (None for the other kinds, or once closed)."""
        return self._process

    @property
    def closed(self) -> bool:
        return self._server is None and self._process is None and self.widget is None

    def close(self) -> None:
        """Stop the web viewer's servers, the native viewer, or remove the widget."""
        server, self._server = self._server, None
        process, self._process = self._process, None
        widget, self.widget = self.widget, None
        if server is not None:
            server.stop()  # the server's whole process group
        if process is not None and process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if widget is not None:
            widget.close()
        atexit.unregister(self.close)

    def __enter__(self) -> Shown:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:  # fmt: skip
        self.close()

    def _ipython_display_(self) -> None:
        # show() displayed the widget already: as the cell's value it is not shown twice;
        # a later cell that names the handle shows the viewer again
        if self.widget is not None and _execution_count() != self._cell:
            from IPython.display import display

            display(self.widget)
        elif self.widget is None:
            print(repr(self))

    def __repr__(self) -> str:
        state = "closed" if self.closed else (self.url or self.kind)
        files = ", ".join(str(p) for p in self.recordings)
        return f"Shown({self.kind}: {files} at {state})"


def open_viewer(
    find: Callable[[], list[Path]],
    *,
    spawn: bool = False,
    notebook: bool | None = None,
    web_port: int = 9090,
    width: int | str = "auto",
    height: int = 640,
) -> Shown:
    """Open the viewer :func:`corraoi.show` describes on the recordings ``find()`` returns,
    called once the viewer is known to be possible (so that nothing is replayed for a
    viewer that cannot open)."""
    web_port = check_options(spawn=spawn, notebook=notebook, web_port=web_port, width=width,
                             height=height)  # fmt: skip
    if spawn and notebook:
        raise UsageError("show: spawn=True opens a native window, notebook=True a widget; "
                         "choose one")  # fmt: skip
    in_notebook = not spawn and (notebook if notebook is not None else in_kernel())
    if spawn:
        from corraoi.recorder.live.viewers import display_problem

        problem = display_problem()
        if problem:  # rr.spawn without a display blocks for seconds and drops the data
            raise ViewerError(f"show(spawn=True): {problem}, so no native viewer was started; "
                              "leave out spawn=True to serve the web viewer on 127.0.0.1")
    elif in_notebook:
        from corraoi.extras import require

        require("notebook", "corraoi.show in a notebook", ("rerun_notebook", "IPython"))
    recordings = find()
    if spawn:
        return _native(recordings)
    if in_notebook:
        return _widget(recordings, width=width, height=height)
    return _web(recordings, web_port=web_port)


def check_options(*, spawn: object, notebook: object, web_port: object, width: object,
                  height: object) -> int:  # fmt: skip
    """The viewer's options of :func:`corraoi.show`, ``Run.show`` and ``Sweep.show``, checked
    (:mod:`corraoi.arguments`); returns ``web_port`` as an int (0: any free port)."""
    from corraoi.limits import MAX_PORT

    arguments.flag(spawn, name="spawn")
    arguments.optional(arguments.flag, notebook, name="notebook")
    port = arguments.integer(web_port, name="web_port", lo=0, hi=MAX_PORT,
                             why="a TCP port; 0 for any free one")  # fmt: skip
    if width != "auto":
        if isinstance(width, str):
            raise arguments.wrong_value(UsageError, "width", width,
                                        "a width in pixels (an integer >= 1) or 'auto'")
        arguments.integer(width, name="width", lo=1, why="pixels, or 'auto'")
    arguments.integer(height, name="height", lo=1, why="pixels")
    return port


def checked_rrd(p: Path) -> Path:
    """``p`` if it is a readable Rerun recording (its first bytes), else LogError."""
    try:
        with open(p, "rb") as f:
            head = f.read(len(RRD_MAGIC))
    except FileNotFoundError:
        raise LogError(f"{p}: no such file (a Rerun recording was expected)") from None
    except OSError as exc:
        raise LogError(f"{p}: cannot read it ({exc.strerror or exc})") from None
    if head != RRD_MAGIC:
        raise LogError(f"{p}: not a Rerun recording (it does not start with {RRD_MAGIC!r})")
    return p


# ---------------------------------------------------------------------------- the viewers


def in_kernel() -> bool:
    """Whether an IPython kernel (Jupyter) runs this code; IPython is not imported for it."""
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    return shell is not None and getattr(shell, "kernel", None) is not None


def _execution_count() -> int | None:
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    return getattr(shell, "execution_count", None)


def _web(recordings: list[Path], *, web_port: int) -> Shown:
    """``rerun --serve-web`` on 127.0.0.1 (the ``--serve-web`` server), fed the recordings."""
    from corraoi.recorder.live.viewers import WebViewer, free_port

    os.environ.setdefault("RUST_LOG", "off")  # Rerun's own log lines: we report problems
    # 0: any free port, as in socket: one is bound and read back, so that the URL names it
    web = WebViewer(web_port=web_port or free_port(0)).start()
    try:
        _send(recordings, web.grpc_url)
    except BaseException:
        web.stop()
        raise
    return Shown("web", recordings, url=web.web_url, server=web)


def _send(recordings: list[Path], url: str) -> None:
    """Load each recording, unchanged, into the server at ``url``, which keeps it for every
    viewer that connects. Each goes through a stream of the file's own application and
    recording id (:func:`store_of`), so the viewer lists the run and nothing beside it (a
    stream of its own would be an empty source of that name)."""
    import rerun as rr

    for p in recordings:
        app, rec = store_of(p)
        stream = rr.RecordingStream(app, recording_id=rec, send_properties=False)
        try:
            stream.connect_grpc(url)
            stream.log_file_from_path(p)
            stream.flush()
        except Exception as exc:  # noqa: BLE001 - rerun raises several kinds here
            raise ViewerError(f"show: cannot send {p} to the viewer at {url}: "
                              f"{exc}") from None  # fmt: skip
        finally:
            stream.disconnect()


def store_of(rrd: Path) -> tuple[str, str | None]:
    """(application id, recording id) of the recording the ``.rrd`` file holds (its first,
    if several); a file without one (a blueprint alone) gives ``corraoi`` and None."""
    import warnings

    from rerun.chunk import RrdReader

    try:
        with warnings.catch_warnings():  # a file from before footers: read whole, not said
            warnings.simplefilter("ignore")
            entries = RrdReader(rrd).recordings()
    except Exception as exc:  # noqa: BLE001 - rerun raises several kinds here
        raise LogError(f"{rrd}: cannot read the Rerun recording ({exc})") from None
    if not entries:
        return "corraoi", None
    return entries[0].application_id, entries[0].recording_id


def _native(recordings: list[Path]) -> Shown:
    """The native viewer opening the files itself (a display was checked for)."""
    from corraoi.recorder.live.viewers import rerun_executable

    cmd = [rerun_executable(), *map(str, recordings)]
    try:
        process = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, start_new_session=True)  # fmt: skip
    except OSError as exc:
        raise ViewerError(f"show(spawn=True): cannot run {cmd[0]}: "
                          f"{exc.strerror or exc}") from None  # fmt: skip
    return Shown("native", recordings, process=process)


def _widget(recordings: list[Path], *, width: int | str, height: int) -> Shown:
    """The rerun-notebook widget, displayed now, each recording sent to it as it is."""
    serve_widget_assets()
    from IPython.display import display
    from rerun_notebook import Viewer

    widget = Viewer(width=width, height=height,
                    panel_states={"blueprint": "collapsed", "selection": "collapsed"})
    for p in recordings:
        widget.send_rrd(p.read_bytes())  # queued until the browser's viewer is ready
    display(widget)
    return Shown("notebook", recordings, widget=widget)


_assets_lock = threading.Lock()
_assets_url: str | None = None


def serve_widget_assets() -> str | None:
    """Serve rerun-notebook's ``widget.js`` and its WebAssembly from the installed package on
    127.0.0.1 (a thread of this process), and point ``RERUN_NOTEBOOK_ASSET`` there before
    rerun-notebook is imported; returns the widget's URL.

    Left alone (None): a ``RERUN_NOTEBOOK_ASSET`` set by the user, or rerun-notebook already
    imported (it reads the variable once). rerun-notebook's own ``serve-local`` would
    gzip the 67 MB WebAssembly at import, 5-6 s here; served as it is over the loopback it
    costs nothing.
    """
    global _assets_url
    with _assets_lock:
        if _assets_url is not None:
            return _assets_url
        if ASSET_ENV in os.environ or "rerun_notebook" in sys.modules:
            return None
        import functools
        import importlib.util
        from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer

        spec = importlib.util.find_spec("rerun_notebook")
        assert spec is not None and spec.origin is not None
        static = Path(spec.origin).parent / "static"

        class Assets(SimpleHTTPRequestHandler):
            extensions_map = {".js": "text/javascript", ".wasm": "application/wasm",
                              ".css": "text/css", "": "application/octet-stream"}  # fmt: skip

            def end_headers(self) -> None:  # the notebook's page is another origin
                self.send_header("Access-Control-Allow-Origin", "*")
                super().end_headers()

            def list_directory(self, path: Any) -> None:
                self.send_error(404)

            def log_message(self, format: str, *args: Any) -> None:
                pass

        server = ThreadingHTTPServer(("127.0.0.1", 0),
                                     functools.partial(Assets, directory=str(static)))
        server.daemon_threads = True
        threading.Thread(target=server.serve_forever, name="corraoi-widget-assets",
                         daemon=True).start()  # fmt: skip
        _assets_url = f"http://127.0.0.1:{server.server_address[1]}/widget.js"
        os.environ[ASSET_ENV] = _assets_url
        return _assets_url


__all__ = ["Shown", "check_options", "checked_rrd", "in_kernel", "open_viewer",
           "serve_widget_assets"]  # fmt: skip
