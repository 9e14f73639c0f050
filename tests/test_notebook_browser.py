"""A real notebook in a real browser, with no network: JupyterLab served on 127.0.0.1 (a free
port, a token), docs/examples/quickstart.ipynb opened in headless Chromium (driven over the
DevTools pipe, tests/browser.py's client), all its cells run, and the Rerun widget that
``corraoi.show`` displays must draw the drilled run: the success and failure markers and the
arms' colours in a screenshot of the widget, and enough drawn pixels. Chromium resolves no
host but 127.0.0.1 and localhost, so the widget's JavaScript and WebAssembly can only come
from the kernel's own server. The test stops the browser and JupyterLab and checks the port
is closed.

``CORRAOI_NOTEBOOK_SCREENSHOT_TO=docs/notebook-show.png pytest tests/test_notebook_browser.py``
also keeps the page's screenshot (a 256-colour palette PNG).
"""

from __future__ import annotations

import importlib.util
import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

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
)

QUICKSTART = Path(__file__).resolve().parent.parent / "docs" / "examples" / "quickstart.ipynb"
#: Only the loopback resolves: anything the page wanted from the network fails.
OFFLINE = "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1 , EXCLUDE localhost"
#: What the drilled run's recording shows in the widget: (name, colour).
MARKS = (
    ("success marker", style.SUCCESS_COLOR),
    ("failure marker", style.FAILURE_COLOR),
    *((f"arm {k + 1}", style.arm_color(k)) for k in (1, 2)),
)

#: Run every cell; then, once the kernel is idle and every cell has run, the show cell's
#: widget element scrolled into view and its rectangle.
RUN_ALL = "window.jupyterapp.commands.execute('notebook:run-all-cells').then(() => true)"
STATE = """(() => {
  const cells = [...document.querySelectorAll('.jp-Notebook .jp-CodeCell')];
  const counts = cells.map(c => (c.querySelector('.jp-InputPrompt') || {}).textContent || '');
  const stderr = '.jp-OutputArea-output[data-mime-type="application/vnd.jupyter.stderr"]';
  const errors = [...document.querySelectorAll(stderr)]
    .map(e => e.textContent).filter(t => /Error|Traceback/.test(t));
  const last = cells[cells.length - 1];
  const canvas = last && last.querySelector('.jp-OutputArea-output canvas');
  let rect = null;
  if (canvas) {
    const box = canvas.closest('.jp-OutputArea-output');
    box.scrollIntoView({block: 'center'});
    const r = box.getBoundingClientRect();
    rect = {x: r.x, y: r.y, width: r.width, height: r.height};
  }
  return {counts, errors, rect};
})()"""


def _jupyterlab_or_skip() -> None:
    for name in ("jupyterlab", "rerun_notebook", "pandas", "pyarrow"):
        if importlib.util.find_spec(name) is None:
            pytest.skip(f'{name} is not installed (pip install -e ".[test,notebook]")')


def evaluate(browser: Chromium, expression: str, timeout: float = 30) -> object:
    reply = browser.call("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                              "awaitPromise": True}, timeout=timeout)  # fmt: skip
    if "exceptionDetails" in reply:
        raise RuntimeError(f"{expression[:60]}...: {reply['exceptionDetails']}")
    return reply["result"].get("value")


@pytest.mark.slow
def test_the_quickstart_notebook_shows_the_run_in_jupyterlab_in_chromium(tmp_path):
    exe = chromium_or_skip()
    _jupyterlab_or_skip()
    root = tmp_path / "lab"
    root.mkdir()
    shutil.copy(QUICKSTART, root / "quickstart.ipynb")
    port, token = free_port(), secrets.token_hex(16)
    env = dict(os.environ, JUPYTER_CONFIG_DIR=str(tmp_path / "config"),
               JUPYTER_RUNTIME_DIR=str(tmp_path / "runtime"),
               JUPYTERLAB_SETTINGS_DIR=str(tmp_path / "settings"),
               JUPYTERLAB_WORKSPACES_DIR=str(tmp_path / "workspaces"))  # fmt: skip
    env.pop("RERUN_NOTEBOOK_ASSET", None)
    news = tmp_path / "settings" / "@jupyterlab" / "apputils-extension"
    news.mkdir(parents=True)  # no "get notified about Jupyter news?" toast over the page
    (news / "notification.jupyterlab-settings").write_text('{"fetchNews": "false"}')
    log = open(tmp_path / "jupyterlab.log", "wb")  # noqa: SIM115 - closed below
    lab = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", "--no-browser", "--ServerApp.ip=127.0.0.1",
         f"--ServerApp.port={port}", "--ServerApp.port_retries=0",
         f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root}",
         "--expose-app-in-browser", "--LabApp.news_url=None",
         "--LabApp.extension_manager=readonly", "--allow-root"],
        cwd=root, env=env, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
        start_new_session=True,
    )  # fmt: skip
    browser = None
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/status?token={token}",
                                            timeout=2) as r:  # fmt: skip
                    json.load(r)
                break
            except OSError:
                assert lab.poll() is None, (tmp_path / "jupyterlab.log").read_text()
                assert time.monotonic() < deadline, "JupyterLab did not start within 90 s"
                time.sleep(0.5)
        browser = Chromium(exe, extra_args=[OFFLINE])
        browser.open(f"http://127.0.0.1:{port}/lab/tree/quickstart.ipynb?token={token}")
        deadline = time.monotonic() + 90
        while not evaluate(browser, "!!(window.jupyterapp && document.querySelector("
                           "'.jp-Notebook .jp-CodeCell') && window.jupyterapp.serviceManager"
                           ".sessions.running().next())"):  # fmt: skip
            assert time.monotonic() < deadline, "the notebook did not open with a kernel"
            time.sleep(1)
        time.sleep(2)  # the kernel connected
        evaluate(browser, RUN_ALL, timeout=60)
        state: dict = {}
        png = b""
        found: dict[str, int] = {}
        wanted = dict(MARKS)
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            time.sleep(3)
            state = evaluate(browser, STATE)  # type: ignore[assignment]
            assert not state["errors"], state["errors"]
            rect = state["rect"]
            if rect is None or any("*" in c or not c.strip("[]: ") for c in state["counts"]):
                continue  # cells still running, or the widget not there yet
            time.sleep(1)
            rect = evaluate(browser, STATE)["rect"]  # type: ignore[index]
            png = browser.screenshot(clip=rect)
            found = {p: colour_pixels(png, rgb) for p, rgb in wanted.items()}
            if all(n >= 30 for n in found.values()) and drawn_share(png) >= 0.05:
                time.sleep(3)  # let the last panels finish drawing
                rect = evaluate(browser, STATE)["rect"]  # type: ignore[index]
                png = browser.screenshot(clip=rect)
                found = {p: colour_pixels(png, rgb) for p, rgb in wanted.items()}
                break
        (tmp_path / "widget.png").write_bytes(png)
        keep = os.environ.get("CORRAOI_NOTEBOOK_SCREENSHOT_TO")
        if keep:
            checkout = QUICKSTART.parent.parent.parent  # a relative path is the checkout's
            save_palette_png(browser.screenshot(), checkout / keep)
        assert state.get("rect"), f"no Rerun widget drawn in the show cell: {state}"
        missing = {p: n for p, n in found.items() if n < 30}
        assert not missing, f"colours missing from the widget: {missing} (all: {found})"
        share = drawn_share(png)
        assert share >= 0.05, f"the widget is nearly blank ({share:.1%} drawn pixels)"
    finally:
        if browser is not None:
            browser.close()
        if lab.poll() is None:
            lab.send_signal(signal.SIGINT)  # twice: JupyterLab asks to confirm the first
            time.sleep(0.5)
            lab.send_signal(signal.SIGINT)
            try:
                lab.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(lab.pid, signal.SIGKILL)
                lab.wait()
        log.close()
    time.sleep(0.5)
    assert not listening(port), "JupyterLab is still serving"
