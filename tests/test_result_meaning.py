"""What a result means, said with it (issue 45, items 7 and 8): a diff of runs that are not
paired says so first; a run recorded from a sweep with changed code says whether it still
equals the sweep's row; ``record --from -p`` takes the labels the sweep's table prints; a
DiffReport is a short table in Jupyter; ``record --foxglove`` on a recorded run says what is
true; a package that is not installed is one line naming it (corraoi.show's served sources:
tests/test_show.py)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import pytest
from click.testing import CliRunner

import corraoi
from corraoi.cli import main
from corraoi.engine.block import FIELDS, RunConfig, SlotBlock
from corraoi.errors import CorraoiWarning
from corraoi.model.instance import Instance
from corraoi.recorder.slotlog.reader import open_log
from corraoi.viewer import diff

PLUGIN = '''"""A plain-Python plug-in: greedy after a forced first pull of every arm."""
from corraoi.policies import Param, Policy


class Greedyish(Policy):
    name = "greedyish"
    params = {"bonus": Param(0.5, "optimism per unpulled arm", low=0.0)}

    def select(self, t, state):
        score = state.mu_hat + self.bonus / (1.0 + state.pulls)
        return state.rng.argmax(score)
'''
#: the same code with a comment more: another hash, the same runs
COMMENTED = PLUGIN + "\n# a comment changes the hash, not a decision\n"
#: other decisions
EDITED = PLUGIN.replace("1.0 + state.pulls", "1.0 + 3 * state.pulls")


def _cli(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


def _write(path: Path, config: RunConfig, block: SlotBlock) -> Path:
    from corraoi.recorder.slotlog.sink import McapSink

    with McapSink(path, config, fsync=False) as sink:
        sink.write(SlotBlock(**{f: block.column(f) for f in FIELDS}))
    return path


# ---------------------------------------------------------------------------- diff: paired?


def test_a_diff_of_runs_that_are_not_paired_says_so_first(record_mcap, tmp_path: Path):
    a, config, ref = record_mcap("ucb", seed=0, horizon=800, name="a.mcap")
    other_seed, _, _ = record_mcap("ucb", seed=1, horizon=800, name="s1.mcap")
    other_inst, _, _ = record_mcap("ucb", instance="I2", seed=0, horizon=800, name="i2.mcap")
    paired, _, _ = record_mcap("cucb", seed=0, horizon=800, name="cucb.mcap")

    report = corraoi.diff(a, other_seed)
    assert not report.paired and report.unpaired == ("seed (0 != 1)",)
    first = report.message().splitlines()[0]
    assert first == ("not paired: seed (0 != 1): the runs did not see one hidden path, so "
                     "their slots differ by more than the policy")  # fmt: skip
    assert report.verdict().startswith("different: not paired; ")
    data = report.to_dict()
    assert data["paired"] is False and data["unpaired"] == ["seed (0 != 1)"]

    report = corraoi.load(a).diff(other_inst)  # Run.diff: the same report
    assert report.unpaired == ("instance (I1 != I2)",)
    assert report.message().startswith("not paired: instance (I1 != I2): ")

    # one seed, one instance: paired, whatever the policies; the report opens as before
    report = corraoi.diff(a, paired)
    assert report.paired and report.unpaired == () and report.pairing_line() is None
    assert report.message().splitlines()[0].startswith(f"--- {a}")
    assert report.to_dict()["paired"] is True
    # a renamed copy of the instance is still the same hidden path: paired
    inst = config.instance
    renamed = Instance("copy-of-I1", inst.p, inst.Y)
    b = _write(tmp_path / "renamed.mcap", replace(config, instance=renamed), ref)
    report = diff(a, b)
    assert report.paired and [d.key for d in report.config] == ["instance.name"]
    assert report["x"].identical


def test_the_command_line_diff_says_it_on_its_first_line_and_exits_1(record_mcap):
    a, _, _ = record_mcap("ucb", seed=0, horizon=500, name="a.mcap")
    b, _, _ = record_mcap("cucb", seed=3, horizon=500, name="b.mcap")
    res = CliRunner().invoke(main, ["diff", str(a), str(b)])
    assert res.exit_code == 1, res.output
    lines = res.stdout.splitlines()
    assert lines[0].startswith("not paired: seed (0 != 3): the runs did not see one hidden")
    assert lines[1].startswith("--- ")
    res = CliRunner().invoke(main, ["diff", str(a), str(b), "--json"])
    assert res.exit_code == 1 and json.loads(res.stdout)["unpaired"] == ["seed (0 != 3)"]


def test_a_diff_report_is_a_short_table_in_jupyter_and_one_line_as_repr(record_mcap):
    a, _, _ = record_mcap("ucb", seed=0, horizon=600, name="a.mcap")
    b, _, _ = record_mcap("ucb", seed=2, horizon=600, name="b.mcap")
    report = diff(a, b)
    text = repr(report)
    assert text == f"DiffReport('a.mcap', 'b.mcap': {report.verdict()})"
    assert "\n" not in text and "RunSummary" not in text and "FieldDiff" not in text
    page = report._repr_html_()
    assert page.count("<table>") == 1 and len(page) < 6000
    assert page.index("not paired: seed (0 != 2)") < page.index("<table>")
    for name, f in report.fields.items():
        first = "-" if f.first_slot is None else f"{f.first_slot:,}"
        row = (f"<td style='text-align:left'>{name}</td><td style='text-align:left'>{first}"
               f"</td><td style='text-align:left'>{f.slots_differing:,} of {f.compared:,}</td>")
        assert row in page, name
    regret = f"{report.a_summary.regret}</td><td style='text-align:left'>{report.b_summary.regret}"
    assert regret in page


# ---------------------------------------------------------------------------- record --from


@pytest.fixture
def swept(tmp_path: Path) -> Path:
    """cucb with c = 1 and 2 (labels cucb(c=1), cucb(c=2)) and a plug-in (greedyish)."""
    (tmp_path / "greedyish.py").write_text(PLUGIN)
    res = _cli("sweep", "-i", "I1", "-p", "cucb,greedyish.py:Greedyish", "--param",
               "cucb.c=1,2", "-n", 4, "-T", 300, "-o", "sw", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    for label in ("cucb(c=1)", "cucb(c=2)", "greedyish"):  # what the sweep's table prints
        assert any(line.startswith(label + " ") for line in res.stdout.splitlines()), label
    return tmp_path / "sw"


def test_record_from_takes_the_labels_the_sweeps_table_prints(swept: Path):
    tmp = swept.parent
    res = _cli("record", "--from", "sw", "-p", "greedyish", "--run", 2, "--no-rrd", "-o",
               "g.mcap", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "from sw: I1 greedyish, run 2 (seed 2, run)" in res.stderr
    log = open_log(tmp / "g.mcap")
    assert (log.config.policy.name, log.config.seed) == ("greedyish", 2)
    # a label with a parameter value picks that cell alone; a plain name every cell of it
    res = _cli("record", "--from", "sw", "-p", "cucb(c=2)", "--run", 1, "--no-rrd", "-o",
               "c.mcap", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert [ln for ln in res.stderr.splitlines() if ln.startswith("from ")] == [
        "from sw: I1 cucb(c=2), run 1 (seed 1, run)"]  # fmt: skip
    assert open_log(tmp / "c.mcap").config.policy.params == {"c": 2.0}
    # and from Python, the same label
    run = corraoi.load(swept).record(1, policy="greedyish", path=tmp / "py.mcap", rrd=False)
    assert (run.log.config.policy.name, run.log.config.seed) == ("greedyish", 1)


def test_allow_changed_code_says_whether_the_run_still_equals_the_sweeps_row(swept: Path):
    tmp = swept.parent
    # the sweep's row, as the unchanged code gives it again (record --from checks that)
    res = _cli("record", "--from", "sw", "--cell", "greedyish", "--run", 3, "--no-rrd", "-o",
               "same.mcap", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    row = corraoi.load(tmp / "same.mcap").summary.regret
    what = "I1 greedyish run 3, recorded with changed code"

    (tmp / "greedyish.py").write_text(COMMENTED)
    res = _cli("record", "--from", "sw", "--cell", "greedyish", "--run", 3, "--no-rrd", "-o",
               "commented.mcap", "--allow-changed-code", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert f"{what}: equal to the sweep's row (regret {row} at slot 300)" in res.stdout

    (tmp / "greedyish.py").write_text(EDITED)
    res = _cli("record", "--from", "sw", "--cell", "greedyish", "--run", 3, "--no-rrd", "-o",
               "edited.mcap", "--allow-changed-code", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    now = corraoi.load(tmp / "edited.mcap").summary.regret
    assert now != row  # the edit changes this run's decisions
    assert (f"{what}: differs from the sweep's row: regret {now} vs {row} at slot 300"
            in res.stdout)  # fmt: skip

    # Python: Sweep.record(..., allow_changed_code=True) says it as a warning
    code = textwrap.dedent("""
        import warnings, corraoi
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            corraoi.load("sw").record(3, cell="greedyish", path="py.mcap", rrd=False,
                                      allow_changed_code=True)
        print([str(w.message) for w in seen if "sweep's row" in str(w.message)])
        print({w.category.__name__ for w in seen})
    """)
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp, capture_output=True,
                         text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    said, kinds = res.stdout.splitlines()
    assert said == repr([f"{what}: differs from the sweep's row: regret {now} vs {row} at "
                         "slot 300"])  # fmt: skip
    assert kinds == repr({CorraoiWarning.__name__})


# ---------------------------------------------------------------------------- the small lies


@pytest.mark.parametrize("live", ["--foxglove", "--serve-web"])
def test_a_live_view_of_a_recorded_run_is_not_called_another_run(tmp_path: Path, live: str):
    args = ["record", "-p", "ucb", "-T", "300", "--no-rrd", "-o", str(tmp_path / "u.mcap")]
    assert CliRunner().invoke(main, args).exit_code == 0
    before = (tmp_path / "u.mcap").stat().st_mtime_ns
    same = CliRunner().invoke(main, args)  # without a live view: up to date
    assert same.exit_code == 0 and same.stdout.startswith("up to date: ")
    res = CliRunner().invoke(main, [*args, live])
    assert res.exit_code == 2, res.output
    (line,) = res.stderr.strip().splitlines()
    assert line == (f"corraoi: error: {tmp_path / 'u.mcap'}: already holds this run (same "
                    f"configuration, complete); {live} shows a run as it is recorded, which "
                    "would write it again: use --force to record it again, or `corraoi replay "
                    f"{tmp_path / 'u.mcap'} {live}` to show this log")  # fmt: skip
    assert "another run" not in res.stderr
    assert (tmp_path / "u.mcap").stat().st_mtime_ns == before


def test_a_missing_package_is_named_with_the_way_to_install_it():
    from corraoi.extras import missing_package

    line = str(missing_package(ModuleNotFoundError("no rerun", name="rerun"), "corraoi sweep"))
    assert line.startswith("rerun-sdk is not installed (no module rerun): corraoi sweep needs "
                           'it, pip install "rerun-sdk')  # fmt: skip
    line = str(missing_package(ModuleNotFoundError("x", name="pyarrow.parquet"), "export"))
    assert line == 'pyarrow is not installed: export needs the analysis extra, pip install ' \
                   '"corraoi[analysis]"'
    # not a package to install: left to show as it is
    assert missing_package(ModuleNotFoundError("x", name="corraoi.nowhere")) is None
    assert missing_package(ImportError("cannot import name X", name="rerun")) is None


NO_RERUN = """
import json, sys
sys.modules["rerun"] = None  # a machine without rerun-sdk
from click.testing import CliRunner
from corraoi.cli import main
out = []
for args in json.loads(sys.argv[1]):
    res = CliRunner().invoke(main, args)
    out.append([res.exit_code, res.stdout, res.stderr, repr(res.exception)])
print(json.dumps(out))
"""


def test_without_rerun_sdk_each_command_that_needs_it_is_one_line(tmp_path: Path):
    run = corraoi.record("ucb", horizon=200, path=tmp_path / "u.mcap", rrd=False)
    commands = [
        ["sweep", "-p", "ucb", "-T", "100", "-n", "2", "-o", "sw"],
        ["record", "-p", "ucb", "-T", "100", "-o", "r.mcap"],
        ["replay", str(run.path), "-o", "u.rrd"],
        ["compare", str(run.path), str(run.path), "--rrd", "c.rrd"],
    ]
    res = subprocess.run([sys.executable, "-c", NO_RERUN, json.dumps(commands)], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    for args, (code, _out, err, exc) in zip(commands, json.loads(res.stdout), strict=True):
        assert code == 1 and "Traceback" not in err and "ModuleNotFoundError" not in exc, (
            args, err, exc)  # fmt: skip
        (line,) = err.strip().splitlines()
        assert line.startswith("corraoi: error: rerun-sdk is not installed (no module rerun): ")
        assert 'needs it, pip install "rerun-sdk' in line, line
    # refused before the sweep ran, before the run was recorded
    assert not (tmp_path / "sw").exists() and not list(tmp_path.glob("r.*"))
    assert not (tmp_path / "u.rrd").exists() and not (tmp_path / "c.rrd").exists()


NO_RERUN_FACE = """
import sys
sys.modules["rerun"] = None  # a machine without rerun-sdk
import corraoi
from corraoi.errors import MissingExtraError
try:
    corraoi.record("ucb", horizon=100, path="r.mcap")
except MissingExtraError as exc:
    print("refused:", exc)
print(corraoi.record("ucb", horizon=100, path="n.mcap", rrd=False).log.n_slots)
"""


def test_without_rerun_sdk_the_python_record_is_one_typed_error_before_any_file(tmp_path: Path):
    res = subprocess.run([sys.executable, "-c", NO_RERUN_FACE], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr
    refused, horizon = res.stdout.strip().splitlines()
    assert refused.startswith("refused: rerun-sdk is not installed (no module rerun): ")
    assert "corraoi.record's Rerun recording (rrd=False: none)" in refused
    assert horizon == "100"  # without a recording it records
    assert not list(tmp_path.glob("r.*")) and (tmp_path / "n.mcap").exists()
