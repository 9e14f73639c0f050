"""The slot record declared once (corraoi.engine.slot_record), and the field that proves it:
``score`` (with ``forced`` and ``override_threshold``), from every engine tier to every
reader; logs written before it still read; the consumers agree with the declaration."""

from __future__ import annotations

import dataclasses
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from corraoi.engine.block import FIELDS, NONE_FIELDS, RunConfig, SlotBlock
from corraoi.engine.simulation import simulate, simulate_run
from corraoi.engine.slot_record import (
    GPU_CAPTURE_PER_ARM,
    GPU_CAPTURE_ROW,
    NAMES,
    SLOT_RECORD,
    markdown_table,
    record_for,
)
from corraoi.errors import CorraoiWarning, LogError, PolicyRuntimeError
from corraoi.face.resolve import policies
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import Choice, Policy, builtins, make_policy
from corraoi.recorder.slotlog.encode import BlockEncoder
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.recorder.vocab import SLOT_TOPIC

ROOT = Path(__file__).parent.parent
#: A slot log written by corraoi before the score (commit 2347ea6): aoi-aware-cucb on I1,
#: seed 5, 1200 slots. Never regenerated: it is the old format.
BEFORE = Path(__file__).parent / "golden" / "before-score.mcap"
NEW = ("forced", "override_threshold", "score")


def _wide() -> Instance:
    rng = np.random.default_rng(7)
    p = rng.dirichlet(np.ones(12))
    Y = (rng.random((6, 12)) < 0.35).astype(np.int64)
    Y[2, int(np.argmax(p))] = 1
    return Instance("record-wide", p, Y)


@pytest.mark.parametrize("name", builtins())
def test_the_arm_played_has_the_highest_score_on_every_slot_chosen_by_it(name):
    spec = make_policy(name)
    cls = builtins()[name]
    for inst in (load_instance("I1"), _wide()):
        blk = next(simulate(inst, spec, [3, 4, 5], 1500, block=1500))
        assert blk.score is not None and blk.forced is not None
        assert blk.score.dtype == np.float32 and blk.score.shape == blk.mu_hat.shape
        chosen = ~blk.forced & ~blk.override
        assert chosen.sum() > 100  # the property is not empty
        runs, slots = np.nonzero(chosen)
        score = blk.score[runs, slots]
        cand = blk.candidates[runs, slots]
        # a number for every candidate, NaN for every other arm
        assert np.array_equal(np.isnan(score), ~cand)
        played = score[np.arange(len(runs)), blk.arm[runs, slots]]
        assert np.array_equal(played, np.nanmax(score, axis=1))
        # a slot not chosen by the score has none
        assert np.isnan(blk.score[~chosen]).all()
        # forced: the first pull of every arm for the UCB family, never for plain TS
        if cls.forced is None:
            assert not blk.forced.any()
        else:
            assert blk.forced.any()
        if cls.aoi_aware:
            before = np.concatenate([np.zeros((3, 1, inst.K)), blk.mu_hat[:, :-1]], axis=1)
            top = before.max(axis=2)
            with np.errstate(divide="ignore"):
                want = np.where(top > 0, 1.0 / top, np.inf).astype(np.float32)
            assert blk.override_threshold is not None
            assert np.array_equal(blk.override_threshold, want)
            assert blk.override.any()
            # the rule acts when the age before the slot exceeds the threshold
            age = np.concatenate([np.ones((3, 1)), blk.aoi[:, :-1]], axis=1)
            over = blk.override
            thr = blk.override_threshold.astype(np.float64)
            assert (age[over] >= thr[over] * (1 - 1e-6)).all()
            assert (age[~over] <= thr[~over] * (1 + 1e-6)).all()
        else:
            assert blk.override_threshold is None


class _ScoredUCB(Policy):
    """UCB in plain Python, saying what it maximised."""

    name = "scored-ucb-test"

    def select(self, t, state):
        n = state.pulls
        unpulled = n == 0
        with np.errstate(divide="ignore", invalid="ignore"):
            index = state.mu_hat + np.sqrt(2 * np.log(max(t, 2)) / n)
        index = np.where(unpulled, np.inf, index)
        arms = state.rng.argmax(index)
        return Choice(arms, scores=index)


class _Bare(_ScoredUCB):
    name = "bare-ucb-test"

    def select(self, t, state):
        return super().select(t, state).arms


class _Triple(_ScoredUCB):
    name = "triple-test"

    def select(self, t, state):
        c = super().select(t, state)
        return (c.arms, None, c.scores)


def test_a_plain_python_policy_gives_its_scores_through_choice():
    inst = load_instance("I1")
    blk = next(simulate(inst, policies(_ScoredUCB)[0], [1, 2], 500, block=500))
    assert blk.score is not None and blk.forced is not None and blk.override_threshold is None
    rows = np.arange(2)[:, None], np.arange(500)[None, :]
    played = blk.score[rows[0], rows[1], blk.arm]
    assert np.array_equal(played, blk.score.max(axis=2))  # +inf for the unpulled arms
    assert not blk.forced.any()
    bare = next(simulate(inst, policies(_Bare)[0], [1, 2], 500, block=500))
    assert bare.score is None and bare.forced is None
    assert np.array_equal(bare.arm, blk.arm)  # the same decisions, with or without scores
    with pytest.raises(PolicyRuntimeError, match="tuple of 3"):
        next(simulate(inst, policies(_Triple)[0], [1], 10))


def test_the_log_round_trips_the_new_fields_with_infinity_and_nan(tmp_path):
    config = RunConfig(load_instance("I1"), make_policy("aoi-aware-cts"), 2, 2500)
    ref = SlotBlock.concat(list(simulate_run(config.instance, config.policy, 2, 2500)))
    ref.score[7, :] = [np.inf, -np.inf, np.nan, 0.5]  # as a plug-in's hook may give
    ref.candidates[7, :] = [True, True, False, True]
    path = tmp_path / "run.mcap"
    with McapSink(path, config, fsync=False) as sink:
        sink.write(ref)
    got = open_log(path).read_all()
    # every field a single source's run may hold (not `collided`, a field of several sources)
    assert got.fields() == ref.fields() == tuple(f.name for f in record_for(1))
    assert "collided" in NAMES and "collided" not in got.fields()
    assert got.equals(ref)
    msg = json.loads(_payloads(path)[7])
    assert msg["score"] == [3.4028235e38, -3.4028235e38, 0.5]  # +-infinity, and no NaN
    assert list(msg)[-3:] == list(NEW)


#: the fields a single source's block holds as None when absent (not `collided`, a field of
#: several sources only)
_SINGLE_NONE = tuple(f for f in NONE_FIELDS if f in {g.name for g in record_for(1)})


def _payloads(path: Path) -> list[bytes]:
    with open(path, "rb") as f:
        return [m.data for _, _, m in make_reader(f).iter_messages(topics=[SLOT_TOPIC])]


def test_a_log_written_before_the_score_reads_and_its_slots_equal_todays(tmp_path):
    old = open_log(BEFORE)
    assert old.status == "complete" and old.n_slots == 1200
    # (not `collided`: a single source's run never has it)
    assert old.absent == _SINGLE_NONE
    blocks = list(old.blocks())
    assert all(b.fields() == FIELDS for b in blocks)
    # today's engine and encoder: the same messages, field by field, but the new fields
    cfg = old.config
    new = tmp_path / "new.mcap"
    with McapSink(new, RunConfig(cfg.instance, cfg.policy, cfg.seed, cfg.horizon),
                  fsync=False) as sink:  # fmt: skip
        for b in simulate_run(cfg.instance, cfg.policy, cfg.seed, cfg.horizon):
            sink.write(b)
    before, today = _payloads(BEFORE), _payloads(new)
    assert len(before) == len(today) == 1200
    for a, b in zip(before, today, strict=True):
        mine = json.loads(b)
        assert set(mine) - set(json.loads(a)) == set(NEW)
        for key in NEW:
            del mine[key]
        assert json.dumps(mine, separators=(",", ":")).encode() == a  # byte for byte
    from corraoi.viewer.diffs import diff

    report = diff(BEFORE, new)
    assert report.same_slots
    assert {n for n, f in report.fields.items() if not f.identical} == set(NEW)
    assert any("only one of the runs logs forced, override_threshold, score" in w
               for w in report.warnings)  # fmt: skip


def test_a_log_before_the_score_loads_as_a_table_without_its_columns():
    pytest.importorskip("pandas")
    import corraoi

    df = corraoi.load(BEFORE).slots
    assert len(df) == 1200
    assert not any(c.startswith("score") or c == "forced" for c in df.columns)
    assert "mu_hat_4" in df.columns and "override_threshold" not in df.columns


def _rewritten(tmp_path: Path, edit) -> Path:
    """A copy of a fresh log with every slot message rewritten by ``edit``."""
    config = RunConfig(load_instance("I1"), make_policy("cucb"), 0, 1500)

    class Editing(BlockEncoder):
        def encode(self, b):  # type: ignore[override]
            return [edit(json.loads(m)) for m in super().encode(b)]

        def encode_framed(self, b, room):  # type: ignore[override]
            return bytearray(b"".join(room + m for m in self.encode(b)))  # what McapSink asks

    path = tmp_path / "edited.mcap"
    with McapSink(path, config, fsync=False) as sink:
        sink._encoder = Editing(config.instance.K)
        for block in simulate_run(config.instance, config.policy, 0, 1500):
            sink.write(block)
    return path


def test_a_field_from_a_newer_corraoi_is_kept_and_named_once(tmp_path):
    def add(msg):
        msg["novelty"] = msg["t"] * 2
        return json.dumps(msg, separators=(",", ":")).encode()

    path = _rewritten(tmp_path, add)
    log = open_log(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        blocks = list(log.blocks())
    named = [w for w in caught if issubclass(w.category, CorraoiWarning)]
    assert len(named) == 1 and "novelty" in str(named[0].message)
    got = SlotBlock.concat(blocks)
    assert np.array_equal(got.extra["novelty"], 2 * got.t)
    pytest.importorskip("pandas")
    from corraoi.recorder.slotlog.frames import RunData

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CorraoiWarning)
        df = RunData(path).slots
    assert np.array_equal(df["novelty"].to_numpy(), 2 * df["t"].to_numpy())
    assert "score_1" in df.columns


def test_a_log_missing_a_required_field_is_one_error_naming_it(tmp_path):
    def drop(msg):
        del msg["regret"]
        return json.dumps(msg, separators=(",", ":")).encode()

    path = _rewritten(tmp_path, drop)
    with pytest.raises(LogError) as info:
        open_log(path).read_all()
    text = str(info.value)
    assert "\n" not in text and "lacks regret, a required field" in text


def test_docs_field_table_is_the_declarations():
    doc = (ROOT / "docs" / "log-format.md").read_text()
    begin, end = "<!-- slot-record: begin -->\n", "<!-- slot-record: end -->"
    assert begin in doc and end in doc
    assert doc.split(begin, 1)[1].split(end, 1)[0] == markdown_table()
    for f in SLOT_RECORD:
        assert f"| `{f.name}` |" in markdown_table()


def test_the_gpu_capture_row_is_the_declared_one():
    source = (ROOT / "corraoi" / "gpu" / "kernel.cu").read_text()
    rows = re.findall(r"row\[(\d+)( \+ k)?\] = [^;]+;\s*// (\w+)", source)
    assert tuple(name for _, _, name in rows) == GPU_CAPTURE_ROW
    assert tuple(name for _, per_arm, name in rows if per_arm) == GPU_CAPTURE_PER_ARM
    from corraoi.gpu.runner import capture_columns, capture_width

    for K in (1, 4, 64):  # each value at its place in the kernel's row, one a slot and arm
        cols = capture_columns(K)
        assert [cols[name].start for _, _, name in rows] == [int(i) for i, _, _ in rows]
        assert all(cols[name].stop - cols[name].start == (K if per_arm else 1)
                   for _, per_arm, name in rows)  # fmt: skip
        assert capture_width(K) == len(GPU_CAPTURE_ROW) - 1 + K
    # the capture module (CAI_CAPTURE=1) captures every field, a sweep's up to the candidates
    assert GPU_CAPTURE_ROW[-1] == "score"  # the K words last: CAI_CAPW is that arithmetic
    ours = GPU_CAPTURE_ROW.index("forced")
    assert (f"#if CAI_CAPTURE\n#define CAI_CAPW ({ours + 2} + KARMS)\n" in source
            and f"#else\n#define CAI_CAPW {ours}\n#endif" in source)  # fmt: skip
    # every captured value is a field, or what one derives from (the estimator from aoisum)
    assert set(GPU_CAPTURE_ROW) - set(NAMES) == {"aoisum"}
    assert {"score", "forced", "override_threshold"} <= set(GPU_CAPTURE_ROW)


def test_a_log_before_the_score_replays_without_the_why_entities(tmp_path):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from corraoi.viewer.replay import replay

    out = tmp_path / "old.rrd"
    replay(BEFORE, rrd_path=out)
    entities = {chunk.entity_path for chunk in RrdReader(out).stream()}
    assert any(e.endswith("/mu_hat") for e in entities)
    assert not any("/why/" in e for e in entities)


def test_the_foxglove_layout_plots_declared_paths_and_the_score():
    layout = json.loads((ROOT / "docs" / "foxglove-layout.json").read_text())
    used = {
        p["value"]
        for panel in layout["configById"].values()
        for p in panel.get("paths", [])
        if p["value"].startswith(SLOT_TOPIC + ".")
    }
    declared = {f.foxglove for f in SLOT_RECORD if f.foxglove}
    assert used <= declared, used - declared
    assert {"/corraoi/slot.score[:]", "/corraoi/slot.forced"} <= used


def test_the_candidates_scores_read_the_same_whether_or_not_their_arms_hold_over_a_block():
    """The encoder writes a block whose scores are NaN at the same arms in every slot column
    by column, any other block through the whole table's text: the messages are the same."""
    b = next(simulate_run(load_instance("I1"), make_policy("cucb"), 0, 300))
    score = np.linspace(-3.5, 7.25, 300 * 4, dtype=np.float32).reshape(300, 4)
    score[:, [1, 3]] = np.nan  # arms 2 and 4 outside the candidate set throughout
    score[7, 0] = np.inf  # written as +FLOAT32_MAX
    mixed = score.copy()
    mixed[0] = np.nan  # a slot not scored: the block's arms no longer hold
    encoder = BlockEncoder(4)
    held = [json.loads(m) for m in encoder.encode(dataclasses.replace(b, score=score))]
    other = [json.loads(m) for m in encoder.encode(dataclasses.replace(b, score=mixed))]
    assert other[0]["score"] == [] and held[1:] == other[1:]
    top = float(np.finfo(np.float32).max)
    for i in range(300):  # the finite scores of the row, as float32
        want = [min(v, top) for v in score[i].tolist() if v == v]
        assert [float(np.float32(v)) for v in held[i]["score"]] == want
    nothing = np.full((300, 4), np.nan, dtype=np.float32)
    none = encoder.encode(dataclasses.replace(b, score=nothing))
    assert all(json.loads(m)["score"] == [] for m in none)


def test_the_score_is_an_option_on_by_default_up_to_64_arms(tmp_path):
    from corraoi.face.recording import record

    inst = load_instance("I1")
    assert RunConfig(inst, make_policy("ucb"), 0, 10).score
    off = RunConfig(inst, make_policy("ucb"), 0, 10, score=False)
    assert off.to_dict()["score"] is False and RunConfig.from_dict(off.to_dict()) == off
    assert "score" not in RunConfig(inst, make_policy("ucb"), 0, 10).to_dict()  # as before
    rng = np.random.default_rng(1)
    wide = Instance("wide-65", np.full(65, 1 / 65), (rng.random((65, 65)) < 0.3).astype(int))
    assert not RunConfig(wide, make_policy("ucb"), 0, 10).score
    run = record("ucb", inst, horizon=300, path=tmp_path / "off.mcap", rrd=False, score=False)
    assert open_log(run.path).absent == _SINGLE_NONE  # ucb: no threshold either


def test_every_declared_rerun_entity_is_one_the_recording_has():
    from corraoi.recorder.rerun.names import ENTITIES, WHY

    for f in SLOT_RECORD:
        for part in filter(None, (p.strip() for p in f.entity.split(","))):
            assert part.removesuffix("/<k>") in ENTITIES + WHY, (f.name, part)
    # the fields a run may lack are the why/ ones and those of several sources (collided)
    several = {f.name for f in SLOT_RECORD if f.sources_only}
    assert several == {"collided"}
    why = {f.name for f in SLOT_RECORD if f.entity.startswith("why/")}
    assert why == set(NONE_FIELDS) - several
