"""A real viewer in a real browser, for the end-to-end tests and the docs' screenshots
(benchmarks/screenshots.py): headless Chromium (Debian's ``chromium``) driven over the
DevTools protocol on a pipe (no extra Python package), the Rerun web viewer of rerun-sdk
serving an ``.rrd`` on 127.0.0.1, and the pixel checks that tell a drawn view from a blank,
error or welcome page.
"""

from __future__ import annotations

import base64
import contextlib
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from urllib.parse import quote

import numpy as np

WIDTH, HEIGHT = 1600, 900
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    """The Chromium executable, or None (then say: looked for CHROMIUM_NAMES)."""
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def chromium_or_skip() -> str:
    """The Chromium executable; the calling test skips with one line where there is none."""
    import pytest

    exe = find_chromium()
    if exe is None:
        pytest.skip(
            "no Chromium found (looked for " + ", ".join(CHROMIUM_NAMES) + "); .ci/run "
            "installs Debian's chromium where it can (apt-get install chromium)"
        )
    return exe


class Chromium:
    """Headless Chromium driven over ``--remote-debugging-pipe`` (fds 3 and 4)."""

    def __init__(self, exe: str, width: int = WIDTH, height: int = HEIGHT,
                 extra_args: list[str] | None = None) -> None:  # fmt: skip
        self.width, self.height = width, height
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
             f"--window-size={width},{height}", *(extra_args or []), "about:blank"],
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
        metrics = {"width": self.width, "height": self.height, "deviceScaleFactor": 1,
                   "mobile": False}
        self.call("Emulation.setDeviceMetricsOverride", metrics)
        self.call("Page.navigate", {"url": url})

    def screenshot(self, timeout: float = 60, clip: dict | None = None) -> bytes:
        """The page (or the ``clip`` rectangle: x, y, width, height in CSS pixels) as PNG."""
        params: dict = {"format": "png"}
        if clip is not None:
            params["clip"] = {**clip, "scale": 1}
        shot = self.call("Page.captureScreenshot", params, timeout=timeout)
        return base64.b64decode(shot["data"])

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




@contextlib.contextmanager
def serve_rrd(path: str | os.PathLike[str]) -> Iterator[str]:
    """The Rerun web viewer serving ``path`` on 127.0.0.1; yields the page's URL. The
    server (its whole process group) is stopped when the block ends."""
    from corraoi.recorder.live.viewers import rerun_binary

    grpc, web = free_port(), free_port()
    proc = subprocess.Popen(
        [rerun_binary(), str(path), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc),
         "--web-viewer-port", str(web)],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True, env={**os.environ, "RERUN_APP_ONLY": "true"},
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 30
        while not (listening(web) and listening(grpc)):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"rerun --serve-web {path} did not start")
            time.sleep(0.1)
        proxy = quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
        yield f"http://127.0.0.1:{web}/?url={proxy}"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def settled_screenshot(browser: Chromium, *, wait: float = 4.0, timeout: float = 120) -> bytes:
    """A screenshot once the page is drawn and stops changing (two equal in a row, with
    drawn pixels), or the last one after ``timeout`` seconds."""
    time.sleep(wait)
    last, end = b"", time.monotonic() + timeout
    while True:
        png = browser.screenshot(timeout=timeout)
        if (png == last and drawn_share(png) > 0.04) or time.monotonic() > end:
            return png
        last = png
        time.sleep(2)


def save_palette_png(png: bytes, path: str | os.PathLike[str]) -> None:
    """``png`` written as a 256-colour palette PNG (the docs' screenshots: small files)."""
    from PIL import Image

    Image.open(io.BytesIO(png)).convert("RGB").quantize(colors=256).save(path, optimize=True)
