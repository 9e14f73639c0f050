"""Plug-ins that misbehave while loading or running (issue 19): each gets one line naming the
plug-in and what it did, a non-zero exit and no traceback; a hang at import ends cleanly on
Ctrl-C (exit 130); a failing select/update leaves the log finished and marked failed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

_GOOD = '''
import numpy as np
from corraoi.policies import Policy


class P(Policy):
    name = "misbehaving"

    def select(self, t, state):
        {select}
        return state.rng.argmax(state.mu_hat)

    def update(self, t, arms, rewards, state):
        {update}
'''


def _plugin(tmp: Path, top: str = "", select: str = "pass", update: str = "pass") -> str:
    path = tmp / "bad_plugin.py"
    path.write_text(top + "\n" + _GOOD.format(select=select, update=update))
    return f"{path}:P"


def _record(tmp: Path, policy: str, *extra: str, timeout: float = 120):
    cmd = [sys.executable, "-m", "corraoi.cli", "record", "--policy", policy, "-T", "50",
           "--no-rrd", "-o", str(tmp / "out.mcap"), *extra]  # fmt: skip
    return subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=timeout)


def _one_line(res: subprocess.CompletedProcess[str]) -> str:
    assert "Traceback" not in res.stderr, res.stderr
    lines = [x for x in res.stderr.splitlines() if x.strip()]
    assert len(lines) == 1, res.stderr[-2000:]
    return lines[0]


@pytest.mark.parametrize(
    ("top", "says"),
    [
        ("import sys; sys.exit(3)", "called sys.exit(3) while loading"),
        ("import sys; sys.exit('bye')", "called sys.exit('bye') while loading"),
        ("raise SystemExit", "called sys.exit(None) while loading"),
        ("import os; os._exit(4)", "called os._exit(4) while loading"),
        ("raise RuntimeError('no GPU in the plug-in')", "RuntimeError: no GPU in the plug-in"),
        ("raise KeyError('x')", "importing"),
        ("import no_such_module_for_corraoi", "ModuleNotFoundError"),
        ("class E(BaseException): pass\nraise E('odd')", "E: odd"),
        ("def f(): f()\nf()", "RecursionError"),
        ("x = (", "SyntaxError"),
    ],
    ids=["sys.exit(3)", "sys.exit(str)", "SystemExit", "os._exit", "RuntimeError", "KeyError",
         "missing-import", "BaseException", "recursion", "syntax"],
)  # fmt: skip
def test_a_plugin_failing_at_import_gets_one_line(tmp_path: Path, top: str, says: str):
    res = _record(tmp_path, _plugin(tmp_path, top))
    assert res.returncode != 0
    line = _one_line(res)
    assert "bad_plugin.py" in line and says in line, line
    assert not (tmp_path / "out.mcap").exists()


@pytest.mark.parametrize(
    "top",
    [
        "print('x' * 5_000_000)",
        "import sys; sys.stderr.write('y' * 3_000_000)",
        "import os; os.write(1, b'z' * 4_000_000)",
    ],
    ids=["print", "stderr", "fd-write"],
)
def test_megabytes_of_output_at_import_become_one_line(tmp_path: Path, top: str):
    res = _record(tmp_path, _plugin(tmp_path, top))
    assert res.returncode == 0, res.stderr[-500:]
    noise = [x for x in res.stderr.splitlines() if "while loading" in x]
    assert len(noise) == 1 and "bytes while loading (not shown)" in noise[0]
    assert len(res.stdout) + len(res.stderr) < 20_000
    assert (tmp_path / "out.mcap").exists()


def test_a_little_output_at_import_is_passed_on(tmp_path: Path):
    res = _record(tmp_path, _plugin(tmp_path, "print('plug-in says hello')"))
    assert res.returncode == 0, res.stderr
    assert "plug-in says hello" in res.stdout + res.stderr


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_hang_at_import_ends_cleanly_on_a_signal(tmp_path: Path, sig: int):
    policy = _plugin(tmp_path, "import time\nopen('started', 'w').close()\ntime.sleep(600)")
    cmd = [sys.executable, "-m", "corraoi.cli", "record", "--policy", policy, "-T", "50",
           "--no-rrd", "-o", str(tmp_path / "out.mcap")]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)  # fmt: skip
    deadline = time.monotonic() + 60
    while not (tmp_path / "started").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    sent = time.monotonic()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=30)
    assert time.monotonic() - sent < 2.0
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err
    assert os.listdir(tmp_path) == ["bad_plugin.py", "started"] or not (
        tmp_path / "out.mcap"
    ).exists()


def test_a_failure_before_the_first_slot_leaves_no_file_and_says_so(tmp_path: Path):
    res = _record(tmp_path, _plugin(tmp_path, select="raise SystemExit(5)"))
    assert res.returncode == 1
    line = _one_line(res)
    assert "slot 1: select raised SystemExit: 5" in line and "no log written" in line, line
    assert sorted(set(os.listdir(tmp_path)) - {"__pycache__"}) == ["bad_plugin.py"]


@pytest.mark.parametrize(
    ("select", "update", "says"),
    [
        ("if t >= 3: __import__('sys').exit(5)", "pass", "slot 3: select raised SystemExit: 5"),
        ("pass", "raise SystemExit('stop')", "slot 1: update raised SystemExit: stop"),
        ("if t >= 3: raise GeneratorExit()", "pass", "slot 3: select raised GeneratorExit"),
    ],
    ids=["sys.exit-in-select", "SystemExit-in-update", "GeneratorExit-in-select"],
)
def test_a_base_exception_while_running_is_reported_like_any_failure(
    tmp_path: Path, select: str, update: str, says: str
):
    res = _record(tmp_path, _plugin(tmp_path, select=select, update=update))
    assert res.returncode != 0
    line = _one_line(res)
    assert says in line and "marked failed" in line, line
    partial = tmp_path / "out.mcap.partial"
    assert partial.exists()
    from corraoi.recorder.slotlog.reader import open_log

    assert open_log(partial, verify=False).status == "failed"
