"""Compiled hooks under the plain-Python policies' contract (issue 32): an arm out of range
or a NaN score for a candidate ends the run with one line naming the policy, the run and the
slot -- the log finished at ``.partial``, status failed; in a sweep nothing written as
complete -- never a crash or a result from memory out of bounds. +inf is a score. A plug-in
class that raises while it is made is one line too."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from corraoi.engine.simulation import Simulation
from corraoi.errors import PolicyRuntimeError
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log

PLUGINS = Path(__file__).parent / "plugins" / "bad_compiled.py"


def _cli(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


def _error(res: subprocess.CompletedProcess[str], code: int = 1) -> str:
    assert res.returncode == code, (res.returncode, res.stderr)
    lines = [ln for ln in res.stderr.splitlines() if not ln.startswith("corraoi: compiling")]
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("corraoi: error: ")
    return lines[0]


def test_a_forced_arm_of_a_million_ends_the_run_at_its_slot(tmp_path: Path):
    line = _error(_cli("record", "-p", f"{PLUGINS}:FarArm", "--seed", 4, "-T", 500, "-o",
                       "far.mcap", cwd=tmp_path))  # fmt: skip
    assert line == (
        "corraoi: error: policy far-arm, slot 7: its forced hook returned arm 1000000 for run 0 "
        "(seed 4); expected 0..3, or a negative number for none (0-based; arm k+1 in logs); "
        "the log is left as far.mcap.partial, marked failed"
    )
    assert not (tmp_path / "far.mcap").exists() and not (tmp_path / "far.rrd").exists()
    log = open_log(tmp_path / "far.mcap.partial")
    assert (log.status, log.n_slots) == ("failed", 6)
    assert log.end["error"].startswith("policy far-arm, slot 7: its forced hook returned")


def test_a_nan_score_for_a_candidate_ends_the_run_at_its_slot(tmp_path: Path):
    line = _error(_cli("record", "-p", f"{PLUGINS}:NaNScore", "-T", 500, "--no-rrd", "-o",
                       "nan.mcap", cwd=tmp_path))  # fmt: skip
    assert line == (
        "corraoi: error: policy nan-score, slot 9: its score hook gave NaN to arm 3, a "
        "candidate, for run 0 (seed 0); a score must be a number (+inf is one); the log is "
        "left as nan.mcap.partial, marked failed"
    )
    log = open_log(tmp_path / "nan.mcap.partial")
    assert (log.status, log.n_slots) == ("failed", 8) and len(log.read_all()) == 8


@pytest.mark.parametrize("seeds", [range(5), range(1000, 1003)])
def test_the_engine_names_the_first_faulty_slot_over_many_runs(seeds: range):
    sim = Simulation(load_instance("I2"), make_policy(f"{PLUGINS}:FarArm", at=40), seeds, 300,
                     first_run=12)  # fmt: skip
    with pytest.raises(PolicyRuntimeError) as info:
        sim.advance(300)
    assert str(info.value).startswith(f"policy far-arm, slot 40: its forced hook returned arm "
                                      f"1000000 for run 12 (seed {seeds[0]})")  # fmt: skip
    block = info.value.partial  # every slot before the fault, no slot after it
    assert block is not None and block.t.tolist() == list(range(1, 40))
    assert (block.arm >= 0).all() and (block.arm < 4).all()


def test_a_fault_in_a_sweep_writes_nothing_as_complete_and_names_the_run(tmp_path: Path):
    line = _error(_cli("sweep", "-p", f"ucb,{PLUGINS}:FarArm", "--param", "far-arm.at=20",
                       "-n", 6, "-T", 300, "--chunk", 3, "--seed", 100, "-o", "sw",
                       cwd=tmp_path))  # fmt: skip
    assert line.startswith("corraoi: error: policy far-arm, slot 20: its forced hook returned "
                           "arm 1000000 for run 0 (seed 100)")  # fmt: skip
    sw = tmp_path / "sw"
    assert not [p for p in sw.rglob("*") if p.name in ("results.parquet", "sweep.mcap",
                                                       "sweep.rrd", "figure.png")]  # fmt: skip
    assert json.loads((sw / "manifest.json").read_text())["status"] == "running"
    far = [p for p in (sw / "parts").iterdir()]
    keys = {c["policy"]["name"]: c for c in json.loads((sw / "manifest.json").read_text())
            ["grid"]["cells"]}  # fmt: skip
    assert far and all(not p.name.startswith("far") for p in far)  # only ucb's parts
    assert len(keys) == 2
    again = _error(_cli("sweep", "-p", f"ucb,{PLUGINS}:FarArm", "--param", "far-arm.at=20",
                        "-n", 6, "-T", 300, "--chunk", 3, "--seed", 100, "-o", "sw",
                        "--resume", cwd=tmp_path))  # one line again, never stuck  # fmt: skip
    assert "policy far-arm, slot 20" in again


def test_plus_infinity_is_a_score_and_runs_unchanged():
    """A compiled UCB that scores unpulled arms +inf (ties at +inf broken at random from
    the policy stream) plays, slot for slot, the arms of the same rule in plain Python,
    which no compiled check touches."""
    inst = load_instance("I1")
    for seed in (0, 7, 2024):
        arms = []
        for ref in (f"{PLUGINS}:InfUCB", f"{PLUGINS}:InfUCBPython"):
            sim = Simulation(inst, make_policy(ref), [seed], 3000)
            block = sim.advance(3000)
            assert block is not None
            arms.append(block.arm[0])
        assert np.array_equal(arms[0], arms[1]), seed
        assert len(set(arms[0][:4].tolist())) == 4  # every arm first, in a random order


def test_a_plugin_class_that_raises_when_made_is_one_line(tmp_path: Path):
    want = ("policy raises-in-init: creating it (RaisesInInit.__init__) raised RuntimeError: "
            "no licence for this policy")  # fmt: skip
    line = _error(_cli("record", "-p", f"{PLUGINS}:RaisesInInit", "-T", 50, "-o", "r.mcap",
                       cwd=tmp_path))  # fmt: skip
    assert line.startswith(f"corraoi: error: {want}")
    assert not list(tmp_path.glob("r.*"))  # before slot 1: no log, no recording
    line = _error(_cli("sweep", "-p", f"{PLUGINS}:RaisesInInit", "-n", 3, "-T", 50,
                       cwd=tmp_path))  # fmt: skip
    assert line == f"corraoi: error: {want}"


@pytest.mark.parametrize(("ref", "code", "want"), [
    ("RaisingScore", 1, "policy raising-score, slots 1..50: a compiled hook raised ValueError: "
                        "score gave up"),
    ("WrongSignature", 2, "the engine for wrong-signature cannot be built in "),
    ("NegativeState", 2, "policy negative-state: its state_size returned -5; expected a whole "
                         "number of float64 entries per run, 0..1048576"),
    ("HugeState", 2, "policy huge-state: its state_size returned 1000000000000000; expected"),
    ("RaisingState", 2, "policy raising-state: its state_size raised RuntimeError: state size "
                        "unknown"),
])  # fmt: skip
def test_a_compiled_plugin_that_misbehaves_in_any_hook_is_one_line(tmp_path: Path, ref: str,
                                                                   code: int, want: str):
    line = _error(_cli("record", "-p", f"{PLUGINS}:{ref}", "-T", 50, "--no-rrd", "-o", "x.mcap",
                       cwd=tmp_path), code)  # fmt: skip
    assert line.startswith(f"corraoi: error: {want}"), line
    assert not (tmp_path / "x.mcap").exists()
    if ref == "RaisingScore":  # in a sweep too, its chunks on the engine's threads
        line = _error(_cli("sweep", "-p", f"{PLUGINS}:{ref}", "-n", 40, "-T", 3000, "-j", 2,
                           cwd=tmp_path))  # fmt: skip
        assert "a compiled hook raised ValueError: score gave up" in line


@pytest.mark.parametrize("what", [1, 2, 3], ids=["npull", "nsucc", "a-pull-moved"])
def test_a_hook_writing_the_counts_ends_the_record_at_its_slot(what: int):
    sim = Simulation(load_instance("I1"), make_policy(f"{PLUGINS}:WritesCounts", what=what,
                                                      at=7), range(3, 6), 200)  # fmt: skip
    with pytest.raises(PolicyRuntimeError) as info:
        sim.advance(200)
    assert str(info.value) == (
        "policy writes-counts, slot 7: a compiled hook wrote into npull or nsucc for run 0 "
        "(seed 3); hooks may write only vals (score) and ps, and read the rest"
    )
    block = info.value.partial  # the slots before it, whose counts are the engine's
    assert block is not None and block.t.tolist() == list(range(1, 7))


def test_a_hook_writing_the_counts_is_caught_in_a_sweep_too():
    sim = Simulation(load_instance("I1"), make_policy(f"{PLUGINS}:WritesCounts", what=1,
                                                      at=50), range(4), 300)  # fmt: skip
    says = r"^policy writes-counts, slots 1\.\.300: a compiled hook wrote into npull or nsucc "
    with pytest.raises(PolicyRuntimeError, match=says + r"for run 0 \(seed 0\)"):
        sim.advance_to(300)


def test_a_hook_writing_its_parameters_ends_the_run(tmp_path: Path):
    import corraoi

    with pytest.raises(PolicyRuntimeError, match=r"slots 1001\.\.2000: a compiled hook wrote "
                       r"into params; hooks may write only"):  # fmt: skip
        corraoi.record(f"{PLUGINS}:WritesCounts", "I1", params={"what": 4, "at": 1500},
                       horizon=2500, path=tmp_path / "p.mcap", rrd=False)  # fmt: skip
    assert not (tmp_path / "p.mcap").exists()  # the blocks before it, marked failed
    log = open_log(tmp_path / "p.mcap.partial", verify=False)
    assert (log.status, log.n_slots) == ("failed", 1000)
    clean = Simulation(load_instance("I1"), make_policy(f"{PLUGINS}:WritesCounts"), [0], 300)
    assert clean.advance(300) is not None  # writing nothing: the checks pass
