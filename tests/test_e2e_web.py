"""End to end in a real viewer: recordings opened in the Rerun web viewer in headless Chromium.

The Rerun web viewer bundled in rerun-sdk serves a recording on 127.0.0.1 (``corraoi compare
--serve-web``, or ``rerun FILE.rrd --serve-web``); headless Chromium (Debian's ``chromium``,
driven over the DevTools protocol: tests/browser.py) opens it at 1600 x 900, and the
screenshot must look like views a person can read: the run's colours, the success and
failure markers, the arms' colours (up to 8 arms) or the colours of the arms that matter
and the grey bars (beyond), and enough drawn (non-background) pixels -- a blank, error or
welcome page has none of them. The tests stop the browser and the servers themselves.

``CORRAOI_SCREENSHOT_TO=docs/compare-screenshot.png pytest tests/test_e2e_web.py -k compare``
keeps the comparison's screenshot (as a 256-colour palette PNG); the docs' screenshots are
made by ``benchmarks/screenshots.py``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from corraoi.recorder import style

from .browser import (
    Chromium,
    chromium_or_skip,
    colour_pixels,
    drawn_share,
    free_port,
    listening,
    save_palette_png,
    serve_rrd,
    settled_screenshot,
)

POLICIES = ("ucb", "ts", "cts-gauss")  # colours unlike any arm, success or failure colour
#: What a readable compare screenshot shows besides the run colours: (name, colour).
MARKS = (
    ("success marker", style.SUCCESS_COLOR),
    ("failure marker", style.FAILURE_COLOR),
    *((f"arm {k + 1}", style.arm_color(k)) for k in range(4)),
)


def record_rrd(tmp_path: Path, instance: str, policy: str, horizon: int) -> Path:
    out = tmp_path / "run.rrd"
    subprocess.run(
        [sys.executable, "-m", "corraoi.cli", "record", "-i", instance, "-p", policy, "-T",
         str(horizon), "-s", "1", "-o", str(tmp_path / "run.mcap"), "--rrd", str(out)],
        check=True, capture_output=True, cwd=tmp_path,
    )  # fmt: skip
    return out


def look_at(path: Path, wanted: dict[str, tuple[int, int, int]], least: int = 40) -> None:
    """Open ``path`` in the web viewer and fail unless every wanted colour shows (at least
    ``least`` pixels of it) and 4% of the pixels are drawn; the screenshot is kept beside
    ``path``."""
    found, share, png = _screenshot(path, wanted, least)
    path.with_suffix(".png").write_bytes(png)
    missing = {n: v for n, v in found.items() if v < least}
    assert not missing, f"colours missing from the screenshot: {missing} (all: {found})"
    assert share >= 0.04, f"the screenshot is nearly blank ({share:.1%} drawn pixels)"


def _screenshot(path: Path, wanted: dict[str, tuple[int, int, int]], least: int,
                ) -> tuple[dict[str, int], float, bytes]:  # fmt: skip
    """The pixels of each wanted colour, the share of drawn pixels and the screenshot,
    once every colour shows (or after a minute and a half)."""
    exe = chromium_or_skip()
    with serve_rrd(path) as url:
        browser = Chromium(exe)
        try:
            browser.open(url)
            deadline = time.monotonic() + 90
            while True:
                png = settled_screenshot(browser, wait=3, timeout=60)
                found = {n: colour_pixels(png, rgb) for n, rgb in wanted.items()}
                if all(v >= least for v in found.values()) or time.monotonic() > deadline:
                    return found, drawn_share(png), png
        finally:
            browser.close()


@pytest.mark.slow
def test_a_run_of_four_arms_draws_every_panel(tmp_path):
    path = record_rrd(tmp_path, "I1", "ts", 2000)
    wanted = {"policy": style.policy_color("ts"), "success": style.SUCCESS_COLOR,
              "failure": style.FAILURE_COLOR, "estimator and k*": style.REFERENCE_COLOR,
              **{f"arm {k + 1}": style.arm_color(k) for k in range(4)}}  # fmt: skip
    look_at(path, wanted)


@pytest.mark.slow
def test_a_run_of_64_arms_draws_bars_strips_and_the_arms_that_matter(tmp_path):
    from .test_views import random_instance

    inst = random_instance(64, seed=64)
    (tmp_path / "r64.json").write_text(json.dumps(inst.to_dict()))
    path = record_rrd(tmp_path, str(tmp_path / "r64.json"), "cucb", 2000)
    wanted = {"policy": style.policy_color("cucb"), "failure": style.FAILURE_COLOR,
              "grey bars": style.BAR_IN_SET_COLOR, "true means": style.BAR_TRUE_COLOR,
              **{f"arm that matters {i + 1}": style.focus_color(i) for i in range(3)}}  # fmt: skip
    look_at(path, wanted)


@pytest.mark.slow
def test_compare_shows_every_run_in_the_web_viewer(tmp_path, record_mcap):
    exe = chromium_or_skip()
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
        browser = Chromium(exe, 1400, 900)
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
            save_palette_png(png, keep)
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
