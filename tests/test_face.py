"""The Python face (issue 33): corraoi.record / sweep / load / compare / diff, Run and Sweep,
policies defined in a test module, bad input as CorraoiError subclasses, an interrupted sweep
that resumes, and the command line writing the face's bytes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import corraoi
from corraoi import Param, Policy
from corraoi.recorder.slotlog.reader import open_log

ROOT = Path(__file__).resolve().parent.parent


class EpsilonFirst(Policy):
    """Play every arm in turn for the first ``explore`` slots, then the best empirical mean."""

    name = "face-eps-first"
    params = {"explore": Param(20.0, "slots of round-robin exploration", low=1, integer=True)}

    def select(self, t: int, state):  # type: ignore[no-untyped-def]
        R, K = state.pulls.shape
        if t <= self.explore:
            return np.full(R, (t - 1) % K, dtype=np.int64)
        means = state.successes / np.maximum(state.pulls, 1)
        return means.argmax(axis=1).astype(np.int64)


def _cli(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True)  # fmt: skip


def test_record_writes_the_bytes_the_command_line_writes(tmp_path: Path) -> None:
    out = _cli("record", "-p", "cucb", "-T", "2500", "-s", "4", "-o", "cli/{label}.mcap",
               cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    run = corraoi.record("cucb", seed=4, horizon=2500, path=tmp_path / "py" / "{label}.mcap")
    cli = tmp_path / "cli" / "cucb-I1-s4.mcap"
    assert run.mcap == tmp_path / "py" / "cucb-I1-s4.mcap"
    assert run.mcap.read_bytes() == cli.read_bytes()
    assert run.rrd is not None and run.rrd.is_file()
    rerun = str(Path(sys.executable).parent / "rerun")
    same = subprocess.run([rerun, "rrd", "compare", str(run.rrd), str(cli.with_suffix(".rrd"))],
                          capture_output=True)  # fmt: skip
    assert same.returncode == 0, same.stderr
    # what was measured while recording is what the log says
    assert run.summary == corraoi.load(run.mcap).summary
    assert run.summary.regret == int(open_log(cli).read_all().regret[-1])


def test_record_returns_a_run_reused_when_up_to_date_and_refuses_another(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    a = corraoi.record("ucb", horizon=400, path=path, rrd=False)
    stamp = path.stat().st_mtime_ns
    again = corraoi.record("ucb", horizon=400, path=path, rrd=False)
    assert again.mcap == path and path.stat().st_mtime_ns == stamp  # nothing ran
    with pytest.raises(corraoi.OutputError, match="force=True"):
        corraoi.record("ucb", horizon=400, seed=1, path=path, rrd=False)
    b = corraoi.record("ucb", horizon=400, seed=1, path=path, rrd=False, force=True)
    assert b.log.config.seed == 1 and b.mcap == a.mcap == path


def test_a_policy_class_from_this_module_records_with_params(tmp_path: Path) -> None:
    run = corraoi.record(EpsilonFirst, seed=3, horizon=600, params={"explore": 40},
                         path=tmp_path / "{label}.mcap", rrd=False)  # fmt: skip
    cfg = run.log.config
    assert cfg.policy.name == "face-eps-first" and cfg.policy.params == {"explore": 40.0}
    arms = run.log.read_all().arm
    assert arms[:40].tolist() == [t % 4 for t in range(40)]  # the round-robin it declares
    # an instance of the class carries its parameters; the log names the class's source
    other = corraoi.record(EpsilonFirst(explore=8), seed=3, horizon=600,
                           path=tmp_path / "{label}-b.mcap", rrd=False)  # fmt: skip
    assert other.log.config.policy.params == {"explore": 8.0}
    plugin = run.log.config.policy.to_dict()["plugin"]
    assert plugin["qualname"].endswith(":EpsilonFirst")
    assert plugin["sha256"] == __import__("hashlib").sha256(Path(__file__).read_bytes()).hexdigest()


def test_bad_input_is_a_corraoi_error_that_says_what_was_expected(tmp_path: Path) -> None:
    cases = [
        (dict(policy=42), corraoi.PolicyError, "expected a policy"),
        (dict(policy="no-such-policy"), corraoi.PolicyError, "unknown policy"),
        (dict(policy=EpsilonFirst, params={"zeta": 1}), corraoi.PolicyError,
         "zeta does not apply"),
        (dict(policy=EpsilonFirst, params={"explore": "many"}), corraoi.UsageError,
         "expected a number"),
        (dict(policy="cucb", instance={"p": [1.0]}), corraoi.InstanceError,
         "expected a built-in name"),
        (dict(policy="cucb", instance=tmp_path / "none.txt"), corraoi.InstanceError, "none"),
        (dict(policy="cucb", horizon=0), corraoi.ConfigError, "horizon"),
        (dict(policy=Policy), corraoi.PolicyError, "base class"),
    ]
    for kwargs, kind, words in cases:
        policy = kwargs.pop("policy")
        with pytest.raises(kind, match=words):
            corraoi.record(policy, path=tmp_path / "x.mcap", rrd=False, **kwargs)
    no_y = tmp_path / "no-y.json"
    no_y.write_text(json.dumps({"name": "half", "p": [0.5, 0.5]}))
    with pytest.raises(corraoi.InstanceError):
        corraoi.record("ucb", no_y, path=tmp_path / "y.mcap", rrd=False)
    assert not list(tmp_path.glob("*.mcap*"))  # nothing was written


def test_a_parameter_several_policies_take_is_warned_and_can_be_scoped(tmp_path: Path) -> None:
    with pytest.warns(corraoi.CorraoiWarning, match="params c applies to ucb, cucb"):
        sw = corraoi.sweep("I1", ["ucb", "cucb"], runs=4, horizon=200, params={"c": 1.0},
                           out=tmp_path / "a")  # fmt: skip
    params = {p["name"]: p["params"] for p in sw.config["policies"]}
    assert params == {"ucb": {"c": 1.0}, "cucb": {"c": 1.0}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sw = corraoi.sweep("I1", ["ucb", "cucb"], runs=4, horizon=200,
                           params={"cucb": {"c": [1.0, 3.0]}}, out=tmp_path / "b")  # fmt: skip
    params = sorted((p["name"], p["params"]["c"]) for p in sw.config["policies"])
    assert params == [("cucb(c=1)", 1.0), ("cucb(c=3)", 3.0), ("ucb", 2.0)]  # ucb: its default


def test_sweep_record_equals_the_sweeps_row_and_load_gives_the_same_types(tmp_path: Path) -> None:
    sw = corraoi.sweep("I2", ["ucb", EpsilonFirst], runs=12, horizon=800, seed=50,
                       out=tmp_path / "sw")  # fmt: skip
    assert isinstance(sw, corraoi.Sweep) and isinstance(corraoi.load(sw.folder), corraoi.Sweep)
    by_results = corraoi.load(sw.folder / "results.parquet")  # a partitioned folder
    assert isinstance(by_results, corraoi.Sweep) and by_results.folder == sw.folder
    assert len(by_results.runs) == len(sw.runs) > 0
    with pytest.raises(corraoi.CorraoiError, match="names 2 runs"):
        sw.record("worst")
    worst = sw.record("worst", policy=EpsilonFirst, path=tmp_path / "w.mcap")
    assert isinstance(worst, corraoi.Run) and isinstance(corraoi.load(worst.mcap), corraoi.Run)
    run = sw.notable["cells"]["face-eps-first"]["worst"]["run"]
    rows = sw.runs
    row = rows[(rows["policy"] == "face-eps-first") & (rows["run"] == run) & (rows["t"] == 800)]
    assert worst.summary.regret == row["regret"].item()
    assert worst.log.config.seed == 50 + run
    # the same run, recorded by the command line from the folder (the class is importable)
    html = sw._repr_html_()
    assert "face-eps-first" in html and "<table>" in html
    assert "<p>I2, 12 runs, T = 800: " in html  # the instance's name, not its dict
    share = sw.summary["policies"]["ucb"]["best_arm_share"]
    assert f"<td>{share:.3f}</td>" in html
    # recorded again to the same place (a cell run again): the run it holds, nothing runs
    stamp = worst.mcap.stat().st_mtime_ns
    same = sw.record("worst", policy=EpsilonFirst, path=tmp_path / "w.mcap")
    assert same.mcap == worst.mcap and worst.mcap.stat().st_mtime_ns == stamp
    again = sw.record("worst", policy=EpsilonFirst, path=tmp_path / "w.mcap", force=True)
    assert again.summary.regret == worst.summary.regret and again.complete


def test_record_each_records_every_cells_run_once_and_compare_takes_them(tmp_path: Path) -> None:
    sw = corraoi.sweep("I1", ["ucb", "cucb"], runs=10, horizon=600, seed=7,
                       out=tmp_path / "sw")  # fmt: skip
    said: list[str] = []
    runs = sw.record_each("median", folder=tmp_path / "runs", say=said.append)
    assert [r.log.config.policy.name for r in runs] == ["ucb", "cucb"] and len(said) == 2
    rows = sw.runs
    for r in runs:
        name = r.log.config.policy.name
        n = sw.notable["cells"][name]["median"]["run"]
        row = rows[(rows["policy"] == name) & (rows["run"] == n) & (rows["t"] == 600)]
        assert r.summary.regret == row["regret"].item() and r.log.config.seed == 7 + n
    stamps = [r.path.stat().st_mtime_ns for r in runs]
    again = sw.record_each("median", folder=tmp_path / "runs", say=said.append)
    assert len(said) == 2 and [r.path.stat().st_mtime_ns for r in again] == stamps  # reused
    import shutil

    shutil.copyfile(runs[1].path, runs[0].path)  # another run under the first one's name
    with pytest.raises(corraoi.OutputError, match="holds another run"):
        sw.record_each("median", folder=tmp_path / "runs")
    runs = sw.record_each("median", folder=tmp_path / "runs", force=True)
    assert runs[0].log.config.policy.name == "ucb"
    cmp = corraoi.compare(runs)
    assert [c.summary.regret for c in cmp.runs] == [r.summary.regret for r in runs]


def test_diff_and_compare_take_runs(tmp_path: Path) -> None:
    a = corraoi.record("ucb", seed=2, horizon=700, path=tmp_path / "a.mcap", rrd=False)
    b = corraoi.record("cucb", seed=2, horizon=700, path=tmp_path / "b.mcap", rrd=False)
    report = corraoi.diff(a, b, fields=["x", "arm"])
    assert report["x"].identical and report["arm"].first_slot is not None
    assert a.diff(a).identical and corraoi.diff(a, os.fspath(a)).identical
    rrd = tmp_path / "ab.rrd"
    cmp = corraoi.compare([a, b.mcap], rrd=rrd)
    assert cmp.path == rrd and rrd.is_file()
    assert [r.summary.regret for r in cmp.runs] == [a.summary.regret, b.summary.regret]
    with pytest.raises(corraoi.UsageError):
        corraoi.compare(a)  # type: ignore[arg-type]


def test_an_interrupted_sweep_resumes_to_the_uninterrupted_result(tmp_path: Path) -> None:
    whole = corraoi.sweep("I1", ["ucb", "cts"], runs=8, horizon=500, chunk=2,
                          out=tmp_path / "whole")  # fmt: skip
    seen = 0

    def stop_midway(n: int) -> None:
        nonlocal seen
        seen += n
        if seen > 500 * 8 // 2:  # slots of the chunks run so far: half the sweep's
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        corraoi.sweep("I1", ["ucb", "cts"], runs=8, horizon=500, chunk=2, out=tmp_path / "cut",
                      on_slots=stop_midway)  # fmt: skip
    assert json.loads((tmp_path / "cut" / "manifest.json").read_text())["status"] != "complete"
    resumed = corraoi.sweep("I1", ["ucb", "cts"], runs=8, horizon=500, chunk=2,
                            out=tmp_path / "cut", resume=True)  # fmt: skip
    cols = ["policy", "run", "t", "regret", "estimator"]
    a = whole.runs.sort_values(["policy", "run", "t"])[cols].reset_index(drop=True)
    b = resumed.runs.sort_values(["policy", "run", "t"])[cols].reset_index(drop=True)
    assert a.equals(b)


def test_a_sweep_without_a_folder_uses_a_temporary_one_removed_with_it() -> None:
    sw = corraoi.sweep("I1", "ucb", runs=3, horizon=100)
    folder = sw.folder
    assert (folder / "summary.json").is_file()
    del sw
    import gc

    gc.collect()
    assert not folder.exists()


def test_the_fixture_takes_params_and_a_channel(corraoi_run, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    trace = tmp_path / "states.txt"
    trace.write_text("1 2 3 4 " * 50)
    run = corraoi_run(EpsilonFirst, seed=1, horizon=200, params={"explore": 10},
                      channel=f"trace:{trace}")  # fmt: skip
    cfg = open_log(run).config
    assert cfg.policy.params == {"explore": 10.0} and cfg.channel.kind == "trace"
    assert open_log(run).read_all().x.tolist() == [0, 1, 2, 3] * 50


def test_check_policy_takes_the_class() -> None:
    from corraoi.testing import check_policy

    check_policy(EpsilonFirst, params={"explore": 5}, arms=(2, 5), horizon=120, runs=3)

    class Mixer(EpsilonFirst):
        name = "face-mixer"

        def select(self, t, state):  # type: ignore[no-untyped-def]
            arms = super().select(t, state)
            return np.roll(arms, 1)  # run i decides with run i-1's history

    with pytest.raises(AssertionError, match="own stream"):
        check_policy(Mixer, arms=(3,), horizon=120, runs=3)


@pytest.mark.parametrize(("touch", "loaded"), [
    ("", []),  # import corraoi: the face's names only, nothing of the engine or the formats
    ("corraoi.record; corraoi.Run; corraoi.Sweep; corraoi.load; corraoi.diff",
     ["corraoi.recorder"]),
])
def test_import_corraoi_stays_light(touch: str, loaded: list[str]) -> None:
    heavy = ("numba", "rerun", "pandas", "pyarrow", "corraoi.recorder", "corraoi.engine.simulation")
    code = (f"import sys, json, corraoi; {touch}\n"
            f"print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)  # fmt: skip
    assert json.loads(out.stdout) == loaded
