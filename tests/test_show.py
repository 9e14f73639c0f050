"""``corraoi.show`` outside Jupyter: which recording it shows, the web viewer it serves on
127.0.0.1 and stops, the native viewer only with a display, bad input in one line, and the
widget's assets served from the installed package (the notebook itself:
tests/test_quickstart_notebook.py and tests/test_notebook_browser.py)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import textwrap
import time
import urllib.request
import warnings
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

import corraoi
from corraoi.errors import LogError, MissingExtraError, UsageError, ViewerError
from corraoi.face.viewing import Shown, in_kernel

from .rrd_util import RERUN


def listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> corraoi.Run:
    folder = tmp_path_factory.mktemp("show")
    return corraoi.record("cucb", "I1", seed=1, horizon=1500, path=folder / "cucb.mcap")


def recordings_of(target) -> list[Path]:
    """What ``corraoi.show(target)`` shows (the web viewer, stopped again)."""
    with corraoi.show(target) as shown:
        return shown.recordings


def test_outside_a_kernel_it_serves_the_web_viewer_on_loopback_and_close_stops_it(recorded):
    assert not in_kernel()
    shown = corraoi.show(recorded)
    try:
        assert isinstance(shown, Shown) and shown.kind == "web"
        assert shown.recordings == [recorded.rrd]
        parts = urlsplit(shown.url)
        assert parts.scheme == "http" and parts.hostname == "127.0.0.1"
        grpc = urlsplit(unquote(parts.query.split("url=", 1)[1]))
        assert grpc.hostname == "127.0.0.1" and grpc.path == "/proxy"
        web_port, grpc_port = parts.port, grpc.port
        assert web_port and grpc_port and listening(web_port) and listening(grpc_port)
        with urllib.request.urlopen(shown.url, timeout=10) as page:  # the viewer's page
            assert page.status == 200 and b"<html" in page.read(4096).lower()
        assert "127.0.0.1" in repr(shown)
    finally:
        shown.close()
    time.sleep(0.3)
    assert shown.closed and not listening(web_port) and not listening(grpc_port)
    assert "closed" in repr(shown)
    shown.close()  # twice is harmless


def served_sources(grpc_url: str, into: Path) -> list[tuple[str, str]]:
    """(application id, recording id) of every recording the server at ``grpc_url`` hands
    a viewer that connects: ``rerun --connect URL --save FILE`` (no window) saves what it
    gets; read once the run has arrived and a moment more has passed."""
    from rerun.chunk import RrdReader

    from corraoi.recorder.live.viewers import rerun_binary

    proc = subprocess.Popen([rerun_binary(), "--connect", grpc_url, "--save", str(into)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (into.is_file() and into.stat().st_size):
            time.sleep(0.2)
        time.sleep(2.0)  # whatever the server holds is sent at once; let it all arrive
    finally:
        proc.terminate()
        proc.wait(timeout=20)
    with warnings.catch_warnings():  # a saved stream has no footer: read whole
        warnings.simplefilter("ignore")
        return [(e.application_id, e.recording_id) for e in RrdReader(into).recordings()]


def test_the_web_viewer_lists_the_run_and_no_empty_source_beside_it(tmp_path, recorded):
    from rerun.chunk import RrdReader

    (own,) = RrdReader(recorded.rrd).recordings()
    with corraoi.show(recorded) as shown:
        grpc = unquote(urlsplit(shown.url).query.split("url=", 1)[1])
        sources = served_sources(grpc, tmp_path / "served.rrd")
    assert sources == [(own.application_id, own.recording_id)]  # no "corraoi-show" beside it


def test_run_show_and_sweep_show_go_through_corraoi_show(tmp_path):
    sw = corraoi.sweep("I1", ["ucb", "cucb"], runs=4, horizon=300, out=tmp_path / "sw")
    with sw.show() as shown:  # a context manager too
        assert shown.recordings == [tmp_path / "sw" / "sweep.rrd"]
        port = urlsplit(shown.url).port
        assert port and listening(port)
    time.sleep(0.3)
    assert not listening(port)
    # a path to the folder or its sweep log: the same recording
    for p in (tmp_path / "sw", tmp_path / "sw" / "sweep.mcap"):
        assert recordings_of(p) == [tmp_path / "sw" / "sweep.rrd"], p
    assert corraoi.load(tmp_path / "sw").recordings() == [tmp_path / "sw" / "sweep.rrd"]


def test_a_log_without_its_rrd_gets_the_replayed_one_beside_it(tmp_path, recorded):
    run = corraoi.record("cucb", "I1", seed=1, horizon=1500, path=tmp_path / "a.mcap", rrd=False)
    assert run.rrd is None and not (tmp_path / "a.rrd").exists()
    assert recordings_of(tmp_path / "a.mcap") == [tmp_path / "a.rrd"]
    # the replayed recording is the one `record` writes (rerun rrd compare: equal)
    same = subprocess.run([RERUN, "rrd", "compare", str(tmp_path / "a.rrd"), str(recorded.rrd)],
                          capture_output=True, text=True)  # fmt: skip
    assert same.returncode == 0, same.stdout + same.stderr
    # an .rrd path is shown as it is; a run with one is not replayed again
    mtime = (tmp_path / "a.rrd").stat().st_mtime_ns
    assert corraoi.load(tmp_path / "a.mcap").recording() == tmp_path / "a.rrd"
    assert recordings_of(tmp_path / "a.rrd") == [tmp_path / "a.rrd"]
    assert (tmp_path / "a.rrd").stat().st_mtime_ns == mtime


@pytest.mark.parametrize(
    ("make", "error", "words"),
    [
        (lambda p: 42, UsageError, "target 42: expected a corraoi.Run, a corraoi.Sweep, or the"),
        (lambda p: p / "nope.mcap", LogError, "nope.mcap: no such file or folder"),
        (lambda p: p, LogError, "a folder without a sweep"),
        (lambda p: _write(p / "x.rrd", b"hello"), LogError, "not a Rerun recording"),
        (lambda p: _write(p / "x.mcap", b"hello"), LogError, "not an MCAP file"),
    ],
)
def test_bad_input_is_one_line(tmp_path, make, error, words):
    with pytest.raises(error) as info:
        corraoi.show(make(tmp_path))
    text = str(info.value)
    assert words in text and "\n" not in text


def _write(p: Path, data: bytes) -> Path:
    p.write_bytes(data)
    return p


def test_spawn_without_a_display_says_why(monkeypatch, recorded):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(ViewerError, match=r"show\(spawn=True\): no display .*web viewer"):
        corraoi.show(recorded, spawn=True)
    with pytest.raises(UsageError, match="choose one"):
        corraoi.show(recorded, spawn=True, notebook=True)


def test_spawn_with_a_display_opens_the_files_in_the_native_viewer(tmp_path, monkeypatch,
                                                                   recorded):  # fmt: skip
    """A stand-in ``rerun`` (the native viewer needs a screen) records what it was given."""
    fake = tmp_path / "rerun"
    fake.write_text(f"#!{sys.executable}\nimport sys, time\n"
                    f"open({str(tmp_path / 'args')!r}, 'w').write('\\n'.join(sys.argv[1:]))\n"
                    "time.sleep(60)\n")  # fmt: skip
    fake.chmod(0o755)
    monkeypatch.setenv("DISPLAY", ":99")
    monkeypatch.setattr("corraoi.recorder.live.viewers.rerun_executable", lambda: str(fake))
    shown = corraoi.show(recorded, spawn=True)
    try:
        assert shown.kind == "native" and shown.url is None
        deadline = time.monotonic() + 20
        while not (tmp_path / "args").exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert (tmp_path / "args").read_text() == str(recorded.rrd)
        process = shown.process
        assert process is not None and process.poll() is None
    finally:
        shown.close()
    assert process.poll() is not None  # close() stopped it


def test_in_jupyter_without_rerun_notebook_names_the_extra(monkeypatch, recorded):
    monkeypatch.setattr("corraoi.extras.missing", lambda names: "rerun_notebook")
    with pytest.raises(MissingExtraError) as info:
        corraoi.show(recorded, notebook=True)
    assert str(info.value) == ('rerun_notebook is not installed: corraoi.show in a notebook '
                               'needs the notebook extra, pip install "corraoi[notebook]"')


def test_the_widget_assets_are_served_from_the_installed_package(tmp_path):
    """No network: rerun-notebook loads its widget from this process's server on 127.0.0.1,
    which serves the package's own files (checked in a fresh interpreter: the variable is read
    once, at import)."""
    pytest.importorskip("rerun_notebook", reason="rerun-notebook is not installed "
                        '(pip install -e ".[notebook]")')  # fmt: skip
    script = textwrap.dedent("""
        import hashlib, json, os, urllib.request
        from corraoi.face.viewing import serve_widget_assets
        url = serve_widget_assets()
        import rerun_notebook
        got = {}
        for name in ("widget.js", "re_viewer_bg.wasm"):
            with urllib.request.urlopen(url.replace("widget.js", name), timeout=30) as r:
                got[name] = [hashlib.sha256(r.read()).hexdigest(), r.headers["Content-Type"],
                             r.headers["Access-Control-Allow-Origin"]]
        try:
            urllib.request.urlopen(url.replace("widget.js", ""), timeout=10)
            listing = 200
        except urllib.error.HTTPError as exc:
            listing = exc.code
        print(json.dumps({"url": url, "env": os.environ["RERUN_NOTEBOOK_ASSET"],
                          "esm": str(rerun_notebook.ESM_MOD), "got": got,
                          "static": str(rerun_notebook.STATIC_DIR), "listing": listing}))
    """)
    env = {k: v for k, v in os.environ.items() if k != "RERUN_NOTEBOOK_ASSET"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=env, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr
    import hashlib
    import json

    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert urlsplit(res["url"]).hostname == "127.0.0.1"
    assert res["env"] == res["esm"] == res["url"]  # the widget loads from there, not the web
    static = Path(res["static"])
    types = (("widget.js", "text/javascript"), ("re_viewer_bg.wasm", "application/wasm"))
    for name, ctype in types:
        digest = hashlib.sha256((static / name).read_bytes()).hexdigest()
        assert res["got"][name] == [digest, ctype, "*"], name
    assert res["listing"] == 404
