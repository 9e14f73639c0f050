"""``corraoi record``: defaults, options, refusals, faults, signals and viewers.

In-process runs use click's CliRunner; signals, SIGKILL, file-size limits and viewers run
``python -m corraoi.cli record`` in a subprocess (servers bound to 127.0.0.1 and stopped
by the test itself; no rr.spawn()).
"""

from __future__ import annotations

import json
import os
import re
import resource
import select
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.engine.block import SlotBlock
from corraoi.files.partial import partial_path
from corraoi.recorder.slotlog.reader import open_log

PYTHON = sys.executable
ROOT = Path(__file__).resolve().parent.parent


def run(*args: str):
    return CliRunner().invoke(main, ["record", *args])


def one_line_error(res, code: int, *needles: str) -> str:
    assert res.exit_code == code, res.output
    err = res.stderr.strip()
    assert err.startswith("corraoi: error: ") and "\n" not in err, err
    assert "Traceback" not in res.output
    for needle in needles:
        assert needle in err, err
    return err


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def cli(*args: str, cwd: Path, **kw) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [PYTHON, "-m", "corraoi.cli", "record", *args],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        **kw,
    )


def engine_prefix(config, n: int) -> SlotBlock:
    from corraoi.engine.simulation import simulate_run

    blocks = list(simulate_run(config.instance, config.policy, config.seed, n))
    return SlotBlock.concat(blocks)


# ---------------------------------------------------------------------------- defaults


def test_record_cucb_with_no_other_option(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = run("--policy", "cucb")
    assert res.exit_code == 0, res.output
    mcap, rrd = Path("runs/cucb-I1-s0.mcap"), Path("runs/cucb-I1-s0.rrd")
    assert mcap.is_file() and rrd.is_file()
    assert not partial_path(mcap).exists() and not partial_path(rrd).exists()
    log = open_log(mcap)
    c = log.config
    assert (c.instance.name, c.policy.name, c.seed, c.horizon) == ("I1", "cucb", 0, 10_000)
    assert log.n_slots == 10_000 and log.status == "complete"
    last = log.read_all().slice(9_999, 10_000)
    out = res.stdout
    assert f"AoI regret at slot 10000: {int(last.regret[0])} (pathwise)" in out
    assert f"{float(last.estimator[0]):.1f} (paper's estimator" in out
    pulls = "  ".join(f"{k + 1}: {n}" for k, n in enumerate(last.pulls[0]))
    assert f"pulls per arm: {pulls}" in out
    assert "MCAP log:        runs/cucb-I1-s0.mcap" in out
    assert "Rerun recording: runs/cucb-I1-s0.rrd" in out
    view = out.strip().splitlines()[-1]
    assert view.startswith("open in the Rerun viewer:") and view.endswith(" runs/cucb-I1-s0.rrd")
    assert res.stderr == ""  # no progress bar when stderr is not a terminal


def test_json_summary_and_options(tmp_path):
    out = tmp_path / "o" / "{policy}-{seed}.mcap"
    res = run("-p", "ts-gauss", "--beta", "2", "-i", "I2", "-T", "1500", "-s", "4", "-o", str(out),
              "--rrd", str(tmp_path / "r.rrd"), "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    (r,) = summary["runs"]
    assert r["mcap"] == str(tmp_path / "o" / "ts-gauss-4.mcap") and r["rrd"] == str(
        tmp_path / "r.rrd"
    )
    assert (r["slots"], r["complete"], r["params"]) == (1500, True, {"beta": 2.0})
    log = open_log(r["mcap"])
    assert log.config.policy.params["beta"] == 2.0 and log.config.instance.name == "I2"
    assert log.read_all().pulls[-1].tolist() == r["pulls"]
    assert summary["view"].endswith(str(tmp_path / "r.rrd"))


def test_several_policies_are_paired_runs(tmp_path):
    res = run("-p", "ucb,cucb", "-p", "aoi-aware-ts", "-T", "2000", "-s", "9",
              "-o", str(tmp_path / "{label}.mcap"), "--no-rrd")  # fmt: skip
    assert res.exit_code == 0, res.output
    logs = [open_log(tmp_path / f"{p}-I1-s9.mcap") for p in ("ucb", "cucb", "aoi-aware-ts")]
    blocks = [log.read_all() for log in logs]
    assert all(np.array_equal(b.x, blocks[0].x) for b in blocks)  # one hidden path
    assert not np.array_equal(blocks[0].arm, blocks[1].arm)  # different decisions
    assert not list(tmp_path.glob("*.rrd"))
    res = run("-p", "all", "-T", "50", "-o", str(tmp_path / "all" / "{label}.mcap"), "--no-rrd")
    assert res.exit_code == 0, res.output
    assert len(list((tmp_path / "all").glob("*.mcap"))) == 12


def test_help_does_not_import_rerun_or_the_recorder():
    code = (
        "import sys\n"
        "from click.testing import CliRunner\n"
        "from corraoi.cli import main\n"
        "r = CliRunner().invoke(main, ['record', '--help'])\n"
        "assert r.exit_code == 0 and '--serve-web' in r.output and '--no-rrd' in r.output\n"
        "print(sorted(m for m in ('rerun', 'mcap', 'corraoi.recorder.slotlog.sink')\n"
        "             if m in sys.modules))\n"
    )
    out = subprocess.run([PYTHON, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_the_same_command_twice_gives_the_same_files(tmp_path):
    for name in ("a", "b"):
        res = run(
            "-p", "aoi-aware-cts", "-T", "2500", "-s", "3", "-o", str(tmp_path / name / "r.mcap")
        )
        assert res.exit_code == 0, res.output
    a, b = tmp_path / "a", tmp_path / "b"
    assert (a / "r.mcap").read_bytes() == (b / "r.mcap").read_bytes()
    cmp = subprocess.run([_rerun_binary(), "rrd", "compare", str(a / "r.rrd"), str(b / "r.rrd")],
                         capture_output=True, text=True)  # fmt: skip
    assert cmp.returncode == 0, cmp.stdout + cmp.stderr
    res = run("-p", "aoi-aware-cts", "-T", "2500", "-s", "4", "-o", str(tmp_path / "c" / "r.mcap"))
    assert res.exit_code == 0
    assert (tmp_path / "c" / "r.mcap").read_bytes() != (a / "r.mcap").read_bytes()


# ---------------------------------------------------------------------------- refusals


def test_refuses_to_clobber_unless_forced(tmp_path):
    args = ["-T", "1200", "-o", str(tmp_path / "a.mcap")]
    assert run(*args).exit_code == 0
    before = (tmp_path / "a.mcap").read_bytes(), (tmp_path / "a.rrd").stat().st_mtime_ns
    same = run(*args)  # the same run again: up to date, nothing rewritten
    assert same.exit_code == 0 and same.stdout.startswith("up to date: ")
    one_line_error(run(*args, "-s", "1"), 2, "a.mcap: already exists", "--force")
    assert (tmp_path / "a.mcap").read_bytes() == before[0]
    one_line_error(run("-T", "10", "-o", str(tmp_path / "b.mcap"), "--rrd",
                       str(tmp_path / "a.rrd")), 2, "a.rrd: already exists")  # fmt: skip
    assert (tmp_path / "a.rrd").stat().st_mtime_ns == before[1]
    res = run(*args, "-s", "1", "--force")
    assert res.exit_code == 0, res.output
    assert open_log(tmp_path / "a.mcap").config.seed == 1


def test_bad_paths_and_option_mixes_are_one_line_errors(tmp_path):
    one_line_error(run("-T", "10", "-o", str(tmp_path)), 2, "is a directory")
    one_line_error(run("-T", "10", "--rrd", str(tmp_path)), 2, "is a directory")
    (tmp_path / "f").write_text("x")
    one_line_error(run("-T", "10", "-o", str(tmp_path / "f" / "x.mcap")), 2, "not a directory")
    one_line_error(run("-T", "10", "-o", "/proc/corraoi-test.mcap", "--no-rrd"), 2, "cannot create")
    one_line_error(run("-p", "ucb,ts", "-o", str(tmp_path / "one.mcap")), 2, "{label}")
    one_line_error(run("--rrd", "x.rrd", "--no-rrd"), 2, "--no-rrd")
    one_line_error(run("--spawn", "--connect"), 2, "choose one")
    one_line_error(run("--connect", "http://example.org"), 2, "rerun+http")
    one_line_error(run("-p", "cucc"), 2, "did you mean cucb")
    one_line_error(run("-o", str(tmp_path / "s.mcap"), "--rrd", str(tmp_path / "s.mcap")), 2,
                   "used twice")  # fmt: skip
    stale = tmp_path / "stale.mcap"
    partial_path(stale).write_text("half of another file")  # not this run: never taken over
    one_line_error(run("-T", "10", "-o", str(stale)), 2, "partial file")
    assert not list(tmp_path.glob("*.rrd*"))  # nothing was started


def test_a_failed_start_leaves_no_partial_file_behind(tmp_path):
    # the MCAP file can be made, the .rrd cannot: neither may be left half-made
    (tmp_path / "ro").write_text("a file where a directory should be")
    res = run("-T", "100", "-o", str(tmp_path / "ok.mcap"), "--rrd", str(tmp_path / "ro" / "x.rrd"))
    one_line_error(res, 2, "not a directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ro"]


# ---------------------------------------------------------------------------- viewers


def test_connect_to_nothing_still_writes_the_files(tmp_path):
    port = free_port()  # nothing listens there
    start = time.monotonic()
    res = run("-T", "1500", "-o", str(tmp_path / "c.mcap"), "--connect", str(port))
    assert time.monotonic() - start < 20
    assert res.exit_code == 1, res.output
    err = res.stderr.strip()
    assert err.count("\n") == 0 and f"--connect rerun+http://127.0.0.1:{port}/proxy" in err
    assert "no Rerun viewer there" in err and "Traceback" not in res.output
    assert open_log(tmp_path / "c.mcap").n_slots == 1500 and (tmp_path / "c.rrd").is_file()


def test_spawn_without_a_display_says_so_and_writes_the_files(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if sys.platform != "linux":
        pytest.skip("the display check is for Linux")
    res = run("-T", "1200", "-o", str(tmp_path / "s.mcap"), "--spawn")
    assert res.exit_code == 1, res.output
    err = res.stderr.strip()
    assert err.count("\n") == 0 and "--spawn: no display" in err
    assert open_log(tmp_path / "s.mcap").n_slots == 1200 and (tmp_path / "s.rrd").is_file()


def _rerun_binary() -> str:
    from corraoi.recorder.live.viewers import rerun_binary

    return rerun_binary()


@pytest.mark.parametrize("how", ["--connect", "--spawn"])
def test_the_viewer_gets_the_same_recording_as_the_file(tmp_path, monkeypatch, how):
    """A headless Rerun server that saves what it receives stands in for the viewer
    (for --spawn, in place of the window that rr.spawn would open)."""
    port = free_port()
    saved = tmp_path / "viewer.rrd"
    server = subprocess.Popen(
        [_rerun_binary(), "--bind", "127.0.0.1", "--port", str(port), "--save", str(saved)],
        env=dict(os.environ, RERUN_APP_ONLY="true", RUST_LOG="off"),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.1)
        url = f"rerun+http://127.0.0.1:{port}/proxy"
        if how == "--spawn":
            from corraoi.recorder.live import viewers as live

            monkeypatch.setenv("DISPLAY", ":99")
            monkeypatch.setattr(live, "spawn_viewer", lambda: url)
            res = run("-p", "cts", "-T", "2000", "-o", str(tmp_path / "v.mcap"), "--spawn")
        else:
            res = run("-p", "cts", "-T", "2000", "-o", str(tmp_path / "v.mcap"), "--connect", url)
        assert res.exit_code == 0, res.output
    finally:
        server.terminate()
        server.wait(timeout=15)
    cmp = subprocess.run([_rerun_binary(), "rrd", "compare", str(saved), str(tmp_path / "v.rrd")],
                         capture_output=True, text=True)  # fmt: skip
    assert cmp.returncode == 0, cmp.stdout + cmp.stderr


@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_serve_web_binds_loopback_and_stops_on_a_signal(tmp_path, stop):
    web = free_port()
    proc = cli("-T", "2000", "-o", "w.mcap", "--serve-web", "--web-port", str(web), cwd=tmp_path,
               start_new_session=True)  # fmt: skip
    try:
        lines = _read_lines(proc.stderr, until="Ctrl-C to stop", timeout=60)
        url = next(line.split("web viewer: ")[1] for line in lines if "web viewer: " in line)
        assert url.startswith(f"http://127.0.0.1:{web}/?url=rerun%2Bhttp")
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=10) as page:
            assert page.status == 200
        listening = subprocess.run(["ss", "-ltn"], capture_output=True, text=True).stdout
        bound = [ln for ln in listening.splitlines() if f":{web} " in ln]
        assert bound and all("127.0.0.1:" in ln for ln in bound), bound
        proc.send_signal(stop)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    with socket.socket() as s:  # the server went with us
        assert s.connect_ex(("127.0.0.1", web)) != 0
    assert open_log(tmp_path / "w.mcap").n_slots == 2000


def test_the_web_server_does_not_outlive_a_killed_record(tmp_path):
    web = free_port()
    proc = cli("-T", "50000000", "-o", "k.mcap", "--no-rrd", "--serve-web", "--web-port", str(web),
               cwd=tmp_path, start_new_session=True)  # fmt: skip
    try:
        _read_lines(proc.stderr, until="web viewer: ", timeout=60)
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=10) as page:
            assert page.status == 200
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", web)) != 0:
                break
        time.sleep(0.1)
    else:
        raise AssertionError(f"the web server on port {web} outlived the killed record")


def _read_lines(stream, *, until: str, timeout: float) -> list[str]:
    lines: list[str] = []
    buf = b""
    deadline = time.monotonic() + timeout
    fd = stream.fileno()
    while time.monotonic() < deadline:
        ready, _, _ = select.select([fd], [], [], 0.5)
        if not ready:
            continue
        chunk = os.read(fd, 65536)
        if not chunk:
            break
        buf += chunk
        *done, buf = buf.split(b"\n")
        lines += [d.decode() for d in done]
        if any(until in line for line in lines):
            return lines
    raise AssertionError(f"no {until!r} within {timeout} s: {lines} {buf!r}")


# ---------------------------------------------------------------------------- faults


def test_a_full_disk_is_one_clear_line_and_no_file_passes_as_complete(tmp_path):
    def limit() -> None:  # writes past 600 kB fail with EFBIG ("File too large")
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    proc = cli("-T", "60000", "-o", "d.mcap", cwd=tmp_path, preexec_fn=limit)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, err
    text = err.decode().strip()
    assert text.startswith("corraoi: error: ") and "\n" not in text and "File too large" in text
    assert not (tmp_path / "d.mcap").exists() and not (tmp_path / "d.rrd").exists()
    assert partial_path(tmp_path / "d.mcap").exists()


def test_an_rrd_that_cannot_be_finished_is_not_presented_as_complete(tmp_path):
    def limit() -> None:  # the .rrd (~150 B a slot) passes 1.5 MB, the MCAP (~50) does not
        resource.setrlimit(resource.RLIMIT_FSIZE, (1_500_000, 1_500_000))

    proc = cli("-T", "15000", "-o", "e.mcap", cwd=tmp_path, preexec_fn=limit)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    text = err.decode().strip()
    assert text.startswith("corraoi: error: ") and "\n" not in text
    assert "e.rrd.partial" in text and "MCAP log e.mcap is complete" in text
    assert not (tmp_path / "e.rrd").exists() and partial_path(tmp_path / "e.rrd").exists()
    assert open_log(tmp_path / "e.mcap").status == "complete"


# ---------------------------------------------------------------------------- signals


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_leaves_both_files_finished_with_every_slot_so_far(tmp_path, sig):
    proc = cli("-T", "50000000", "-o", "s.mcap", cwd=tmp_path)
    _wait_for(partial_path(tmp_path / "s.mcap"), size=200_000, proc=proc)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    err_text = err.decode().strip()
    assert err_text.count("\n") == 0 and f"interrupted ({sig.name})" in err_text
    slots = int(re.search(rb": (\d+) of 50000000 slots \(interrupted\)", out).group(1))
    log = open_log(tmp_path / "s.mcap")
    assert (log.n_slots, log.finished, log.status) == (slots, True, "interrupted")
    assert log.read_all().equals(engine_prefix(log.config, slots))
    from rerun.chunk import RrdReader

    store = RrdReader(tmp_path / "s.rrd").store()  # has its footer: finished
    assert store is not None
    aoi = [c for c in RrdReader(tmp_path / "s.rrd").stream() if c.entity_path.endswith("/aoi")]
    assert sum(c.num_rows for c in aoi if not c.is_static) == slots
    assert not partial_path(tmp_path / "s.mcap").exists()
    assert not partial_path(tmp_path / "s.rrd").exists()


def _wait_for(path: Path, *, size: int, proc: subprocess.Popen, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        if path.exists() and path.stat().st_size >= size:
            return
        time.sleep(0.05)
    raise AssertionError(f"{path} did not reach {size} bytes")


def test_sigkill_leaves_a_log_recovered_up_to_the_last_1000_slots(tmp_path):
    """The progress bar (on a terminal) says how far the run got; after SIGKILL the reader
    recovers at least all of it but the last 2,000 slots (the open chunk, and the one a
    second thread may have been writing)."""
    import pty

    master, slave = pty.openpty()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(
        [PYTHON, "-m", "corraoi.cli", "record", "-T", "50000000", "-o", "k.mcap"],
        cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=slave,
    )  # fmt: skip
    os.close(slave)
    seen = 0
    buf = b""
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and seen < 40_000:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                buf = (buf + os.read(master, 65536))[-4096:]
                found = re.findall(rb"cucb-I1-s0 slot (\d+)", buf)
                if found:
                    seen = int(found[-1])
        assert seen >= 40_000, buf
        proc.kill()
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    assert not (tmp_path / "k.mcap").exists() and not (tmp_path / "k.rrd").exists()
    log = open_log(partial_path(tmp_path / "k.mcap"))
    assert log.cut_short and log.status == "truncated" and not log.finished
    assert log.n_slots >= seen - 2000 and log.n_slots % 1000 == 0
    assert "killed" in log.summary
    assert log.read_all().equals(engine_prefix(log.config, log.n_slots))
    assert partial_path(tmp_path / "k.rrd").stat().st_size > 0
