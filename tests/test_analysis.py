"""corraoi.load on slot logs: values equal the raw MCAP messages, windows, Arrow batches,
the lazy import and the missing-extra message."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
from mcap.reader import make_reader

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")

import corraoi  # noqa: E402
from corraoi.errors import MissingExtraError, UsageError  # noqa: E402
from corraoi.recorder.slotlog.frames import slot_columns  # noqa: E402
from corraoi.recorder.slotlog.sink import McapSink  # noqa: E402

from .conftest import Recorded  # noqa: E402


def raw_messages(path: Path) -> list[dict]:
    with open(path, "rb") as f:
        return [json.loads(m.data) for _, _, m in make_reader(f).iter_messages()]


@pytest.fixture
def cucb_log(record_mcap: Callable[..., Recorded]) -> Recorded:
    return record_mcap("aoi-aware-cucb", horizon=2500, seed=4)


def test_slots_equal_the_raw_messages_for_every_column(cucb_log: Recorded):
    path, config, _ = cucb_log
    run = corraoi.load(path)
    df = run.slots
    rows = raw_messages(path)
    K = config.instance.K
    assert len(df) == len(rows) == 2500
    assert list(df.columns) == [n for n, _ in slot_columns(K)]
    assert {n: str(t) for n, t in df.dtypes.items()} == dict(slot_columns(K))
    for key in ("t", "x", "arm", "success", "aoi", "oracle_aoi", "regret", "estimator",
                "override"):  # fmt: skip
        assert df[key].tolist() == [r[key] for r in rows], key
    for k in range(K):
        assert df[f"mu_hat_{k + 1}"].tolist() == [r["mu_hat"][k] for r in rows]
        assert df[f"pulls_{k + 1}"].tolist() == [r["pulls"][k] for r in rows]
        assert df[f"cand_{k + 1}"].tolist() == [k + 1 in r["candidates"] for r in rows]
    # numbered from 1 as in the file: arm K and state n occur, 0 never does
    assert df["arm"].min() == 1 and df["arm"].max() <= K and df["x"].min() == 1
    assert df["override"].any()  # the AoI-aware rule fired: the column is not all False


def test_config_names_the_run(cucb_log: Recorded):
    path, config, _ = cucb_log
    cfg = corraoi.load(path).config
    assert (cfg["policy"], cfg["seed"], cfg["horizon"], cfg["instance"]) == (
        "aoi-aware-cucb", 4, 2500, "I1"
    )
    assert cfg["params"] == config.policy.params and cfg["best_arm"] == 2


def test_a_window_equals_the_same_rows_of_a_full_load(
    cucb_log: Recorded, monkeypatch: pytest.MonkeyPatch
):
    path, _, _ = cucb_log
    full = corraoi.load(path).slots
    import corraoi.recorder.slotlog.reader as reader

    decoded: list[int] = []
    real = reader.decode_messages

    def counting(payloads, *args, **kwargs):  # type: ignore[no-untyped-def]
        decoded.append(len(payloads))
        return real(payloads, *args, **kwargs)

    monkeypatch.setattr(reader, "decode_messages", counting)
    win = corraoi.load(path, slots=(1500, 1999)).slots
    assert decoded == [1000]  # only the chunk of slots 1001..2000 was decoded
    expected = full[(full.t >= 1500) & (full.t <= 1999)].reset_index(drop=True)
    pd.testing.assert_frame_equal(win, expected)
    decoded.clear()
    edge = corraoi.load(path, slots=(999, 2001)).slots
    assert decoded == [1000, 1000, 500] and edge.t.tolist() == list(range(999, 2002))


def test_a_window_of_a_log_without_footer(cucb_log: Recorded, tmp_path: Path):
    """A killed writer's .partial file has no chunk index: the chunk headers are walked."""
    src, config, blocks = cucb_log
    sink = McapSink(tmp_path / "cut.mcap", config, fsync=False)
    sink.write(blocks)
    part = sink.abort()
    assert part is not None and part.name.endswith(".partial")
    win = corraoi.load(part, slots=(1200, 2100)).slots
    full = corraoi.load(src).slots
    pd.testing.assert_frame_equal(
        win, full[(full.t >= 1200) & (full.t <= 2100)].reset_index(drop=True)
    )


def test_to_arrow_streams_batches_that_make_the_table(cucb_log: Recorded):
    path, _, _ = cucb_log
    run = corraoi.load(path)
    batches = list(run.to_arrow(batch=1000))
    assert [b.num_rows for b in batches] == [1000, 1000, 500]
    import pyarrow as pa

    table = pa.Table.from_batches(batches)
    pd.testing.assert_frame_equal(table.to_pandas(), run.slots)


def test_bad_windows_are_one_line_errors(cucb_log: Recorded):
    path, _, _ = cucb_log
    for bad in ((0, 5), (10, 3), "x"):
        with pytest.raises(UsageError, match="slots"):
            corraoi.load(path, slots=bad)  # type: ignore[arg-type]


def test_import_corraoi_stays_light():
    code = (
        "import sys, corraoi; assert callable(corraoi.load); "
        "heavy = [m for m in ('pandas', 'pyarrow', 'corraoi.recorder', 'numba')"
        " if m in sys.modules]; "
        "print(heavy)"
    )
    # accessing corraoi.load imports corraoi.face.tables, which imports neither pandas nor recorder
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_load_names_the_extra_without_pandas(
    cucb_log: Recorded, monkeypatch: pytest.MonkeyPatch
):
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now raises ImportError
    run = corraoi.load(cucb_log[0])  # the run and its figures need no table
    assert run.summary.slots == run.log.n_slots
    with pytest.raises(MissingExtraError, match=r'pip install "corraoi\[analysis\]"'):
        _ = run.slots


def test_load_refuses_what_is_not_a_log(tmp_path: Path):
    bad = tmp_path / "notes.mcap"
    bad.write_text("hello")
    with pytest.raises(UsageError, match="not an MCAP file"):
        corraoi.load(bad)
    with pytest.raises(UsageError, match="no such file"):
        corraoi.load(tmp_path / "missing.mcap")


def test_results_reader_takes_a_partitioned_dataset(tmp_path: Path):
    """The scale work partitions results.parquet by instance: the reader takes both."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from corraoi.recorder.sweeplog.results import read_results, results_metadata, results_schema

    md = results_metadata({"horizon": 10, "seed": 0, "instance": {"name": "I1"}})
    schema = results_schema(md)
    rows = {
        "instance": ["I1", "I1", "I2"], "policy": ["ucb"] * 3, "params": ['{"c": 2.0}'] * 3,
        "horizon": [10] * 3, "run": [0, 1, 0], "seed": [0, 1, 0], "t": [10] * 3,
        "regret": [1.0, 2.0, 3.0], "estimator": [0.5, 0.25, 0.125], "best_arm_pulls": [4, 5, 6],
    }  # fmt: skip
    table = pa.Table.from_pydict(rows, schema=schema)
    single = tmp_path / "one" / "results.parquet"
    single.parent.mkdir()
    pq.write_table(table, single)
    ds_dir = tmp_path / "many" / "results.parquet"
    for inst in ("I1", "I2"):
        part = table.filter(pa.compute.equal(table["instance"], inst)).drop_columns(["instance"])
        (ds_dir / f"instance={inst}").mkdir(parents=True)
        where = ds_dir / f"instance={inst}" / "part-0.parquet"
        pq.write_table(part.replace_schema_metadata(md), where)
    a = read_results(single)
    b = read_results(ds_dir).sort_values(["instance", "run"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(a, b)
    assert b["instance"].tolist() == ["I1", "I1", "I2"]
