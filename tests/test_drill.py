"""From a sweep to the run worth watching: named runs, `record --from`, `load(sweep).record`.

The re-recorded runs are checked against the sweep's own per-run rows (results.parquet), at
every checkpoint, so a seed or a parameter carried wrongly fails here.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyarrow")

import corraoi  # noqa: E402
from corraoi.experiments.grid import build_grid  # noqa: E402
from corraoi.experiments.notable import MAX_PAIRED_CELLS, cell_runs, notable_runs  # noqa: E402
from corraoi.experiments.sweeps import sweep  # noqa: E402
from corraoi.face.outputs import FolderOutputs  # noqa: E402
from corraoi.recorder.slotlog.reader import open_log  # noqa: E402
from corraoi.recorder.sweeplog.read import read_sweep  # noqa: E402

POLICIES = ["ucb", "cucb", "aoi-aware-cts"]
SEED = 100
RUNS = 40


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("drill") / "sw"
    grid = build_grid(instances=["I2"], policies=POLICIES, horizons=[1500], runs=RUNS,
                      seed=SEED, chunk=16, checkpoints=25)  # fmt: skip
    sweep(grid, out=out, workers=1, outputs=FolderOutputs())
    return out


def _finals(folder: Path) -> dict[str, np.ndarray]:
    runs = corraoi.load(folder).runs
    last = runs[runs["t"] == runs["t"].max()].sort_values(["policy", "run"])
    return {p: g["regret"].to_numpy() for p, g in last.groupby("policy")}


def _regret(mcap: Path) -> np.ndarray:
    return np.concatenate([b.regret for b in open_log(mcap).blocks()])


def _x(mcap: Path) -> np.ndarray:
    return np.concatenate([b.x for b in open_log(mcap).blocks()])


def _corraoi(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


# ---------------------------------------------------------------------------- naming


def test_named_runs_are_the_extremes_of_the_per_run_finals(folder: Path) -> None:
    summary = json.loads((folder / "summary.json").read_text())
    finals = _finals(folder)
    for label in POLICIES:
        f = finals[label]
        named = summary["notable"]["cells"][label]
        assert named["worst"]["regret"] == f.max() and f[named["worst"]["run"]] == f.max()
        assert named["best"]["regret"] == f.min() and f[named["best"]["run"]] == f.min()
        assert named["median"]["regret"] == np.sort(f)[(RUNS - 1) // 2]
        for k in ("worst", "best", "median"):
            assert named[k]["seed"] == SEED + named[k]["run"]
    pairs = summary["notable"]["pairs"]
    assert len(pairs) == 3  # every pair of three cells
    for g in pairs:
        a, b = g["policies"]
        diff = finals[a] - finals[b]
        assert abs(g["difference"]) == np.abs(diff).max() == abs(diff[g["run"]])
    assert [abs(g["difference"]) for g in pairs] == sorted((abs(g["difference"]) for g in pairs),
                                                          reverse=True)  # fmt: skip
    # the sweep log and summary.md carry them too
    assert read_sweep(folder / "sweep.mcap").notable == summary["notable"]
    md = (folder / "summary.md").read_text()
    worst = summary["notable"]["cells"]["cucb"]["worst"]
    assert f"| cucb | {worst['regret']:g} (run {worst['run']}, seed {worst['seed']})" in md


def test_ties_go_to_the_lowest_run_and_the_median_is_the_lower_one() -> None:
    named = cell_runs(np.array([3.0, 7.0, 1.0, 7.0, 1.0, 5.0]), seed=10)
    assert named["worst"] == {"run": 1, "seed": 11, "regret": 7.0}
    assert named["best"] == {"run": 2, "seed": 12, "regret": 1.0}
    assert named["median"] == {"run": 0, "seed": 10, "regret": 3.0}  # sorted: 1 1 3 5 7 7


def test_a_cells_named_runs_are_the_ones_the_sweep_recording_draws_apart() -> None:
    # one list of a cell's runs (corraoi.stats.CELL_RUNS): what notable names, what --run
    # takes, what the sweep recording leaves out of its overlay of means
    from corraoi.experiments.notable import CHOICES
    from corraoi.stats import CELL_RUNS

    named = cell_runs(np.array([3.0, 7.0, 1.0]), seed=0, collisions=np.array([5, 2, 9]))
    assert list(named) == list(CELL_RUNS)
    assert named["most-collisions"] == {"run": 2, "seed": 2, "regret": 1.0, "collisions": 9}
    assert list(cell_runs(np.array([3.0, 7.0]), seed=0)) == list(CELL_RUNS[:3])
    assert set(CHOICES) == set(CELL_RUNS) | {"widest-gap"}


def test_pairs_against_a_baseline_and_none_for_a_large_grid_without_one() -> None:
    rng = np.random.default_rng(1)
    finals = [rng.normal(size=20) for _ in range(4)]
    labels = ["a", "b", "c", "d"]
    same = [{"kind": "iid"}] * 4
    with_base = notable_runs(labels, finals, same, seed=0, baseline="c")
    assert sorted(tuple(g["policies"]) for g in with_base["pairs"]) == [
        ("a", "c"), ("b", "c"), ("d", "c")]  # fmt: skip
    # cells on different channels share no hidden path: no pair between them
    mixed = notable_runs(labels, finals, [{"kind": "iid"}] * 2 + [{"kind": "markov"}] * 2, seed=0)
    assert sorted(tuple(g["policies"]) for g in mixed["pairs"]) == [("a", "b"), ("c", "d")]
    n = MAX_PAIRED_CELLS + 1
    big = notable_runs([f"p{i}" for i in range(n)], [finals[0]] * n, [{}] * n, seed=0)
    assert big["pairs"] == [] and len(big["cells"]) == n


# ---------------------------------------------------------------------------- exact re-records


@pytest.mark.parametrize("choice", ["worst", "best", "median"])
def test_a_rerecorded_run_equals_the_sweeps_row_at_every_checkpoint(
    folder: Path, tmp_path: Path, choice: str
) -> None:
    sweep = corraoi.load(folder)
    runs = sweep.runs
    summary = json.loads((folder / "summary.json").read_text())
    with pytest.raises(corraoi.CorraoiError, match=f"{choice!r} names 3 runs .*I2/ucb run"):
        sweep.record(choice)  # one run per policy: say which
    for label in POLICIES:
        outcome = sweep.record(choice, policy=label, path=tmp_path / "{from}.mcap", rrd=False)
        run = summary["notable"]["cells"][label][choice]["run"]
        assert outcome.mcap.name == f"sw-I2-{label}-run{run}-{choice}.mcap"
        assert outcome.summary.regret == runs[(runs["policy"] == label) & (runs["run"] == run)
                                              & (runs["t"] == 1500)]["regret"].item()
        log = open_log(outcome.mcap)
        assert log.config.seed == SEED + run and log.config.policy.name == label
        regret = _regret(outcome.mcap)
        rows = runs[(runs["policy"] == label) & (runs["run"] == run)].sort_values("t")
        assert len(rows) >= 20 and rows["t"].max() == 1500
        np.testing.assert_array_equal(regret[rows["t"].to_numpy() - 1], rows["regret"].to_numpy())


def test_a_paired_rerecord_shares_the_hidden_path(folder: Path, tmp_path: Path) -> None:
    out = _corraoi("record", "--from", folder, "--run", "widest-gap", "-p", "ucb,cucb",
                   "--no-rrd", cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    logs = sorted((tmp_path / "runs").glob("*.mcap"))
    assert [p.name.split("-run")[0] for p in logs] == ["sw-I2-cucb", "sw-I2-ucb"]
    gap = next(g for g in json.loads((folder / "summary.json").read_text())["notable"]["pairs"]
               if set(g["policies"]) == {"ucb", "cucb"})  # fmt: skip
    assert all(f"-run{gap['run']}-widest-gap" in p.name for p in logs)
    np.testing.assert_array_equal(_x(logs[0]), _x(logs[1]))
    finals = {open_log(p).config.policy.name: _regret(p)[-1] for p in logs}
    i, j = gap["policies"]
    assert finals[i] - finals[j] == gap["difference"]


def test_a_policy_added_on_a_run_is_paired(folder: Path, tmp_path: Path) -> None:
    out = _corraoi("record", "--from", folder, "--run", "7", "-p", "cts,cucb", "--no-rrd",
                   cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "cts: not in the sweep; recorded on the chosen run too" in out.stderr
    logs = {open_log(p).config.policy.name: p for p in (tmp_path / "runs").glob("*.mcap")}
    assert sorted(logs) == ["cts", "cucb"]
    assert open_log(logs["cts"]).config.seed == SEED + 7
    np.testing.assert_array_equal(_x(logs["cts"]), _x(logs["cucb"]))
    runs = corraoi.load(folder).runs
    row = runs[(runs["policy"] == "cucb") & (runs["run"] == 7) & (runs["t"] == 1500)]
    assert _regret(logs["cucb"])[-1] == row["regret"].item()


@pytest.mark.parametrize("damage", [{"pairs": "cucb"}, {"cells": []}, {"pairs": [{"x": 1}]},
                                    {"cells": {"ucb": {"worst": 3}}}], ids=str)  # fmt: skip
def test_a_malformed_summary_is_not_trusted(
    folder: Path, tmp_path: Path, damage: dict[str, object]
) -> None:
    """Named again from the parts, the same runs as the undamaged folder's."""
    import shutil

    copy = tmp_path / "sw"
    shutil.copytree(folder, copy)
    summary = json.loads((copy / "summary.json").read_text())
    named = summary["notable"]
    summary["notable"] = {**named, **damage}
    (copy / "summary.json").write_text(json.dumps(summary))
    for choice in ("worst", "widest-gap"):
        out = _corraoi("record", "--from", copy, "--run", choice, "--no-rrd", "-p", "ucb,cucb",
                       cwd=tmp_path)  # fmt: skip
        assert out.returncode == 0, out.stderr
    worst = {open_log(p).config.policy.name: open_log(p).config.seed
             for p in (tmp_path / "runs").glob("*-worst.mcap")}  # fmt: skip
    assert worst == {p: named["cells"][p]["worst"]["seed"] for p in ("ucb", "cucb")}


def test_a_folder_without_named_runs_still_drills(folder: Path, tmp_path: Path) -> None:
    """A sweep folder from before runs were named: by index, and by name from its parts."""
    import shutil

    old = tmp_path / "old"
    shutil.copytree(folder, old)
    summary = json.loads((old / "summary.json").read_text())
    named = summary.pop("notable")
    (old / "summary.json").write_text(json.dumps(summary))
    data = corraoi.load(old)
    by_index = data.record(3, cell="ucb", path=tmp_path / "a.mcap", rrd=False)
    assert by_index.log.config.seed == SEED + 3
    worst = data.record("worst", policy="cucb", path=tmp_path / "b.mcap", rrd=False)
    assert worst.log.config.seed == SEED + named["cells"]["cucb"]["worst"]["run"]


def test_info_lists_the_named_runs_with_a_command_that_records_each(
    folder: Path, tmp_path: Path
) -> None:
    import shlex

    out = _corraoi("info", folder, "--json", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    summary = json.loads((folder / "summary.json").read_text())
    assert info["runs"] == RUNS and info["seeds"] == [SEED, SEED + RUNS - 1]
    (group,) = info["groups"]
    worst = group["notable"]["cells"]["aoi-aware-cts"]["worst"]
    assert worst["run"] == summary["notable"]["cells"]["aoi-aware-cts"]["worst"]["run"]
    command = shlex.split(worst["command"])
    assert command[:4] == ["corraoi", "record", "--from", str(folder)]
    ran = _corraoi(*command[1:], "--no-rrd", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    (log,) = (tmp_path / "runs").glob("*.mcap")
    assert open_log(log).config.seed == SEED + worst["run"]
    assert _regret(log)[-1] == worst["regret"]
    text = _corraoi("info", folder, cwd=tmp_path).stdout
    assert worst["command"] in text and "runs worth watching" in text


def test_compare_from_a_sweep_puts_each_policys_chosen_run_side_by_side(
    folder: Path, tmp_path: Path
) -> None:
    out = _corraoi("compare", "--from", folder, "--run", "median", "--no-rrd", "--json",
                   cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    named = json.loads((folder / "summary.json").read_text())["notable"]["cells"]
    table = json.loads(out.stdout)
    runs = table["runs"] if isinstance(table, dict) else table
    got = {r["policy"]: (r["seed"], r["summary"]["regret"]) for r in runs}
    assert got == {p: (named[p]["median"]["seed"], named[p]["median"]["regret"]) for p in POLICIES}
    assert len(list((tmp_path / "runs").glob("*-median.mcap"))) == 3
    again = _corraoi("compare", "--from", folder, "--run", "median", "--no-rrd", cwd=tmp_path)
    assert again.returncode == 0 and "recording" not in again.stderr  # the logs are reused


# ---------------------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--run", "40"], "--run 40: out of range; the sweep in"),
        (["--run", "-1"], "--run -1: out of range"),
        (["--run", "worstest"], "--run 'worstest': expected a run index"),
        (["--run", "worst", "-p", "cts"], "--policy cts: not in the sweep"),
        (["--cell", "thompson"], "--cell 'thompson': no such cell"),
        (["-T", "100"], "--horizon and --from: the sweep fixes the horizon"),
        (["--seed", "3"], "--seed and --from"),
        (["--c", "3"], "--c/--beta/--param and --from"),
        (["--run", ""], "--run '': expected a run index"),
        (["-o", "x.mcap"], "-o/--output x.mcap: names one file but 3 runs are recorded; put "
         "{label} or {from} in it"),
    ],
)
def test_bad_drill_requests_get_one_line(
    folder: Path, tmp_path: Path, args: list[str], says: str
) -> None:
    out = _corraoi("record", "--from", folder, "--no-rrd", *args, cwd=tmp_path)
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], out.stderr
    assert not (tmp_path / "runs").exists()


def test_foreign_and_damaged_folders_get_one_line(folder: Path, tmp_path: Path) -> None:
    import shutil

    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("not a sweep")
    damaged = tmp_path / "damaged"
    shutil.copytree(folder, damaged)
    (damaged / "manifest.json").write_text("{ not json")
    bad_summary = tmp_path / "bad-summary"
    shutil.copytree(folder, bad_summary)
    summary = json.loads((bad_summary / "summary.json").read_text())
    summary["notable"]["cells"]["ucb"]["worst"]["run"] = 10_000
    (bad_summary / "summary.json").write_text(json.dumps(summary))
    cases = [
        (foreign, "not a sweep folder (no manifest.json in it"),
        (tmp_path / "missing", "no such folder"),
        (foreign / "notes.txt", "not a folder"),
        (damaged, "unreadable manifest"),
        (bad_summary, "names run 10000, not one of the sweep's 0..39"),
    ]
    for path, says in cases:
        out = _corraoi("record", "--from", path, "--run", "worst", "-p", "ucb", "--no-rrd",
                       cwd=tmp_path)  # fmt: skip
        lines = out.stderr.strip().splitlines()
        assert out.returncode != 0 and len(lines) == 1 and says in lines[0], (path, out.stderr)


@pytest.mark.slow
def test_the_docs_section_runs_as_shown_on_the_papers_outlier(tmp_path: Path) -> None:
    """docs/analysis.md, "Finding the run worth watching": every command, in a fresh
    directory, and the figures the text states (I2, aoi-aware-cts, run 114, regret 1410)."""
    import shlex

    text = (Path(__file__).parents[1] / "docs" / "analysis.md").read_text()
    section = text.split("## Finding the run worth watching", 1)[1].split("\n## ", 1)[0]
    block = section.split("```bash\n", 1)[1].split("```", 1)[0]
    outputs = []
    for line in block.strip().splitlines():
        args = shlex.split(line)
        assert args[0] == "corraoi"
        out = _corraoi(*args[1:], cwd=tmp_path)
        assert out.returncode == 0, (line, out.stderr)
        outputs.append(out.stdout)
    assert "aoi-aware-cts        worst        1410  run 114" in outputs[1]
    worst = tmp_path / "runs" / "paper-I2-aoi-aware-cts-run114-worst.mcap"
    assert _regret(worst)[-1] == 1410 and worst.with_suffix(".rrd").is_file()
    runs = corraoi.load(tmp_path / "paper" / "I2").runs
    rows = runs[(runs["policy"] == "aoi-aware-cts") & (runs["run"] == 114)].sort_values("t")
    np.testing.assert_array_equal(_regret(worst)[rows["t"].to_numpy() - 1], rows["regret"])
    cts = tmp_path / "runs" / "paper-I2-cts-run114-widest-gap.mcap"
    aware = tmp_path / "runs" / "paper-I2-aoi-aware-cts-run114-widest-gap.mcap"
    assert _regret(cts)[-1] == 3 and _regret(aware)[-1] == 1410
    np.testing.assert_array_equal(_x(cts), _x(aware))
    assert (tmp_path / "paper-run114.rrd").is_file()


def test_the_sweeps_recording_draws_each_named_run_over_its_mean(folder: Path) -> None:
    """sweep.rrd: sweep/regret/<policy>/<worst|median|best> holds that run's regret at every
    checkpoint (as results.parquet), labelled with run and seed, in a tab of its own."""
    pytest.importorskip("rerun")
    from .test_sweep_log import _rrd_contents

    values, static, _ = _rrd_contents(folder / "sweep.rrd")
    named = json.loads((folder / "summary.json").read_text())["notable"]["cells"]
    runs = corraoi.load(folder).runs
    for label in POLICIES:
        for kind in ("worst", "median", "best"):
            e = named[label][kind]
            path = f"/sweep/regret/{label}/{kind}"
            rows = runs[(runs["policy"] == label) & (runs["run"] == e["run"])]
            assert values[path] == dict(zip(rows["t"], rows["regret"], strict=True))
            assert static[path]["SeriesLines:names"] == [
                [f"{label} {kind}: run {e['run']}, seed {e['seed']}"]]  # fmt: skip


def test_info_of_a_folder_with_a_damaged_summary_names_no_runs(folder: Path, tmp_path: Path):
    import shutil

    from corraoi.experiments.notable import well_formed

    copy = tmp_path / "sw"
    shutil.copytree(folder, copy)
    summary = json.loads((copy / "summary.json").read_text())
    assert well_formed(summary["notable"], POLICIES)
    summary["notable"]["cells"]["ucb"]["worst"]["regret"] = "a lot"
    assert not well_formed(summary["notable"], POLICIES)
    (copy / "summary.json").write_text(json.dumps(summary))
    out = _corraoi("info", copy, cwd=tmp_path)
    assert out.returncode == 0 and out.stderr == ""
    assert "no runs named in its summary.json (an older sweep, or a damaged summary)" in out.stdout
