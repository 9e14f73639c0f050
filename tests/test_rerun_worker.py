"""The Rerun recording written by a forked worker (recorder/rerun/worker.py, issue 22): the
same recording as in-process, bad paths refused before the run, a worker that dies or a
parent that dies handled with one line or a ``.partial`` file, Ctrl-C to the whole process
group, and no pandas in the worker either."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from corraoi.engine.block import RunConfig
from corraoi.errors import OutputError, WriteError
from corraoi.face.recording import record_run
from corraoi.files.partial import partial_path
from corraoi.model.instance import load_instance
from corraoi.policies import make_policies
from corraoi.recorder.rerun.worker import RerunWorker
from corraoi.recorder.slotlog.reader import open_log

from .rrd_util import RERUN, read_rrd
from .test_cli_record import _wait_for

PYTHON = sys.executable
ROOT = Path(__file__).resolve().parent.parent


def _config(horizon: int = 3000, policy: str = "cucb") -> RunConfig:
    spec = make_policies((policy,), {})[0]
    return RunConfig(load_instance("I1"), spec, 7, horizon)


def _worker() -> RerunWorker:
    worker = RerunWorker(None)  # not .start(): the test runner may run threads of its own
    return worker


def test_the_worker_writes_the_recording_an_in_process_sink_writes(tmp_path):
    config = _config()
    with _worker() as worker:
        out = record_run(config, tmp_path / "w.mcap", rrd=tmp_path / "w.rrd", rerun=worker)
    assert out.rrd == tmp_path / "w.rrd" and out.slots == 3000
    record_run(config, tmp_path / "p.mcap", rrd=tmp_path / "p.rrd")
    cmp = subprocess.run([RERUN, "rrd", "compare", str(tmp_path / "w.rrd"),
                          str(tmp_path / "p.rrd")], capture_output=True, text=True)  # fmt: skip
    assert cmp.returncode == 0, cmp.stdout + cmp.stderr
    slots, _ = read_rrd(tmp_path / "w.rrd")[f"/runs/{config.label}/aoi"]
    assert list(slots) == list(range(1, 3001))
    assert (tmp_path / "w.mcap").read_bytes() == (tmp_path / "p.mcap").read_bytes()
    assert not partial_path(tmp_path / "w.rrd").exists()


def test_several_runs_one_after_the_other_in_one_worker(tmp_path):
    with _worker() as worker:
        for pol in ("ucb", "cucb"):
            config = _config(500, pol)
            record_run(config, tmp_path / f"{pol}.mcap", rrd=tmp_path / f"{pol}.rrd", rerun=worker)
            slots, aoi = read_rrd(tmp_path / f"{pol}.rrd")[f"/runs/{config.label}/aoi"]
            log = open_log(tmp_path / f"{pol}.mcap").read_all()
            assert list(slots) == list(range(1, 501))
            assert [v[0] for v in aoi] == [float(a) for a in log.aoi]


def test_a_bad_rrd_path_is_refused_before_the_run(tmp_path):
    (tmp_path / "taken.rrd").write_bytes(b"keep me")
    with _worker() as worker:
        with pytest.raises(OutputError, match="taken.rrd: already exists"):
            worker.open(_config(), rrd_path=tmp_path / "taken.rrd")
        with pytest.raises(OutputError, match="is a directory"):
            worker.open(_config(), rrd_path=tmp_path)
    assert (tmp_path / "taken.rrd").read_bytes() == b"keep me"


def test_a_worker_that_dies_is_one_line_and_the_mcap_log_is_complete(tmp_path):
    worker = _worker()
    try:
        worker.process.kill()
        worker.process.join(5)
        with pytest.raises(WriteError) as err:
            record_run(_config(), tmp_path / "d.mcap", rrd=tmp_path / "d.rrd", rerun=worker)
    finally:
        worker.stop()
    text = str(err.value)
    assert "the Rerun writer process ended unexpectedly (exit code -9)" in text
    assert "\n" not in text
    assert open_log(tmp_path / "d.mcap").status == "complete"
    assert not (tmp_path / "d.rrd").exists()


def test_an_abort_leaves_the_partial_file_or_discards_it(tmp_path):
    with _worker() as worker:
        rec = worker.open(_config(), rrd_path=tmp_path / "a.rrd")
        assert rec.abort() == partial_path(tmp_path / "a.rrd")
        assert partial_path(tmp_path / "a.rrd").exists() and not (tmp_path / "a.rrd").exists()
        rec = worker.open(_config(), rrd_path=tmp_path / "b.rrd")
        assert rec.abort(discard=True) is None
        assert not partial_path(tmp_path / "b.rrd").exists()


def _record(args: list[str], cwd: Path, **kw) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([PYTHON, "-m", "corraoi.cli", "record", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)  # fmt: skip


def _children(pid: int) -> list[int]:
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids = (task / "children").read_text().split()
        found.extend(int(k) for k in kids)
    return found


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_ctrl_c_to_the_process_group_finishes_both_files(tmp_path):
    """A terminal's Ctrl-C reaches the worker too: it ignores it and finishes the .rrd on
    the parent's word, with every slot the log holds."""
    proc = _record(["-T", "50000000", "-o", "g.mcap"], tmp_path, start_new_session=True)
    _wait_for(partial_path(tmp_path / "g.rrd"), size=300_000, proc=proc)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    log = open_log(tmp_path / "g.mcap")
    assert log.status == "interrupted"
    slots, _ = read_rrd(tmp_path / "g.rrd")[f"/runs/{log.config.label}/aoi"]
    assert len(slots) == log.n_slots and slots[-1] == log.n_slots


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_a_killed_record_leaves_no_worker_behind(tmp_path):
    proc = _record(["-T", "50000000", "-o", "k.mcap"], tmp_path)
    _wait_for(partial_path(tmp_path / "k.rrd"), size=300_000, proc=proc)
    kids = _children(proc.pid)
    assert len(kids) == 1  # the worker
    proc.kill()
    proc.communicate(timeout=30)
    deadline = time.monotonic() + 30
    while Path(f"/proc/{kids[0]}").exists() and time.monotonic() < deadline:
        status = Path(f"/proc/{kids[0]}/status")
        if status.exists() and "zombie" in status.read_text():
            break
        time.sleep(0.1)
    status = Path(f"/proc/{kids[0]}/status")
    assert not status.exists() or "zombie" in status.read_text()
    assert partial_path(tmp_path / "k.rrd").exists() and not (tmp_path / "k.rrd").exists()


_PROBE = """
import json, os, sys
import corraoi.recorder.rerun.worker as w
serve = w.serve
def spy(*args):
    try:
        serve(*args)
    finally:
        heavy = sorted(m for m in ("numba", "rerun", "pandas", "pyarrow") if m in sys.modules)
        with open("child.json", "w") as f:
            json.dump(heavy, f)
w.serve = spy
from corraoi.cli import main
try:
    main(sys.argv[1:])
except SystemExit as exc:
    assert not exc.code, exc.code
heavy = sorted(m for m in ("numba", "rerun", "pandas", "pyarrow") if m in sys.modules)
print("PARENT " + json.dumps(heavy))
"""


def test_the_engine_and_rerun_load_in_different_processes_and_pandas_in_none(tmp_path):
    args = ["record", "--policy", "ucb", "-T", "20", "-o", "r.mcap"]
    proc = subprocess.run([PYTHON, "-c", _PROBE, *args], cwd=tmp_path, capture_output=True,
                          text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    parent = [x for x in proc.stdout.splitlines() if x.startswith("PARENT ")]
    assert json.loads(parent[-1][len("PARENT ") :]) == ["numba"]
    assert json.loads((tmp_path / "child.json").read_text()) == ["pyarrow", "rerun"]
    assert (tmp_path / "r.rrd").is_file()
