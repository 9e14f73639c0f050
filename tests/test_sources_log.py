"""The log and the views of a run of several sources (issue 43, item 3): the MCAP slot log
(a channel per source, format version 4), the tidy table, the summary, info, replay,
compare and diff, the Rerun recording, and ``--sources`` on the face and the command line.

The runs are made by hand from single-source runs (:mod:`tests.sources_fake`): what is
tested is what the log and the views do with a run of several sources, not its engine.
"""

from __future__ import annotations

import json
import subprocess
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader

import corraoi
from corraoi.cli import main
from corraoi.engine.block import RunConfig, SourcesBlock
from corraoi.engine.slot_record import PER_SOURCE, SHARED, record_for
from corraoi.engine.summary import summarize_blocks
from corraoi.errors import ConfigTypeError, ConfigValueError
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.recorder.vocab import SLOT_TOPIC, slot_topic

from .rrd_util import RERUN, read_rrd, strict_rerun  # noqa: F401 (autouse: Rerun fails loudly)
from .sources_fake import install, policy_name, sources_run

T = 2500
#: the policy the runs name (what they play is sources_fake's)
POLICY = policy_name()


@pytest.fixture(scope="module")
def three() -> SourcesBlock:
    return sources_run(load_instance("I1"), 1, T, 3)


def _config(M: int = 3, horizon: int = T, **kw) -> RunConfig:
    policy = make_policy(POLICY if M > 1 else "ucb")
    return RunConfig(load_instance("I1"), policy, 1, horizon, sources=M, **kw)


def _write(path, block: SourcesBlock, step: int = 700, M: int = 3):
    with McapSink(path, _config(M, len(block)), fsync=False) as sink:
        for i in range(0, len(block), step):
            sink.write(block.slice(i, i + step))
    return path


def test_the_hand_made_run_is_consistent(three):
    """(the helper's run: collisions deliver nothing, the x path is shared)"""
    a, b, c = three.sources
    clash = (a.arm == b.arm) | (a.arm == c.arm)
    assert np.array_equal(a.collided, clash) and not (a.success & a.collided).any()
    assert a.collided.any() and np.array_equal(b.x, a.x)


def test_a_sources_block_round_trips_through_the_log_field_by_field(tmp_path, three):
    log = open_log(_write(tmp_path / "m3.mcap", three))
    assert (log.status, log.n_slots, log.format_version, log.sources) == ("complete", T, 4, 3)
    got = log.read_all()
    assert isinstance(got, SourcesBlock) and got.M == 3
    names = tuple(f.name for f in record_for(3) if getattr(three.sources[0], f.name) is not None)
    assert "collided" in names
    for mine, ref in zip(got.sources, three.sources, strict=True):
        assert mine.fields() == ref.fields() == names
        for f in names:
            assert np.array_equal(mine.column(f), ref.column(f), equal_nan=True), f
    assert got.equals(three)
    # every block size and window gives the same slots back, source by source
    assert SourcesBlock.concat(list(log.blocks(333))).equals(three)
    (part,) = [w for w in log.window(990, 1010) if w.t[0] == 1001]
    assert part.equals(three.slice(1000, 1010))


def test_each_source_has_its_channel_and_todays_readers_refuse_the_file(tmp_path, three):
    path = _write(tmp_path / "m3.mcap", three)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.id: (c.topic, c.metadata) for c in summary.channels.values()}
        per = {m: [json.loads(msg.data) for _, _, msg in reader.iter_messages(
            topics=[slot_topic(m, 3)])] for m in (1, 2, 3)}  # fmt: skip
    assert topics == {m: (f"{SLOT_TOPIC}/{m}", {"format_version": "4", "source": str(m)})
                      for m in (1, 2, 3)}  # fmt: skip
    assert summary.statistics.channel_message_counts == {1: T, 2: T, 3: T}
    for m, msgs in per.items():
        src = three.sources[m - 1]
        assert [r["t"] for r in msgs] == list(range(1, T + 1))
        assert [r["arm"] for r in msgs] == (src.arm + 1).tolist()
        assert [r["collided"] for r in msgs] == src.collided.tolist()
        assert [r["x"] for r in msgs] == (three.x + 1).tolist()
    log = open_log(path)
    assert log.metadata["format_version"] == "4"  # newer than version 3: "upgrade corraoi"
    assert json.loads(log.metadata["config"])["sources"] == 3
    regrets = [int(s.regret[-1]) for s in three.sources]
    assert json.loads(log.end["regret_by_source"]) == regrets
    assert int(log.end["regret"]) == sum(regrets)


def test_a_block_of_other_sources_is_refused(tmp_path, three):
    with McapSink(tmp_path / "x.mcap", _config(2, T), fsync=False) as sink:
        with pytest.raises(ValueError, match="block has 3 source"):
            sink.write(three)
        with pytest.raises(ValueError, match="block has 1 source"):
            sink.write(three.sources[0])
        sink.abort()


def test_the_summary_regret_is_the_sum_of_the_sources(three):
    s = summarize_blocks(_config(), [three.slice(0, 1000), three.slice(1000, None)])
    assert s.regret_by_source == tuple(int(b.regret[-1]) for b in three.sources)
    assert s.regret == sum(s.regret_by_source)
    assert s.collisions == sum(int(b.collided.sum()) for b in three.sources)
    assert s.pulls == tuple(int(v) for v in sum(b.pulls[-1] for b in three.sources))
    d = s.to_dict()
    assert d["regret_by_source"] == list(s.regret_by_source) and d["estimator"] is None
    # a single source's summary is what it was (no key of several sources)
    one = summarize_blocks(_config(1), [three.sources[0]])
    assert one.regret_by_source is None and "regret_by_source" not in one.to_dict()


@pytest.fixture
def recorded(tmp_path, monkeypatch):
    """corraoi.record(sources=3) of the hand-made runs, seeds 1 and 2 (the same call the
    command line makes)."""
    install(monkeypatch)
    a = corraoi.record(POLICY, "I1", seed=1, horizon=1200, sources=3, path=tmp_path / "a.mcap",
                       rrd=False)  # fmt: skip
    b = corraoi.record(POLICY, "I1", seed=2, horizon=1200, sources=3, path=tmp_path / "b.mcap",
                       rrd=False)  # fmt: skip
    return a, b


def test_record_sources_writes_the_run_and_its_summary(recorded):
    a, _ = recorded
    ref = sources_run(load_instance("I1"), 1, 1200, 3)
    assert a.label == f"{POLICY}-I1-m3-s1" and a.log.config.sources == 3
    assert open_log(a.path).read_all().equals(ref)
    s = a.summary  # measured while recording
    assert s.regret_by_source == tuple(int(b.regret[-1]) for b in ref.sources)
    assert s.regret == sum(s.regret_by_source)
    assert corraoi.load(a.path).summary == s  # the same from the log


def test_run_slots_is_tidy_one_row_per_slot_and_source(recorded):
    a, _ = recorded
    ref = sources_run(load_instance("I1"), 1, 1200, 3)
    df = a.slots
    assert df.shape[0] == 3 * 1200
    assert list(df.columns[:3]) == ["t", "source", "x"]
    assert "collided" in df.columns and "mu_hat_4" in df.columns
    assert df["source"].tolist() == [1, 2, 3] * 1200
    assert df["t"].tolist() == np.repeat(np.arange(1, 1201), 3).tolist()
    assert (df.groupby("t")["x"].nunique() == 1).all()  # the slot's shared x repeated
    for m, src in enumerate(ref.sources, start=1):
        rows = df[df["source"] == m]
        assert rows["arm"].tolist() == (src.arm + 1).tolist()
        assert rows["collided"].tolist() == src.collided.tolist()
        assert rows["regret"].tolist() == src.regret.tolist()
        assert rows["x"].tolist() == (src.x + 1).tolist()
    assert set(SHARED) | set(PER_SOURCE) >= {"t", "x", "collided"}
    window = corraoi.load(a.path, slots=(10, 19)).slots
    assert window.shape[0] == 30 and window["t"].min() == 10


def test_info_of_a_multi_source_log(recorded):
    a, _ = recorded
    res = CliRunner().invoke(main, ["info", str(a.path)])
    assert res.exit_code == 0, res.output
    s = a.summary
    assert "format version 4" in res.output
    assert "sources                3 sharing the channels" in res.output
    assert f"pathwise regret        {s.regret} (all sources)" in res.output
    assert "regret per source      " + " ".join(map(str, s.regret_by_source)) in res.output
    assert f"collisions             {s.collisions}" in res.output


def test_diff_pairs_the_sources(recorded, tmp_path):
    a, b = recorded
    assert corraoi.diff(a, a).identical
    # source 2's arm changed at slot 700: diff names the slot, the field and the source
    ref = open_log(a.path).read_all()
    two = ref.sources[1]
    arm = two.arm.copy()
    arm[699] = (arm[699] + 1) % 4
    changed = SourcesBlock((ref.sources[0], replace(two, arm=arm), ref.sources[2]))
    with McapSink(tmp_path / "c.mcap", a.log.config, fsync=False) as sink:
        sink.write(changed)
    report = corraoi.diff(a, tmp_path / "c.mcap")
    arm_diff = report["arm"]
    assert (arm_diff.first_slot, arm_diff.slots_differing, arm_diff.source) == (700, 1, 2)
    assert (arm_diff.a_value, arm_diff.b_value) == (int(two.arm[699]) + 1, int(arm[699]) + 1)
    assert report["x"].identical and report.differing_fields == ["arm"]
    assert "source 2: a=" in report.message()
    other = corraoi.diff(a, b)
    assert not other.identical and other["x"].source is None  # x is the slot's, shared
    assert (
        "regret source 2",
        a.summary.regret_by_source[1],
        b.summary.regret_by_source[1],
        b.summary.regret_by_source[1] - a.summary.regret_by_source[1],
    ) in other.finals()


def test_compare_and_replay_of_a_multi_source_log(recorded, tmp_path):
    a, b = recorded
    got = corraoi.compare([a, b])
    assert [r.summary.regret_by_source for r in got.runs] == [
        a.summary.regret_by_source,
        b.summary.regret_by_source,
    ]
    res = CliRunner().invoke(main, ["compare", str(a.path), str(b.path), "-o",
                                    str(tmp_path / "cmp.rrd")])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert (tmp_path / "cmp.rrd").stat().st_size > 0
    played = corraoi.replay(a, rrd=tmp_path / "a.rrd")
    assert played.slots == 1200 and (tmp_path / "a.rrd").stat().st_size > 0


def test_compare_of_a_run_of_several_sources_beside_a_run_of_one(recorded, tmp_path):
    # their summaries have different figures (regret per source, collisions; the paper's
    # estimator): every figure is a row, "-" for a run without it (an IndexError before)
    a, _ = recorded
    one = corraoi.record("ucb", "I1", seed=1, horizon=1200, path=tmp_path / "one.mcap",
                         rrd=False)  # fmt: skip
    res = CliRunner().invoke(main, ["compare", str(a.path), str(one.path), "-o",
                                    str(tmp_path / "mixed.rrd")])  # fmt: skip
    assert res.exit_code == 0 and "Traceback" not in res.output, res.output
    rows = {line[:25].strip(): line[25:].split() for line in res.output.splitlines()
            if line[:25].strip()}  # fmt: skip
    assert rows["regret per source"] == [*map(str, a.summary.regret_by_source), "-"]
    assert rows["collisions"][-1] == "-" and rows["collisions"][0] == str(a.summary.collisions)
    assert rows["paper's estimator"][0] == "-"
    assert rows["paper's estimator"][1] == f"{one.summary.estimator:.6g}"
    assert (tmp_path / "mixed.rrd").stat().st_size > 0


def test_the_recording_of_several_sources_draws_each_source_and_the_collisions(recorded, tmp_path):
    a, _ = recorded
    ref = sources_run(load_instance("I1"), 1, 1200, 3)
    corraoi.replay(a, rrd=tmp_path / "a.rrd")
    got = read_rrd(tmp_path / "a.rrd")
    base = f"/runs/{POLICY}-I1-m3-s1"

    def values(path):
        slots, vals = got[f"{base}/{path}"]
        return np.asarray(slots), np.asarray([v[0] if isinstance(v, list) else v for v in vals])

    t, total = values("regret")
    assert np.array_equal(t, np.arange(1, 1201))
    assert np.array_equal(total, sum(s.regret for s in ref.sources))
    for m, src in enumerate(ref.sources, start=1):
        assert np.array_equal(values(f"sources/{m}/aoi")[1], src.aoi)
        assert np.array_equal(values(f"sources/{m}/oracle_aoi")[1], src.oracle_aoi)
        assert np.array_equal(values(f"sources/{m}/regret")[1], src.regret)
        lane = values(f"occupancy/{m}")[1]  # the channel, a little off its line
        assert np.array_equal(np.rint(lane), src.arm + 1)
    # a red cross at every (slot, channel) where sources collided
    at, channel = values("occupancy/collided")
    want = sorted({(int(t), int(s.arm[t - 1]) + 1) for s in ref.sources
                   for t in np.flatnonzero(s.collided) + 1})  # fmt: skip
    assert sorted(zip(at.tolist(), channel.astype(int).tolist(), strict=True)) == want


@pytest.mark.parametrize(
    ("value", "error", "words"),
    [
        (0, ConfigValueError, "sources 0: out of range, expected 1..4"),
        (5, ConfigValueError, "sources 5: out of range, expected 1..4 (at most the 4 arms"),
        (2.5, ConfigTypeError, "sources 2.5: not an integer"),
        (2.0, ConfigTypeError, "sources 2.0: not an integer"),
        ("2", ConfigTypeError, "sources '2': not an integer"),
    ],
)
def test_bad_sources_on_the_face_are_one_typed_error(value, error, words, tmp_path):
    with pytest.raises(error) as info:
        corraoi.record(POLICY, "I1", horizon=50, sources=value, path=tmp_path / "x.mcap")
    assert words in str(info.value) and "\n" not in str(info.value)
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize(
    ("value", "words"),
    [
        ("0", "0 is not in the range 1..4096"),
        ("5", "--sources 5: out of range, expected 1..4 (at most the 4 arms of instance I1)"),
        ("2.5", "'2.5' is not a valid integer"),
        ("two", "'two' is not a valid integer"),
    ],
)
def test_bad_sources_on_the_command_line_are_one_line(value, words, tmp_path):
    res = CliRunner().invoke(main, ["record", "-p", POLICY, "-T", "50", "--sources", value,
                                    "-o", str(tmp_path / "x.mcap")])  # fmt: skip
    assert res.exit_code != 0 and "Traceback" not in res.output
    err = res.stderr.strip()
    assert words in err and len(err.splitlines()) <= 3, err  # (click's usage lines)
    assert not list(tmp_path.iterdir())


def test_record_sources_on_the_command_line(tmp_path, monkeypatch):
    install(monkeypatch)
    res = CliRunner().invoke(main, ["record", "-p", POLICY, "-T", "300", "--sources", "2",
                                    "-o", str(tmp_path / "r.mcap"), "--no-rrd"])  # fmt: skip
    assert res.exit_code == 0, res.output
    log = open_log(tmp_path / "r.mcap")
    assert log.config.sources == 2 and log.read_all().equals(
        sources_run(load_instance("I1"), 0, 300, 2)
    )


def test_recover_keeps_every_source_of_a_log_cut_short(tmp_path, three):
    path = tmp_path / "cut.mcap"
    sink = McapSink(path, _config(3, T), fsync=False)
    sink.write(three.slice(0, 2300))
    sink.abort()  # the writer stops without finishing: the .partial stays, no footer
    cut = open_log(tmp_path / "cut.mcap.partial")
    assert (cut.status, cut.n_slots) == ("truncated", 2300)
    done = corraoi.recover(tmp_path / "cut.mcap.partial", out=tmp_path / "fixed.mcap")
    fixed = open_log(done.path)
    assert (fixed.status, fixed.n_slots, fixed.sources) == ("interrupted", 2300, 3)
    assert fixed.read_all().equals(three.slice(0, 2300))
    regrets = [int(s.regret[2299]) for s in three.sources]
    assert json.loads(fixed.end["regret_by_source"]) == regrets
    assert int(fixed.end["regret"]) == sum(regrets)


def test_the_recording_of_several_sources_is_the_same_recorded_or_replayed(tmp_path, monkeypatch):
    install(monkeypatch)
    run = corraoi.record(POLICY, "I1", seed=3, horizon=1500, sources=2, path=tmp_path / "r.mcap")
    corraoi.replay(run, rrd=tmp_path / "again.rrd")
    same = subprocess.run([RERUN, "rrd", "compare", str(run.rrd), str(tmp_path / "again.rrd")],
                          capture_output=True, text=True)  # fmt: skip
    assert same.returncode == 0, same.stdout + same.stderr


def test_record_with_the_engine_of_several_sources(tmp_path):
    """`corraoi record -p rhorand-cucb --sources 3 -i I1` (issue 43's "done when"), once the
    engine of several sources is in: its log holds three sources whose collisions are what
    their arms say, and a recording."""
    pytest.importorskip("corraoi.engine.sources")
    args = ["-p", "rhorand-cucb", "--sources", "3", "-i", "I1", "-T", "2000"]
    res = CliRunner().invoke(main, ["record", *args, "-o", str(tmp_path / "r.mcap")])
    assert res.exit_code == 0, res.output
    log = open_log(tmp_path / "r.mcap")
    got = log.read_all()
    assert isinstance(got, SourcesBlock) and got.M == 3 and len(got) == 2000
    arms = np.stack([s.arm for s in got.sources])
    for m, s in enumerate(got.sources):
        others = np.delete(arms, m, axis=0)
        assert np.array_equal(s.collided, (others == s.arm).any(axis=0))
        assert not (s.success & s.collided).any()
    run = corraoi.load(tmp_path / "r.mcap")
    assert run.summary.regret == sum(run.summary.regret_by_source)
    assert (tmp_path / "r.rrd").stat().st_size > 0


def test_a_run_of_several_sources_goes_to_the_sinks_that_take_it_and_refuses_the_others(
        tmp_path):  # fmt: skip
    from corraoi.errors import ConfigError
    from corraoi.recorder.sink import Sink

    class Single(Sink):  # takes a single source's blocks only (the default)
        def write(self, block):
            raise AssertionError("a block of several sources reached it")

        def close(self):
            pass

    class Several(Sink):
        takes_sources = True

        def __init__(self):
            self.blocks = []

        def write(self, block):
            self.blocks.append(block)

        def close(self):
            pass

    with pytest.raises(ConfigError, match=r"2 sources .* Single takes a single source's"):
        corraoi.record("rhorand-ucb", "I1", horizon=300, sources=2, path=tmp_path / "a.mcap",
                       rrd=False, sinks=[Several(), Single()])  # fmt: skip
    assert list(tmp_path.iterdir()) == []  # refused before anything was written
    taker = Several()
    run = corraoi.record("rhorand-ucb", "I1", horizon=2500, sources=2, path=tmp_path / "b.mcap",
                         rrd=False, sinks=[taker])  # fmt: skip
    got = SourcesBlock.concat(taker.blocks)
    assert isinstance(taker.blocks[0], SourcesBlock) and got.M == 2 and len(got) == 2500
    assert tuple(int(s.regret[-1]) for s in got.sources) == run.summary.regret_by_source
