"""Sweeps of many sources (issue 43, item 4): the number of sources M a grid axis, its rows
against the single-source sweep's, the regret growing with M, the notable collision storm
and its drill-down, the GPU's refusal and bad input; ``reproduce decentralized`` (item 6).
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyarrow")

import corraoi  # noqa: E402
from corraoi.engine.sources import simulate_run_sources, simulate_sources  # noqa: E402
from corraoi.errors import ConfigError, GpuUnavailable  # noqa: E402
from corraoi.experiments.backends import settle  # noqa: E402
from corraoi.experiments.drill import choose, row_mismatch  # noqa: E402
from corraoi.experiments.grid import build_grid  # noqa: E402
from corraoi.experiments.sweeps import sweep  # noqa: E402
from corraoi.face.outputs import FolderOutputs  # noqa: E402
from corraoi.model.instance import Instance  # noqa: E402
from corraoi.recorder.sweeplog.results import COLUMNS, SOURCE_COLUMNS  # noqa: E402

SEED = 7
RUNS = 8
T = 1500


def bernoulli(means: list[float]) -> Instance:
    """K independent Bernoulli channels: the hidden states are their outcome vectors."""
    states = list(itertools.product((0, 1), repeat=len(means)))
    p = np.array([np.prod([m if o else 1 - m for m, o in zip(means, s, strict=True)])
                  for s in states])  # fmt: skip
    Y = np.array(states, dtype=np.int8).T
    return Instance(f"bern{len(means)}", p / p.sum(), Y)


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("sources-sweep")
    many, single = root / "many", root / "single"
    grid = build_grid(instances=["I1"], policies=["rhorand-ucb"], horizons=[T], runs=RUNS,
                      seed=SEED, chunk=5, checkpoints=12, sources=[1, 2, 3])  # fmt: skip
    sweep(grid, out=many, workers=1, outputs=FolderOutputs())
    grid = build_grid(instances=["I1"], policies=["ucb"], horizons=[T], runs=RUNS, seed=SEED,
                      chunk=5, checkpoints=12)  # fmt: skip
    sweep(grid, out=single, workers=1, outputs=FolderOutputs())
    return many, single


def test_one_source_rows_are_the_single_source_sweeps_rows(folders: tuple[Path, Path]) -> None:
    many, single = folders
    rows = corraoi.load(many).runs
    base = corraoi.load(single).runs
    assert [c for c, _ in COLUMNS] == list(base.columns)  # a single source's file: as before
    assert list(rows.columns) == [c for c, _ in COLUMNS + SOURCE_COLUMNS]
    one = rows[rows["sources"] == 1].sort_values(["t", "run"]).reset_index(drop=True)
    base = base.sort_values(["t", "run"]).reset_index(drop=True)
    assert len(one) == len(base) == RUNS * base["t"].nunique()
    for col in ("run", "seed", "t", "regret", "estimator", "best_arm_pulls"):
        np.testing.assert_array_equal(one[col].to_numpy(), base[col].to_numpy(), err_msg=col)
    assert (one["collisions"] == 0).all()
    # several sources: the total is the sum over the sources, collisions counted
    three = rows[rows["sources"] == 3]
    by = np.stack(three["regret_by_source"].to_numpy())
    assert by.shape == (len(three), 3)
    np.testing.assert_array_equal(by.sum(axis=1), three["regret"].to_numpy())
    assert three[three["t"] == T]["collisions"].min() > 0


def test_summary_labels_collisions_and_the_collision_storm(folders: tuple[Path, Path]) -> None:
    many, _ = folders
    summary = json.loads((many / "summary.json").read_text())
    pols = summary["policies"]
    assert list(pols) == ["rhorand-ucb(M=1)", "rhorand-ucb(M=2)", "rhorand-ucb(M=3)"]
    assert "collisions_mean" not in pols["rhorand-ucb(M=1)"]
    totals = simulate_sources(_i1(), _spec("rhorand-ucb"),
                              range(SEED, SEED + RUNS), T, 3)  # fmt: skip
    entry = pols["rhorand-ucb(M=3)"]
    assert entry["sources"] == 3
    assert entry["collisions_mean"] == pytest.approx(totals.collisions.sum(axis=1).mean())
    np.testing.assert_allclose(entry["regret_by_source_mean"], totals.regret.mean(axis=0))
    assert entry["regret_mean"] == pytest.approx(totals.total_regret.mean())
    storm = summary["notable"]["cells"]["rhorand-ucb(M=3)"]["most-collisions"]
    hits = totals.collisions.sum(axis=1)
    assert storm["collisions"] == hits.max() and storm["run"] == int(np.argmax(hits))
    assert "most-collisions" not in summary["notable"]["cells"]["rhorand-ucb(M=1)"]
    assert "Most collisions" in (many / "summary.md").read_text()


def test_the_sweep_log_holds_the_collisions_of_several_sources_only(
    folders: tuple[Path, Path],
) -> None:
    from corraoi.recorder.sweeplog.read import read_sweep

    many, single = folders
    summary = json.loads((many / "summary.json").read_text())
    log = read_sweep(many / "sweep.mcap")
    assert log.config["sources"] == [1, 2, 3]
    assert log.curves["rhorand-ucb(M=1)"].collisions_mean is None
    for m in (2, 3):
        curve = log.curves[f"rhorand-ucb(M={m})"]
        assert curve.collisions_mean is not None and curve.t[-1] == T
        assert curve.collisions_mean[-1] == summary["policies"][f"rhorand-ucb(M={m})"][
            "collisions_mean"]
        assert np.all(np.diff(curve.collisions_mean) >= 0)  # counted up to t
    curves = corraoi.load(many).curves
    assert curves[curves["policy"] == "rhorand-ucb(M=3)"]["collisions_mean"].iloc[-1] > 0
    plain = read_sweep(single / "sweep.mcap")
    assert "sources" not in plain.config and plain.curves["ucb"].collisions_mean is None
    assert "collisions_mean" not in corraoi.load(single).curves.columns
    from mcap.reader import make_reader

    for folder, declared in ((single, False), (many, True)):  # its schema declares them
        with open(folder / "sweep.mcap", "rb") as f:
            schemas = make_reader(f).get_summary().schemas.values()  # type: ignore[union-attr]
            assert any(b"collisions_mean" in sc.data for sc in schemas) is declared


def test_a_drilled_run_of_several_sources_gives_the_sweeps_row_again(
    folders: tuple[Path, Path],
) -> None:
    many, _ = folders
    summary = json.loads((many / "summary.json").read_text())
    (drill,) = choose(many, "most-collisions", cells=["rhorand-ucb(M=3)"])
    storm = summary["notable"]["cells"]["rhorand-ucb(M=3)"]["most-collisions"]
    cfg = drill.config
    assert cfg.sources == 3 and cfg.seed == SEED + storm["run"] and drill.run == storm["run"]
    assert drill.expect[-1] == (T, storm["regret"])
    blocks = list(simulate_run_sources(cfg.model, cfg.policy, cfg.seed, cfg.horizon,
                                       cfg.sources, block=400, channel=cfg.channel))  # fmt: skip
    final = sum(int(s.regret[-1]) for s in blocks[-1].sources)
    assert final == storm["regret"]
    assert all(row_mismatch(drill.expect, b) is None for b in blocks)
    wrong = tuple((t, v + 1) for t, v in drill.expect)
    assert "sweep's row says" in (row_mismatch(wrong, blocks[-1]) or "")
    with pytest.raises(ConfigError, match="most-collisions: rhorand-ucb\\(M=1\\) runs one source"):
        choose(many, "most-collisions", cells=["rhorand-ucb(M=1)"])


def test_regret_grows_with_the_number_of_sources_on_an_easy_instance() -> None:
    inst = bernoulli([0.9, 0.7, 0.4, 0.2])
    grid = build_grid(instances=[inst], policies=["rhorand-ucb", "centralized-ucb"],
                      horizons=[2000], runs=20, seed=3, sources=[1, 2, 3])  # fmt: skip
    (summary,) = sweep(grid, workers=1).summaries
    pols = summary["policies"]
    means = [pols[f"rhorand-ucb(M={m})"]["regret_mean"] for m in (1, 2, 3)]
    assert means[0] < means[1] < means[2], means
    # decentralized pays for its collisions: above the coordinated baseline at M = 3
    assert pols["rhorand-ucb(M=3)"]["regret_mean"] > pols["centralized-ucb(M=3)"]["regret_mean"]
    assert pols["centralized-ucb(M=3)"]["collisions_mean"] == 0
    assert pols["rhorand-ucb(M=3)"]["collisions_mean"] > 0


def test_the_gpu_backend_refuses_several_sources_naming_the_cpu() -> None:
    grid = build_grid(instances=["I1"], policies=["rhorand-ucb"], horizons=[100], runs=2,
                      sources=[1, 2])  # fmt: skip
    with pytest.raises(GpuUnavailable) as err:
        settle(grid, "gpu")
    text = str(err.value)
    assert "\n" not in text and "2 sources" in text and "--backend cpu" in text


def _corraoi(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


@pytest.mark.parametrize(("args", "says"), [
    (["-p", "rhorand-ucb", "--sources", "0"], "sources 0: expected an integer from 1"),
    (["-p", "rhorand-ucb", "--sources", "5"], "sources 5: expected an integer from 1 to the "
                                              "number of arms of I1, 4"),
    (["-p", "rhorand-ucb", "--sources", "1.5"], "--sources '1.5': expected an integer"),
    (["-p", "rhorand-ucb", "--sources", "two"], "--sources 'two': expected an integer"),
    (["-p", "ucb", "--sources", "1,2"], "policy ucb is single-source; with sources 2 use one of "
                                        "its multi-source forms: rhorand-ucb"),
    (["-p", "rhorand-ucb", "--sources", "2", "--backend", "gpu"], "--backend cpu"),
])  # fmt: skip
def test_bad_sources_get_one_line_and_write_nothing(
    tmp_path: Path, args: list[str], says: str
) -> None:
    out = _corraoi("sweep", "-i", "I1", "-n", "2", "-T", "100", *args, "-o", "sw", cwd=tmp_path)
    assert out.returncode != 0
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], out.stderr
    assert not (tmp_path / "sw").exists()


def test_the_sweep_table_names_the_collision_storm(tmp_path: Path) -> None:
    out = _corraoi("sweep", "-i", "I1", "-p", "rhorand-ucb", "--sources", "1,3", "-n", "4",
                   "-T", "400", "-o", "sw", cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "sw" / "summary.json").read_text())
    e = summary["notable"]["cells"]["rhorand-ucb(M=3)"]["most-collisions"]
    assert (f"most collisions: rhorand-ucb(M=3), {e['collisions']} at run {e['run']}"
            in out.stdout), out.stdout
    assert "--run worst|median|best|widest-gap|most-collisions|N" in out.stdout


def test_the_experiment_files_sources_key(tmp_path: Path) -> None:
    from corraoi.experiments.grid import grid_from_file

    f = tmp_path / "e.toml"
    f.write_text('instances = ["I1"]\npolicies = ["mctopm-ts"]\nsources = [2, 4]\nruns = 3\n')
    grid = grid_from_file(f)
    assert [c.sources for c in grid.cells] == [2, 4]
    assert [c.to_dict()["sources"] for c in grid.cells] == [2, 4]
    f.write_text('instances = ["I1"]\npolicies = ["mctopm-ts"]\nsources = [2.5]\n')
    with pytest.raises(ConfigError, match=r"e.toml: sources 2.5: expected an integer"):
        grid_from_file(f)


def _i1() -> Instance:
    from corraoi.model.instance import load_instance

    return load_instance("I1")


def _spec(name: str) -> object:
    from corraoi.policies import make_policy

    return make_policy(name)


def test_reproduce_decentralized_writes_the_figure_and_our_ordering(tmp_path: Path) -> None:
    from corraoi.experiments.sweeps import decentralized_grid

    grid = decentralized_grid(runs=2, horizon=300)
    assert len(grid.cells) == 12 * 4 and {c.sources for c in grid.cells} == {1, 2, 3, 4}
    out = _corraoi("reproduce", "decentralized", "-o", "dec", "-n", "2", "-T", "300",
                   cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    dec = tmp_path / "dec"
    assert (dec / "regret-vs-sources.png").stat().st_size > 10_000
    summary = json.loads((dec / "summary.json").read_text())
    text = (dec / "decentralized.md").read_text()
    assert "our choices" in text and "not the paper's" in text
    pols = summary["policies"]
    row = next(line for line in text.splitlines() if line.startswith("| mctopm-cts |"))
    cells = [c.strip() for c in row.strip("|").split("|")][1:]
    assert [float(c.split()[0]) for c in cells] == [
        round(pols[f"mctopm-cts(M={m})"]["regret_mean"], 1) for m in (1, 2, 3, 4)]
    line = next(x for x in text.splitlines() if x.startswith("- M = 2: "))
    order = line.removeprefix("- M = 2: ").split(" < ")
    means = [pols[f"{p}(M=2)"]["regret_mean"] for p in order]
    assert len(order) == 12 and means == sorted(means)


def test_record_from_a_sweep_of_several_sources_records_its_collision_storm(
    folders: tuple[Path, Path], tmp_path: Path
) -> None:
    import shutil

    many, _ = folders
    summary = json.loads((many / "summary.json").read_text())
    storm = summary["notable"]["cells"]["rhorand-ucb(M=3)"]["most-collisions"]
    out = _corraoi("record", "--from", many, "--run", "most-collisions", "--cell",
                   "rhorand-ucb(M=3)", "--no-rrd", cwd=tmp_path)  # fmt: skip
    assert out.returncode == 0, out.stderr
    (mcap,) = (tmp_path / "runs").glob("*.mcap")
    from corraoi.recorder.slotlog.reader import open_log

    assert corraoi.load(mcap).summary.regret == storm["regret"]
    config = open_log(mcap).config
    assert config.sources == 3 and config.seed == SEED + storm["run"]
    # the recording is checked against the sweep's row: a row that differs stops it
    bad = tmp_path / "bad"
    shutil.copytree(many, bad)
    start = 0 if storm["run"] < 5 else 5  # chunks of 5 runs
    (part,) = [p for p in (bad / "parts").glob(f"*-{start:09d}-*.npz") if _holds_sources(p, 3)]
    with np.load(part) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["regret"][storm["run"] - start] += 1.0
    np.savez(part, **arrays)
    out = _corraoi("record", "--from", bad, "--run", str(storm["run"]), "--cell",
                   "rhorand-ucb(M=3)", "--no-rrd", "-o", "x.mcap", cwd=tmp_path)  # fmt: skip
    assert out.returncode != 0 and "the sweep's row says" in out.stderr, out.stderr


def _holds_sources(part: Path, sources: int) -> bool:
    with np.load(part) as z:
        return "regret_by_source" in z.files and z["regret_by_source"].shape[2] == sources


def test_the_python_face_sweeps_sources_too() -> None:
    sw = corraoi.sweep("I1", "mctopm-ts", runs=3, horizon=300, sources=[2, 3], seed=SEED)
    assert list(sw.summary["policies"]) == ["mctopm-ts(M=2)", "mctopm-ts(M=3)"]
    totals = simulate_sources(_i1(), _spec("mctopm-ts"), range(SEED, SEED + 3), 300, 3)
    assert sw.summary["policies"]["mctopm-ts(M=3)"]["regret_mean"] == pytest.approx(
        totals.total_regret.mean())
    with pytest.raises(ConfigError, match=r"sources\[0\] 2.5: not an integer"):
        corraoi.sweep("I1", "mctopm-ts", runs=3, horizon=300, sources=[2.5])  # type: ignore[list-item]
    with pytest.raises(ConfigError, match="policy ucb is single-source; with sources 2"):
        corraoi.sweep("I1", "ucb", runs=3, horizon=300, sources=2)
