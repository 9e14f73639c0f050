"""corraoi.viewer.diff and the run summary: slot-by-slot comparison of recorded runs (logs only)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from corraoi.engine.block import RunConfig, SlotBlock
from corraoi.engine.summary import summarize_blocks
from corraoi.errors import UsageError
from corraoi.model.instance import Instance
from corraoi.policies import make_policy
from corraoi.viewer import diff
from corraoi.viewer.diffs import DIFF_FIELDS, parse_fields


def _write(path, config: RunConfig, block: SlotBlock):
    from corraoi.recorder.slotlog.sink import McapSink

    with McapSink(path, config, fsync=False) as sink:
        for start in range(0, len(block), 1000):
            sink.write(block.slice(start, start + 1000))
    return path


def test_the_same_seed_twice_is_identical(record_mcap):
    a, _, _ = record_mcap("cts", seed=4, horizon=2500, name="a.mcap")
    b, _, _ = record_mcap("cts", seed=4, horizon=2500, name="b.mcap")
    report = diff(a, b)
    assert report.identical
    assert report.same_config and report.same_slots
    assert set(report.fields) == set(DIFF_FIELDS)
    for f in report.fields.values():
        assert f.compared == 2500 and f.slots_differing == 0 and f.first_slot is None
    assert report.first_divergence is None
    assert report.verdict().startswith("identical: 2500 slots")
    report.assert_identical()  # does not raise


def test_ucb_against_cucb_same_x_path_first_divergence_in_arm(record_mcap):
    a, _, ra = record_mcap("ucb", seed=2, horizon=3000)
    b, _, rb = record_mcap("cucb", seed=2, horizon=3000)
    report = diff(a, b)
    assert not report.identical
    assert [(d.key, d.a, d.b) for d in report.config] == [("policy.name", "ucb", "cucb")]
    # common random numbers: the hidden path is the same, so x never differs
    assert report["x"].identical and report["x"].compared == 3000
    assert report["oracle_aoi"].identical
    # the arm column: first divergence and count, checked against the engine's own output
    differ = np.flatnonzero(ra.arm != rb.arm)
    assert differ.size > 0
    arm = report["arm"]
    assert arm.first_slot == int(differ[0]) + 1
    assert arm.slots_differing == differ.size
    assert arm.a_value == int(ra.arm[differ[0]]) + 1  # numbered from 1
    assert arm.b_value == int(rb.arm[differ[0]]) + 1
    cand = np.flatnonzero((ra.candidates != rb.candidates).any(axis=1))
    assert report["candidates"].first_slot == int(cand[0]) + 1
    assert report["candidates"].b_value == [
        int(k) + 1 for k in np.flatnonzero(rb.candidates[cand[0]])
    ]
    slot, field = report.first_divergence
    assert slot == min(int(differ[0]), int(cand[0])) + 1
    finals = {name: (va, vb, d) for name, va, vb, d in report.finals()}
    assert finals["regret"] == (int(ra.regret[-1]), int(rb.regret[-1]),
                                int(rb.regret[-1] - ra.regret[-1]))  # fmt: skip
    assert finals["pulls arm 2"][0] == int(ra.pulls[-1, 1])
    with pytest.raises(AssertionError) as err:
        report.assert_identical()
    text = str(err.value)
    assert "policy.name: ucb != cucb" in text
    assert f"first divergence at slot {slot} ({field})" in text
    assert text.splitlines()[-1] == report.verdict()
    # the per-field table's columns line up for every field, override_threshold included
    lines = str(report).splitlines()
    top = lines.index("per field:") + 1
    rows = lines[top:lines.index("final figures:")]
    assert [r.split()[0] for r in rows[1:]] == list(report.fields)
    assert "override_threshold" in report.fields
    ends = {r.index(" of 3000") + 8 for r in rows[1:]}  # "N of 3000" right-aligned
    assert ends == {rows[0].index("slots differing") + len("slots differing")}


def test_different_seeds_differ_in_x_from_the_first_differing_state(record_mcap):
    a, _, ra = record_mcap("ucb", seed=0, horizon=1200)
    b, _, rb = record_mcap("ucb", seed=1, horizon=1200)
    report = diff(a, b, fields=["x"])
    assert list(report.fields) == ["x"]
    differ = np.flatnonzero(ra.x != rb.x)
    assert report["x"].first_slot == int(differ[0]) + 1
    assert report["x"].slots_differing == differ.size
    assert [d.key for d in report.config] == ["seed"]


def test_a_float_perturbation_is_found_and_atol_forgives_it(tmp_path, make_config, engine):
    config = make_config("ts-gauss", horizon=2000)
    block = SlotBlock.concat(engine(config))
    a = _write(tmp_path / "a.mcap", config, block)
    mu = block.mu_hat.copy()
    mu[1733, 2] += 1e-9
    b = _write(tmp_path / "b.mcap", config, replace(block, mu_hat=mu))
    exact = diff(a, b)
    assert not exact.identical
    assert exact.differing_fields == ["mu_hat"]
    assert exact["mu_hat"].first_slot == 1734 and exact["mu_hat"].slots_differing == 1
    assert diff(a, b, atol=1e-6).identical
    assert not diff(a, b, atol=1e-12).identical


def test_an_integer_change_is_not_forgiven_by_atol(tmp_path, make_config, engine):
    config = make_config("ucb", horizon=1500)
    block = SlotBlock.concat(engine(config))
    a = _write(tmp_path / "a.mcap", config, block)
    aoi = block.aoi.copy()
    aoi[999] += 1
    b = _write(tmp_path / "b.mcap", config, replace(block, aoi=aoi))
    report = diff(a, b, atol=10.0)
    assert report.differing_fields == ["aoi"]
    assert report["aoi"].first_slot == 1000
    assert (report["aoi"].a_value, report["aoi"].b_value) == (int(aoi[999]) - 1, int(aoi[999]))


def test_a_cut_short_log_against_the_full_one(tmp_path, record_mcap):
    full, config, ref = record_mcap("cucb", horizon=3000)
    from corraoi.recorder.slotlog.sink import McapSink

    with McapSink(tmp_path / "short.mcap", config, fsync=False) as sink:
        for start in (0, 1000):
            sink.write(ref.slice(start, start + 1000))
    report = diff(full, tmp_path / "short.mcap")
    assert not report.identical and not report.same_slots
    assert (report.a_slots, report.b_slots) == (3000, 2000)
    assert all(f.identical and f.compared == 2000 for f in report.fields.values())
    assert report.b_status == "interrupted"
    assert "slot counts differ (3000 vs 2000)" in report.verdict()
    assert report.a_summary.regret == int(ref.regret[-1])
    assert report.b_summary.regret == int(ref.regret[1999])


def test_runs_with_different_numbers_of_arms(tmp_path, record_mcap):
    a, _, _ = record_mcap("ucb", horizon=1000)
    three = Instance("three", np.array([0.5, 0.5]), np.array([[1, 0], [0, 1], [1, 1]]))
    config = RunConfig(three, make_policy("ucb"), 0, 1000)
    from corraoi.engine.simulation import simulate_run

    block = SlotBlock.concat(list(simulate_run(three, config.policy, 0, 1000)))
    b = _write(tmp_path / "three.mcap", config, block)
    report = diff(a, b)
    assert not report.identical
    assert not report["mu_hat"].comparable and report["mu_hat"].slots_differing == 1000
    assert report["aoi"].comparable
    assert any("different numbers of arms" in w for w in report.warnings)
    assert "instance.name" in [d.key for d in report.config]
    rows = {name: (va, vb) for name, va, vb, _ in report.finals()}
    assert rows["pulls arm 4"] == (report.a_summary.pulls[3], None)
    json.dumps(report.to_dict())


def test_version_difference_is_a_note_not_a_difference(tmp_path, make_config, engine):
    config = make_config("ucb", horizon=1000)
    block = SlotBlock.concat(engine(config))
    a = _write(tmp_path / "a.mcap", config, block)
    b = _write(tmp_path / "b.mcap", replace(config, version="0.0.1"), block)
    report = diff(a, b)
    assert report.identical
    assert [(n.key, n.b) for n in report.notes] == [("version", "0.0.1")]
    assert "note: version differs" in report.message()


def test_the_json_report(record_mcap):
    a, _, ra = record_mcap("ucb", seed=3, horizon=1000)
    b, _, _ = record_mcap("ts", seed=3, horizon=1000)
    data = json.loads(json.dumps(diff(a, b).to_dict()))
    assert data["identical"] is False
    assert data["fields"]["x"]["identical"] is True
    assert data["fields"]["arm"]["first_slot"] >= 1
    assert data["config"] == [
        {"key": "policy.name", "a": "ucb", "b": "ts"},
        {"key": "policy.params.c", "a": 2.0, "b": None},  # ts has no parameter c
    ]
    assert data["a"]["summary"]["pulls"] == [int(v) for v in ra.pulls[-1]]
    assert data["finals"]["regret"]["a"] == int(ra.regret[-1])


def test_field_names_are_checked():
    assert parse_fields(None) == DIFF_FIELDS
    assert parse_fields(["x,arm", "arm", "regret"]) == ("x", "arm", "regret")
    with pytest.raises(UsageError, match="unknown field 'bogus'"):
        parse_fields(["x,bogus"])
    with pytest.raises(UsageError, match="no field given"):
        parse_fields([","])


def test_bad_atol_is_refused(record_mcap):
    a, _, _ = record_mcap("ucb", horizon=1000)
    with pytest.raises(UsageError, match="atol"):
        diff(a, a, atol=-1.0)
    with pytest.raises(UsageError, match="atol"):
        diff(a, a, atol=float("nan"))


def test_summary_figures_match_the_engine(make_config, engine):
    config = make_config("aoi-aware-cts", horizon=4000, seed=7)
    blocks = engine(config)
    ref = SlotBlock.concat(blocks)
    s = summarize_blocks(config, blocks)
    best = 1  # I1: arm 2
    off = np.flatnonzero(ref.arm != best)
    assert s.best_arm == best
    assert s.slots == 4000
    assert s.regret == int(ref.regret[-1]) and s.estimator == float(ref.estimator[-1])
    assert s.pulls == tuple(int(v) for v in ref.pulls[-1])
    assert s.best_share == pytest.approx(np.mean(ref.arm == best))
    assert s.overrides == int(ref.override.sum()) > 0
    assert s.settled_at == (int(off[-1]) + 2 if off.size else 1)
    assert s.settled_at is not None and ref.arm[s.settled_at - 1 :].tolist() == [best] * (
        4000 - s.settled_at + 1
    )
    assert s.to_dict()["best_arm"] == 2


def test_summary_of_a_run_that_ends_off_the_best_arm(make_config, engine):
    config = make_config("ucb", horizon=1000)
    block = SlotBlock.concat(engine(config))
    arm = block.arm.copy()
    arm[-1] = 0
    s = summarize_blocks(config, [replace(block, arm=arm)])
    assert s.settled_at is None
    empty = summarize_blocks(config, [])
    assert empty.slots == 0 and empty.regret is None and empty.settled_at is None
