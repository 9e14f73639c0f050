"""Signals at random moments: exit 130 (or 0 if the run had finished), never a traceback,
never a lost or half-written run, never an orphaned child process.

Subprocesses, since signals are involved; bounded: a handful of seeded random moments.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from corraoi.engine.block import RunConfig
from corraoi.engine.simulation import simulate_run
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink

CORRAOI = [sys.executable, "-m", "corraoi"]


def _alive(pid: int) -> bool:
    """A process that exists and is not a zombie (a dead child nobody reaped)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def _children(pid: int) -> list[int]:
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


def _check_stderr(err: str) -> None:
    assert "Traceback" not in err and "Exception ignored" not in err, err
    for line in err.splitlines():
        assert line.startswith("corraoi: "), err


# moments: seconds after the start (start-up imports, the run, the finalisation); from
# 0.3 s on, when the interpreter has surely imported corraoi (before it, Python's own
# default handling applies)
_RNG = random.Random(11)
MOMENTS = [_RNG.uniform(lo, hi) for lo, hi in ((0.3, 0.9), (0.9, 1.6), (1.6, 2.4), (2.0, 3.0),
                                                (0.3, 3.0))]  # fmt: skip


@pytest.mark.parametrize(
    ("delay", "sig"),
    [(d, (signal.SIGINT, signal.SIGTERM)[i % 2]) for i, d in enumerate(MOMENTS)],
    ids=[f"{d:.2f}s-{('INT', 'TERM')[i % 2]}" for i, d in enumerate(MOMENTS)],
)
def test_record_interrupted_at_a_random_moment(tmp_path, delay, sig):
    proc = subprocess.Popen(
        [*CORRAOI, "record", "-p", "cucb", "-T", "60000"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "RUST_LOG": "off"},
    )  # fmt: skip
    time.sleep(delay)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    _check_stderr(err)
    assert proc.returncode in (0, 130), (proc.returncode, err)
    runs = tmp_path / "runs"
    names = sorted(os.listdir(runs)) if runs.exists() else []
    assert not any(n.endswith(".partial") for n in names), names  # nothing half-written
    if proc.returncode == 0:
        assert names == ["cucb-I1-s0.mcap", "cucb-I1-s0.rrd"]
    if "cucb-I1-s0.mcap" in names:  # once the run started: a finished log
        log = open_log(runs / "cucb-I1-s0.mcap")
        assert log.finished and log.status in ("interrupted", "complete")
        if proc.returncode == 130 and log.status == "interrupted":
            assert f"after slot {log.n_slots} of 60000" in err
    else:
        assert proc.returncode == 130 and err.strip().endswith("interrupted"), err
    assert not [c for c in _children(proc.pid) if _alive(c)]


@pytest.fixture(scope="module")
def long_log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("long") / "long.mcap"
    config = RunConfig(load_instance("I1"), make_policy("ucb"), 0, 400_000)
    with McapSink(path, config, fsync=False) as sink:
        for block in simulate_run(config.instance, config.policy, 0, config.horizon):
            sink.write(block)
    return path


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_replay_interrupted_is_one_line_and_no_rrd(tmp_path, long_log, sig):
    proc = subprocess.Popen(
        [*CORRAOI, "replay", str(long_log), "-o", str(tmp_path / "r.rrd")],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "RUST_LOG": "off"},
    )  # fmt: skip
    deadline = time.monotonic() + 30
    while not (tmp_path / "r.rrd.partial").exists() and time.monotonic() < deadline:
        time.sleep(0.02)  # the recording has started
    assert proc.poll() is None, "the replay finished before it was interrupted"
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and err.strip().endswith("corraoi: interrupted"), err
    _check_stderr(err)
    assert not (tmp_path / "r.rrd").exists()  # nothing presented as complete
    assert not [c for c in _children(proc.pid) if _alive(c)]


def test_a_ctrl_c_that_no_command_caught_is_one_line_without_a_blank_one(tmp_path):
    """A Ctrl-C during start-up (the group's imports) reaches click, which printed an empty
    line before our one line; the group now turns it into the same single line and 130."""
    probe = (
        "import sys\n"
        "from corraoi.cli import main, run\n"
        "@main.command('boom')\n"
        "def boom():\n"
        "    raise KeyboardInterrupt\n"
        "sys.argv = ['corraoi', 'boom']\n"
        "run()\n"
    )
    proc = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60)  # fmt: skip
    assert (proc.returncode, proc.stderr) == (130, "corraoi: interrupted\n")


def test_an_interrupt_python_can_only_print_is_sent_again_not_lost():
    """A signal whose KeyboardInterrupt lands where Python swallows it (here a fork's own
    hook; in the wild a finaliser during a replay) prints no traceback and is not lost: it
    is raised again once that code has returned, so the command stops with its one line."""
    code = (
        "import os, signal\n"
        "from corraoi import _signals\n"
        "_signals.install()\n"
        "os.register_at_fork(after_in_parent=lambda: os.kill(os.getpid(), signal.SIGTERM))\n"
        "try:\n"
        "    pid = os.fork()\n"
        "    if pid == 0:\n"
        "        os._exit(0)\n"
        "    for _ in range(10**6):\n"
        "        pass\n"
        "    print('lost')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted after the fork')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "interrupted after the fork"
    assert out.stderr == ""
