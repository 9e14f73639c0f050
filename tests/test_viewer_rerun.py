"""corraoi.viewer.replay and corraoi.viewer.compare: logs re-rendered into Rerun, read back and
compared."""

from __future__ import annotations

import subprocess
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from corraoi.cli import main  # noqa: E402
from corraoi.engine.block import RunConfig, SlotBlock  # noqa: E402
from corraoi.engine.summary import summarize_blocks  # noqa: E402
from corraoi.model.instance import load_instance  # noqa: E402
from corraoi.policies import make_policy  # noqa: E402
from corraoi.recorder.rerun.names import run_path  # noqa: E402
from corraoi.viewer import compare, replay  # noqa: E402
from corraoi.viewer.compare import (  # noqa: E402
    SUMMARY_ENTITY,
    comparability_warnings,
    log_colors,
    summary_table,
)
from corraoi.viewer.runs import safe_label, unique_labels  # noqa: E402

from .rrd_util import RERUN, read_rrd, strict_rerun  # noqa: E402, F401


def rrd_compare(a: Path, b: Path) -> subprocess.CompletedProcess:
    return subprocess.run([RERUN, "rrd", "compare", str(a), str(b)], capture_output=True, text=True)


def static_texts(path: Path) -> dict[str, str]:
    out = {}
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            data = chunk.to_record_batch().to_pydict()
            if "TextDocument:text" in data:
                out[chunk.entity_path] = data["TextDocument:text"][0][0]
    return out


def blueprint_text(path: Path) -> str:
    reader = RrdReader(path)
    (blueprint,) = reader.blueprints()
    texts = []
    for chunk in reader.stream(store=blueprint):
        for column in chunk.to_record_batch().columns:
            if "string" in str(column.type):
                texts.append(str(column.to_pylist()))
    return " ".join(texts)


def test_a_replayed_rrd_equals_the_live_one(tmp_path):
    from click.testing import CliRunner

    live_mcap, live_rrd = tmp_path / "run.mcap", tmp_path / "live.rrd"
    args = ["record", "-p", "aoi-aware-cts", "-T", "2500", "-s", "3"]
    res = CliRunner().invoke(main, [*args, "-o", str(live_mcap), "--rrd", str(live_rrd)])
    assert res.exit_code == 0, res.output
    done = replay(live_mcap, rrd_path=tmp_path / "replay.rrd")
    assert (done.slots, done.status, done.cut_short) == (2500, "complete", False)
    same = rrd_compare(live_rrd, tmp_path / "replay.rrd")
    assert same.returncode == 0, same.stdout + same.stderr
    # the check can fail: another seed renders differently
    res = CliRunner().invoke(main, ["record", "-p", "aoi-aware-cts", "-T", "2500", "-s", "4",
                                    "-o", str(tmp_path / "other.mcap"), "--no-rrd"])  # fmt: skip
    assert res.exit_code == 0, res.output
    replay(tmp_path / "other.mcap", rrd_path=tmp_path / "other.rrd")
    assert rrd_compare(live_rrd, tmp_path / "other.rrd").returncode != 0


def test_replay_of_a_cut_short_log_renders_the_slots_it_holds(tmp_path, make_config, engine):
    from corraoi.recorder.slotlog.sink import McapSink

    config = make_config("cucb", horizon=4000, seed=1)
    ref = SlotBlock.concat(engine(config))
    sink = McapSink(tmp_path / "run.mcap", config, fsync=False)
    for start in (0, 1000):
        sink.write(ref.slice(start, start + 1000))
    sink.abort()  # a writer that died: run.mcap.partial without footer
    done = replay(tmp_path / "run.mcap.partial", rrd_path=tmp_path / "cut.rrd")
    assert (done.slots, done.horizon, done.status, done.cut_short) == (
        2000,
        4000,
        "truncated",
        True,
    )
    assert "2000 of 4000" in done.description
    data = read_rrd(tmp_path / "cut.rrd")
    slots, values = data[f"/{run_path(config.label)}/regret"]
    assert np.array_equal(slots, np.arange(1, 2001))
    assert np.array_equal([v[0] for v in values], ref.regret[:2000])


def test_compare_puts_every_run_side_by_side(tmp_path, record_mcap):
    paths, refs = [], {}
    for policy in ("ucb", "cucb", "aoi-aware-ts"):
        path, config, ref = record_mcap(policy, seed=5, horizon=2000)
        paths.append(path)
        refs[policy] = (config, ref)
    out = tmp_path / "cmp.rrd"
    result = compare(paths, rrd_path=out)
    assert result.path == out and result.warnings == []
    assert [r.label for r in result.runs] == ["ucb", "cucb", "aoi-aware-ts"]
    data = read_rrd(out)
    for run in result.runs:
        config, ref = refs[run.label]
        base = f"/{run_path(run.label)}"
        for name in ("regret", "aoi"):
            slots, values = data[f"{base}/{name}"]
            assert np.array_equal(slots, np.arange(1, 2001))
            assert np.array_equal([v[0] for v in values], getattr(ref, name)), (run.label, name)
        assert np.array_equal(np.array(data[f"{base}/mu_hat"][1]), ref.mu_hat)
        assert run.summary == summarize_blocks(config, [ref])
    texts = static_texts(out)
    table = texts[f"/{SUMMARY_ENTITY}"]
    assert "| | ucb | cucb | aoi-aware-ts |" in table
    regrets = " | ".join(str(int(refs[p][1].regret[-1])) for p in ("ucb", "cucb", "aoi-aware-ts"))
    assert f"| pathwise regret | {regrets} |" in table
    bp = blueprint_text(out)
    assert "AoI regret [slot-ages] (pathwise), every run" in bp
    for label in ("ucb", "cucb", "aoi-aware-ts"):
        views = ("AoI [slots]", "arm played (1..4)", "means", "candidate set")
        for view in views:
            assert f"{label}: {view}" in bp
        assert f"{run_path(label)}/regret" in bp
    printed = result.table()
    assert printed.splitlines()[0].split() == ["ucb", "cucb", "aoi-aware-ts"]
    row = next(line for line in printed.splitlines() if line.startswith("AoI override slots"))
    assert row.split()[-3:] == [str(int(refs[p][1].override.sum())) for p in
                                ("ucb", "cucb", "aoi-aware-ts")]  # fmt: skip


def test_compare_without_an_output_only_summarises(record_mcap):
    a, config, ref = record_mcap("ts", horizon=1500)
    result = compare([a])
    assert result.path is None
    assert result.runs[0].summary == summarize_blocks(config, [ref])
    assert result.to_dict()["runs"][0]["summary"]["regret"] == int(ref.regret[-1])


def _fake(policy: str, *, instance: str = "I1", seed: int = 0, horizon: int = 1000, **params):
    config = RunConfig(load_instance(instance), make_policy(policy, **params), seed, horizon)
    return SimpleNamespace(config=config, cut_short=False, path=Path(f"{config.label}.mcap"),
                           summary="")  # fmt: skip


def test_labels_are_policy_names_made_unique_where_needed():
    assert unique_labels([_fake("ucb"), _fake("cucb")]) == ["ucb", "cucb"]
    assert unique_labels([_fake("ucb", seed=0), _fake("ucb", seed=1), _fake("cts")]) == [
        "ucb-s0", "ucb-s1", "cts",
    ]  # fmt: skip
    assert unique_labels([_fake("ucb", instance="I1"), _fake("ucb", instance="I2")]) == [
        "ucb-I1", "ucb-I2",
    ]  # fmt: skip
    assert unique_labels([_fake("ucb", c=2), _fake("ucb", c=1)]) == ["ucb-c2", "ucb-c1"]
    assert unique_labels([_fake("ucb"), _fake("ucb"), _fake("ucb")]) == ["ucb", "ucb-2", "ucb-3"]
    assert safe_label("my run/1 x") == "my_run_1_x"


def test_runs_that_cannot_be_compared_are_warned_about():
    assert comparability_warnings([_fake("ucb"), _fake("cucb")]) == []
    w = comparability_warnings([_fake("ucb", instance="I1"), _fake("ucb", instance="I2")])
    assert any("instances I1, I2" in x and "not comparable" in x for x in w)
    w = comparability_warnings([_fake("ucb", horizon=1000), _fake("cts", horizon=2000)])
    assert any("different horizons (1000, 2000)" in x for x in w)
    w = comparability_warnings([_fake("ucb", seed=0), _fake("cts", seed=1)])
    assert any("different seeds" in x for x in w)


def test_runs_of_one_policy_get_distinct_colours():
    colors = log_colors([_fake("ucb", seed=0), _fake("ucb", seed=1), _fake("cts")])
    assert len(set(colors)) == 3
    assert colors[0] == (31, 119, 180)


def test_the_side_by_side_table_aligns_columns(record_mcap):
    a, _, _ = record_mcap("ucb", horizon=1000, seed=1)
    b, _, _ = record_mcap("ucb", horizon=1000, seed=2)
    result = compare([a, b])
    lines = summary_table(result.runs).splitlines()
    assert lines[0].split() == ["ucb-s1", "ucb-s2"]
    assert len({len(line) for line in lines}) == 1  # every row as wide as the header
    seeds = next(line for line in lines if line.startswith("seed"))
    assert seeds.split() == ["seed", "1", "2"]


def test_a_damaged_chunk_found_mid_replay_leaves_no_file(tmp_path, record_mcap):
    import struct

    from corraoi.errors import LogError

    path, _, _ = record_mcap("ucb", horizon=5000)
    data = bytearray(path.read_bytes())
    pos, chunks = 8, 0
    while True:  # break the CRC of the fourth chunk: three blocks are sent before it
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x06:
            chunks += 1
            if chunks == 4:
                struct.pack_into("<I", data, pos + 9 + 24, 12345)
                break
        pos += 9 + length
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    sent: list[int] = []
    with pytest.raises(LogError, match="CRC mismatch"):
        replay(bad, rrd_path=tmp_path / "out.rrd", on_block=sent.append)
    assert sent == [1000, 1000, 1000]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap", path.name]
    with pytest.raises(LogError, match="CRC mismatch"):  # checked up front for a viewer
        replay(bad, viewer_url="rerun+http://127.0.0.1:9/proxy")


def _items_then_boom():
    from corraoi.errors import LogError

    yield 1
    yield 2
    raise LogError("boom: chunk at byte 7 is damaged")


def test_read_ahead_hands_on_errors_and_stops_early():
    import threading

    from corraoi.errors import LogError
    from corraoi.viewer import readahead

    got = []
    with pytest.raises(LogError, match="boom: chunk at byte 7"):
        for x in readahead.read_ahead(_items_then_boom()):
            got.append(x)
    assert got == [1, 2]
    before = threading.active_count()
    for x in readahead.read_ahead(iter(range(10**7)), depth=2):
        if x == 3:
            break
    assert threading.active_count() <= before  # the reader thread was stopped
    assert list(readahead.read_ahead([{"a": 1}, (2, b"x")])) == [{"a": 1}, (2, b"x")]


