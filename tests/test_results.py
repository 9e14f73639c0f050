"""results.parquet from `corraoi sweep -o`, paired comparisons (--baseline), corraoi.load of
a sweep, and `corraoi export` round trips."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

pd = pytest.importorskip("pandas")
pq = pytest.importorskip("pyarrow.parquet")

import corraoi  # noqa: E402
from corraoi._version import __version__  # noqa: E402
from corraoi.cli import main  # noqa: E402
from corraoi.experiments.montecarlo import mean_ci95  # noqa: E402
from corraoi.recorder.slotlog.frames import slot_columns  # noqa: E402
from corraoi.recorder.sweeplog.read import read_sweep  # noqa: E402
from corraoi.recorder.sweeplog.results import COLUMNS, read_results  # noqa: E402

from .conftest import Recorded  # noqa: E402

POLICIES = ("ucb", "cucb", "cts")
RUNS, T = 12, 600


def run(*args: str) -> Any:
    return CliRunner().invoke(main, list(args))


@pytest.fixture(scope="module")
def swept(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("sweep") / "I1"
    res = run("sweep", "-p", ",".join(POLICIES), "-n", str(RUNS), "-T", str(T), "-s", "5",
              "-o", str(out), "--checkpoints", "20", "--baseline", "ucb", "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout[: res.stdout.rindex("}") + 1])
    return out, summary


def test_results_file_has_the_documented_columns_and_metadata(swept):
    out, summary = swept
    df = read_results(out / "results.parquet")
    assert [(c, str(t)) for c, t in df.dtypes.items()] == [
        (n, {"string": "str", "int64": "int64", "float64": "float64"}[t]) for n, t in COLUMNS
    ]
    log = read_sweep(out / "sweep.mcap")
    n_checkpoints = len(log.curves["ucb"])
    assert len(df) == len(POLICIES) * RUNS * n_checkpoints
    assert set(df["instance"]) == {"I1"} and set(df["horizon"]) == {T}
    assert df.groupby("policy", sort=False).size().index.tolist() == list(POLICIES)
    assert sorted(set(df["run"])) == list(range(RUNS))
    assert (df["seed"] == df["run"] + 5).all()
    assert set(df.loc[df.policy == "ucb", "params"]) == {'{"c": 2.0}'}
    # a dataset partitioned by instance, the grid in its metadata
    part = out / "results.parquet" / "instance=I1" / "part-0.parquet"
    raw = pq.read_schema(part).metadata
    md = {k.decode(): v.decode() for k, v in raw.items()}
    assert md["corraoi_version"] == __version__ and md["format_version"] == "1"
    grid = json.loads(md["sweep_config"])
    assert (grid["runs"], grid["seed"]) == (RUNS, 5)
    assert [c["policy"]["name"] for c in grid["cells"]] == list(POLICIES)


def test_per_run_results_average_to_the_printed_means_exactly(swept):
    out, summary = swept
    df = read_results(out / "results.parquet")
    log = read_sweep(out / "sweep.mcap")
    for name in POLICIES:
        at_T = df[(df.policy == name) & (df.t == T)].sort_values("run")
        entry = summary["policies"][name]
        assert float(np.mean(at_T["regret"].to_numpy())) == entry["regret_mean"]
        assert float(np.mean(at_T["estimator"].to_numpy())) == entry["estimator_mean"]
        assert float(np.mean(at_T["best_arm_pulls"].to_numpy() / T)) == entry["best_arm_share"]
        m, h = mean_ci95(at_T["regret"].to_numpy())
        assert float(h) == entry["regret_ci95"]
        # every checkpoint of the sweep log is the mean of the per-run values there
        curve = log.curves[name]
        per_t = df[df.policy == name].groupby("t")["regret"].agg(lambda v: float(np.mean(v)))
        assert per_t.index.tolist() == curve.t.tolist()
        assert per_t.to_numpy().tolist() == curve.regret_mean.tolist()


def test_paired_difference_against_the_baseline(swept):
    out, summary = swept
    assert summary["baseline"] == "ucb" and "paired_diff_mean" not in summary["policies"]["ucb"]
    df = read_results(out / "results.parquet")
    base = df[(df.policy == "ucb") & (df.t == T)].sort_values("run")["regret"].to_numpy()
    for name in ("cucb", "cts"):
        entry = summary["policies"][name]
        mine = df[(df.policy == name) & (df.t == T)].sort_values("run")["regret"].to_numpy()
        # the mean of the differences is the difference of the means
        assert entry["paired_diff_mean"] == pytest.approx(
            entry["regret_mean"] - summary["policies"]["ucb"]["regret_mean"], abs=1e-9
        )
        m, h = mean_ci95(mine - base)
        assert (entry["paired_diff_mean"], entry["paired_diff_ci95"]) == (float(m), float(h))
        unpaired = np.hypot(entry["regret_ci95"], summary["policies"]["ucb"]["regret_ci95"])
        assert entry["unpaired_diff_ci95"] == pytest.approx(unpaired, rel=1e-12)


def test_paired_table_and_unknown_baseline(tmp_path: Path):
    res = run("sweep", "-p", "ucb,cucb", "-n", "4", "-T", "200", "--baseline", "cucb")
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    head = lines.index(next(x for x in lines if x.startswith("paired against cucb")))
    row = lines[head + 2].split()
    assert row[0] == "ucb" and len(row) == 4 and float(row[2]) >= 0
    bad = run("sweep", "-p", "ucb,cucb", "-n", "4", "-T", "200", "--baseline", "cts")
    assert bad.exit_code == 2
    assert bad.stderr.strip().splitlines() == [
        "corraoi: error: --baseline cts: not one of the swept policies (ucb, cucb); "
        "expected one of them"
    ]


def test_load_a_sweep_folder_or_its_log(swept):
    out, summary = swept
    data = corraoi.load(out)
    pd.testing.assert_frame_equal(data.runs, read_results(out / "results.parquet"))
    assert data.summary == json.loads((out / "summary.json").read_text())
    assert data.summary["policies"]["cucb"]["paired_diff_mean"] == (
        summary["policies"]["cucb"]["paired_diff_mean"]
    )
    via_log = corraoi.load(out / "sweep.mcap")
    pd.testing.assert_frame_equal(via_log.runs, data.runs)
    curves = data.curves
    assert curves.columns.tolist()[:6] == ["policy", "t", "regret_mean", "regret_ci95",
                                           "estimator_mean", "estimator_ci95"]  # fmt: skip
    assert len(curves) == len(data.runs) // RUNS
    with pytest.raises(corraoi.UsageError, match="slots"):
        corraoi.load(out, slots=(1, 2))


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_export_round_trips_a_slot_log(
    ext: str, tmp_path: Path, record_mcap: Callable[..., Recorded]
):
    path, config, _ = record_mcap("ts", horizon=1500)
    target = tmp_path / f"slots.{ext}"
    res = run("export", str(path), "-o", str(target))
    assert res.exit_code == 0, res.output
    assert res.stdout.strip() == f"wrote {target}: 1500 rows (slots, {ext})"
    dtypes = dict(slot_columns(config.instance.K))
    back = pd.read_csv(target, dtype=dtypes) if ext == "csv" else pd.read_parquet(target)
    pd.testing.assert_frame_equal(back, corraoi.load(path).slots)
    assert not list(tmp_path.glob("*.partial"))


@pytest.mark.parametrize("ext", ["csv", "parquet"])
def test_export_round_trips_sweep_results(ext: str, tmp_path: Path, swept):
    out, _ = swept
    target = tmp_path / f"runs.{ext}"
    res = run("export", str(out), "-o", str(target))
    assert res.exit_code == 0, res.output
    want = read_results(out / "results.parquet")
    if ext == "csv":
        back = pd.read_csv(target, dtype={n: t if t != "string" else "str" for n, t in COLUMNS},
                           keep_default_na=False)  # fmt: skip
    else:
        back = pd.read_parquet(target)
    pd.testing.assert_frame_equal(back, want)


@pytest.fixture(scope="module")
def swept_many(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sweep folder of rhorand-ucb with one and with two sources."""
    out = tmp_path_factory.mktemp("many") / "I1"
    res = run("sweep", "-p", "rhorand-ucb", "--sources", "1,2", "-n", "4", "-T", "200",
              "--checkpoints", "5", "-o", str(out))  # fmt: skip
    assert res.exit_code == 0, res.output
    return out


def test_info_of_a_sweep_of_several_sources_lines_up_its_runs_worth_watching(swept_many):
    # "most-collisions" is longer than the kind column was (7): its rows were pushed right
    res = run("info", str(swept_many))
    assert res.exit_code == 0, res.output
    named = ("worst", "best", "median", "most-collisions")
    rows = [line for line in res.output.splitlines()
            if len(line.split()) > 1 and line.split()[1] in named]  # fmt: skip
    assert {line.split()[1] for line in rows} == set(named)
    assert len({line.index(" run ") for line in rows}) == 1  # one column for the regrets


def test_csv_export_of_a_sweep_of_several_sources_spreads_each_sources_regret(
        tmp_path: Path, swept_many: Path):  # fmt: skip
    # results.parquet holds regret_by_source as a list, which CSV cannot (a pyarrow
    # traceback): one column per source, empty in the rows of a cell of fewer sources
    out = swept_many
    res = run("export", str(out), "-o", str(tmp_path / "runs.csv"))
    assert res.exit_code == 0 and "Traceback" not in res.output, res.output
    back = pd.read_csv(tmp_path / "runs.csv")
    want = read_results(out / "results.parquet")
    lists = want.pop("regret_by_source")
    assert list(back.columns) == [*want.columns, "regret_by_source_1", "regret_by_source_2"]
    for m in (0, 1):
        got = back[f"regret_by_source_{m + 1}"].to_numpy()
        assert np.array_equal(got, [v[m] if len(v) > m else np.nan for v in lists],
                              equal_nan=True)  # fmt: skip
    assert set(back.loc[back["sources"] == 1, "regret_by_source_2"].isna()) == {True}
    assert not back.loc[back["sources"] == 2, "regret_by_source_2"].isna().any()
    assert np.array_equal(back["regret"], want["regret"])


def test_export_refusals_are_one_line(tmp_path: Path, record_mcap: Callable[..., Recorded]):
    path, _, _ = record_mcap("ucb", horizon=1000)
    res = run("export", str(path), "-o", str(tmp_path / "x.xlsx"))
    assert res.exit_code == 2 and res.stderr.count("\n") == 1
    assert "unknown export format '.xlsx'" in res.stderr and ".csv or .parquet" in res.stderr
    taken = tmp_path / "taken.csv"
    taken.write_text("keep me")
    res = run("export", str(path), "-o", str(taken))
    assert res.exit_code == 2 and "already exists" in res.stderr
    assert taken.read_text() == "keep me"
    res = run("export", str(tmp_path / "missing.mcap"), "-o", str(tmp_path / "m.csv"))
    assert res.exit_code == 2 and "no such file" in res.stderr
    assert not (tmp_path / "m.csv").exists() and not list(tmp_path.glob("*.partial"))


def test_reproduce_writes_per_run_results_per_instance(tmp_path: Path):
    out = tmp_path / "paper"
    res = run("reproduce", "-o", str(out), "-n", "3", "-T", "200")
    assert res.exit_code == 0, res.output
    for inst in ("I1", "I2"):
        summary = json.loads((out / inst / "summary.json").read_text())
        df = corraoi.load(out / inst).runs  # the instance's rows of paper/results.parquet
        assert set(df["instance"]) == {inst} and df["policy"].nunique() == 12
        at_T = df[df.t == 200]
        for name, group in at_T.groupby("policy"):
            assert group["run"].tolist() == [0, 1, 2]
            assert float(np.mean(group["regret"].to_numpy())) == (
                summary["policies"][name]["regret_mean"]
            )


def test_sweep_without_pyarrow_warns_and_writes_the_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)  # import fails as if absent
    out = tmp_path / "s"
    res = run("sweep", "-p", "ucb", "-n", "2", "-T", "100", "-o", str(out), "--checkpoints", "5")
    assert res.exit_code == 0, res.output
    warning = 'results.parquet not written: install the analysis extra, pip install "corraoi['
    assert warning in res.stderr
    assert not (out / "results.parquet").exists() and (out / "sweep.mcap").is_file()
