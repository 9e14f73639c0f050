"""Many sources sharing the channels (issue 43): the run's configuration and block."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from corraoi.engine.block import RunConfig, SlotBlock, SourcesBlock
from corraoi.engine.simulation import Simulation, simulate_run
from corraoi.engine.slot_record import SHARED, record_for
from corraoi.engine.sources import (
    SourcesSimulation,
    oracle_channels,
    simulate_run_sources,
    simulate_runs,
    simulate_sources,
    source_blocks,
)
from corraoi.errors import ConfigError, PolicyError, PolicyRuntimeError
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import builtins, make_policy, parse_policy_names

PLUGINS = Path(__file__).parent / "plugins"


@pytest.mark.parametrize("bad", [0, 5, -1, 2.0, "2", True, None])
def test_sources_outside_1_to_K_is_one_error_naming_it(bad):
    expected = r"sources .*expected an integer from 1 to the number of arms, 4"
    with pytest.raises(ConfigError, match=expected):
        RunConfig(load_instance("I1"), make_policy("ucb"), 0, 100, sources=bad)


def test_a_single_source_config_is_written_as_before_and_several_round_trip():
    one = RunConfig(load_instance("I1"), make_policy("ucb"), 3, 100)
    assert "sources" not in one.to_dict() and one.label == "ucb-I1-s3"
    three = RunConfig(load_instance("I1"), make_policy("rhorand-ucb"), 3, 100, sources=3)
    assert three.to_dict()["sources"] == 3 and three.label == "rhorand-ucb-I1-m3-s3"
    assert RunConfig.from_dict(three.to_dict()) == three
    assert RunConfig.from_dict(one.to_dict()).sources == 1


def test_a_single_sources_record_has_no_field_of_several_sources():
    assert [f.name for f in record_for(2) if f not in record_for(1)] == ["collided"]
    assert SHARED == ("t", "x")


def test_a_sources_block_joins_and_slices_source_by_source():
    inst = load_instance("I1")
    a, b = (SlotBlock.concat(list(simulate_run(inst, make_policy(p), 1, 300)))
            for p in ("ucb", "ts"))  # fmt: skip
    whole = SourcesBlock((a, b))
    assert whole.M == 2 and len(whole) == 300 and np.array_equal(whole.x, a.x)
    parts = [whole.slice(0, 100), whole.slice(100, None)]
    assert SourcesBlock.concat(parts).equals(whole)
    assert not SourcesBlock.concat(parts).equals(SourcesBlock((b, a)))
    with pytest.raises(ValueError, match="two sources or more"):
        SourcesBlock((a,))


# ---------------------------------------------------------------- the engine of many sources

BASES = ("ucb", "cucb", "aoi-aware-ucb", "aoi-aware-cucb", "ts", "cts", "aoi-aware-ts",
         "aoi-aware-cts")  # fmt: skip


def _bernoulli(means, name="bern"):
    """Independent Bernoulli channels: the states are the arms' outcome vectors."""
    K = len(means)
    states = np.arange(1 << K)
    Y = ((states[None, :] >> np.arange(K)[:, None]) & 1).astype(np.int64)
    p = np.prod(np.where(Y == 1, np.asarray(means)[:, None], 1 - np.asarray(means)[:, None]),
                axis=0)  # fmt: skip
    return Instance(name, p, Y)


@pytest.mark.parametrize("base", BASES)
def test_one_source_of_every_rhorand_form_is_its_base_policy(base):
    for inst in (load_instance("I1"), load_instance("I2")):
        one = SlotBlock.concat([b[0] for b in source_blocks(
            inst, make_policy(f"rhorand-{base}"), 7, 700, 1, block=300)])  # fmt: skip
        ref = SlotBlock.concat(list(simulate_run(inst, make_policy(base), 7, 700)))
        for f in ("x", "arm", "success", "aoi", "oracle_aoi", "regret", "score", "forced",
                  "mu_hat", "pulls", "candidates", "override", "estimator"):  # fmt: skip
            assert np.array_equal(one.column(f), ref.column(f), equal_nan=f == "score"), f
        assert one.equals(ref)
        totals = simulate_sources(inst, make_policy(f"rhorand-{base}"), [7, 8], 700, 1)
        sim = Simulation(inst, make_policy(base), [7, 8], 700)
        sim.advance_to(700)
        assert np.array_equal(totals.regret[:, 0], sim.regret)
        assert np.array_equal(totals.collisions, np.zeros((2, 1)))


def test_the_collision_rule_and_the_oracle_on_hand_checked_slots():
    # two channels always ON: each source's oracle age is 1 on every slot. UCB's first
    # round: each source plays both channels once, in an order of its own; where the two
    # orders agree they collide on both slots (ages 2, 3: regret 1 + 2), else neither
    inst = Instance("on", np.array([1.0]), np.array([[1], [1]]))
    for seed in range(6):
        blk = next(simulate_run_sources(inst, make_policy("rhorand-ucb"), seed, 200, 2,
                                        block=200))  # fmt: skip
        s1, s2 = blk.sources
        same = s1.arm[0] == s2.arm[0]
        for s in (s1, s2):
            assert sorted(s.arm[:2].tolist()) == [0, 1] and (s.oracle_aoi == 1).all()
            assert s.collided[:2].tolist() == [same, same]
            assert s.aoi[:2].tolist() == ([2, 3] if same else [1, 1])
            assert s.regret[1] == (3 if same else 0)
    both = s1.arm == s2.arm
    for s in (s1, s2):
        assert np.array_equal(s.collided, both)
        assert np.array_equal(s.success, ~both)  # every channel is ON: only collisions fail
        age = np.ones(len(s), dtype=np.int64)
        for t in range(len(s)):
            age[t] = 1 if s.success[t] else (age[t - 1] if t else 1) + 1
        assert np.array_equal(s.aoi, age)
        assert np.array_equal(s.regret, np.cumsum(s.aoi - s.oracle_aoi))
    assert not both[-50:].any()  # the ranks found distinct channels
    # the oracle: source m gets the m-th best mean, ties by lowest index
    assert oracle_channels(np.array([0.5, 1.0, 0.5, 0.7]), 3).tolist() == [1, 3, 0]
    inst = _bernoulli([0.3, 0.9, 0.3, 0.6])
    blk = next(simulate_run_sources(inst, make_policy("mctopm-ts"), 2, 300, 3, block=300))
    Y = inst.Y
    for m, channel in enumerate((1, 3, 0)):
        src = blk.sources[m]
        age = np.ones(len(src), dtype=np.int64)
        for t in range(len(src)):
            age[t] = 1 if Y[channel, blk.x[t]] else (age[t - 1] if t else 1) + 1
        assert np.array_equal(src.oracle_aoi, age)
        assert np.array_equal(src.success, (Y[src.arm, blk.x] == 1) & ~src.collided)


@pytest.mark.parametrize("rule", ["rhorand", "mctopm", "centralized", "chairs"])
@pytest.mark.parametrize("base", ["ucb", "ts", "cucb"])
def test_each_family_settles_on_an_orthogonal_assignment(rule, base):
    inst = _bernoulli([0.9, 0.1, 0.75, 0.2], "easy")
    blk = SourcesBlock.concat(list(simulate_run_sources(
        inst, make_policy(f"{rule}-{base}"), 11, 6000, 2, block=2000)))  # fmt: skip
    tail = blk.slice(4800, None)
    a, b = (s.arm for s in tail.sources)
    assert (a != b).mean() > 0.9  # collision-free
    for s in tail.sources:
        assert np.isin(s.arm, [0, 2]).mean() > 0.85  # on the top-2 channels
        assert s.collided.mean() < 0.1
    totals = simulate_sources(inst, make_policy(f"{rule}-{base}"), [11], 6000, 2)
    assert np.array_equal(totals.regret[0], [s.regret[-1] for s in blk.sources])
    assert totals.collisions[0].tolist() == [int(s.collided.sum()) for s in blk.sources]
    if rule == "centralized":
        assert totals.collisions.sum() == 0


@pytest.mark.parametrize("bad", [0, 5, 2.0, "2", True, None])
def test_a_source_count_outside_1_to_K_is_one_error(bad):
    with pytest.raises(ConfigError, match=r"^sources .*expected an integer from 1 to the number "
                       r"of arms, 4$"):  # fmt: skip
        simulate_sources(load_instance("I1"), make_policy("rhorand-ucb"), [1], 10, bad)


def test_a_single_source_policy_with_several_sources_names_its_multi_source_forms():
    want = (r"^policy cucb is single-source; with sources 2 use one of its multi-source "
            r"forms: rhorand-cucb, mctopm-cucb, centralized-cucb, chairs-cucb$")  # fmt: skip
    with pytest.raises(ConfigError, match=want):
        RunConfig(load_instance("I1"), make_policy("cucb"), 0, 100, sources=2)
    with pytest.raises(ConfigError, match=want):
        simulate_sources(load_instance("I1"), make_policy("cucb"), [1], 10, 2)
    with pytest.raises(ConfigError, match=r"^policy sw-ucb is single-source; .* no multi-source"):
        RunConfig(load_instance("I1"), make_policy("sw-ucb"), 0, 100, sources=3)
    # a multi-source form runs one source as its base policy
    assert RunConfig(load_instance("I1"), make_policy("rhorand-ucb"), 0, 100).sources == 1
    with pytest.raises(ConfigError, match="simulate_run"):
        next(simulate_run_sources(load_instance("I1"), make_policy("rhorand-ucb"), 0, 10, 1))
    plain = make_policy(f"{PLUGINS / 'eps_greedy.py'}:EpsilonGreedy")
    with pytest.raises(ConfigError, match=r'^policy eps-greedy is single-source; with sources '
                       r'2 a plain-Python policy declares multi_source = "own" '):  # fmt: skip
        simulate_sources(load_instance("I1"), plain, [1], 10, 2)


def test_the_multi_source_forms_are_registered_but_not_single_source_builtins():
    assert "rhorand-ucb" not in builtins() and "rhorand-ucb" in builtins(multi=True)
    spec = make_policy("mctopm-aoi-aware-cts")
    assert spec.builtin and spec.resolve().multi_source == "mctopm"
    assert spec.resolve().aoi_aware and spec.resolve().correlated
    assert "centralized-ts" not in parse_policy_names(["all"])


PLUGIN = """
from corraoi.policies import CompiledPolicy, Param


class ManyFar(CompiledPolicy):
    name = "many-far"
    multi_source = "rhorand"
    params = {"at": Param(7.0, "slot from which forced returns arm 10^6", low=1.0)}
    forced = "bad_compiled:far_forced"
    score = "corraoi.policies.hooks:score_none"


class Bogus(CompiledPolicy):
    name = "bogus-rule"
    multi_source = "round-robin"
    score = "corraoi.policies.hooks:score_none"
"""


def test_a_multi_source_plugin_runs_and_its_arm_out_of_range_is_one_line(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))
    (tmp_path / "many.py").write_text(PLUGIN)
    spec = make_policy(f"{tmp_path / 'many.py'}:ManyFar", at=40)
    sim = SourcesSimulation(load_instance("I2"), spec, [3, 4], 300, 3)
    assert sim.advance(39) is not None  # a plug-in declaring a rule runs with 3 sources
    with pytest.raises(PolicyRuntimeError, match=r"^policy many-far, slot 40: its forced hook "
                       r"returned arm 1000000 for run 0 \(seed 3\); expected 0\.\.3"):  # fmt: skip
        sim.advance(10)
    bogus = make_policy(f"{tmp_path / 'many.py'}:Bogus")
    with pytest.raises(PolicyError, match=r"^policy bogus-rule: multi_source 'round-robin'; "
                       "expected one of rhorand, mctopm, centralized"):  # fmt: skip
        simulate_sources(load_instance("I2"), bogus, [1], 10, 2)


def test_a_run_of_several_sources_has_the_single_runs_path_and_the_fields_of_its_record():
    inst = load_instance("I2")
    one = SlotBlock.concat(list(simulate_run(inst, make_policy("ts"), 5, 400)))
    for name, aware in (("rhorand-ts", False), ("centralized-aoi-aware-cucb", True)):
        blk = SourcesBlock.concat(list(simulate_run_sources(inst, make_policy(name), 5, 400, 3,
                                                            block=150)))  # fmt: skip
        assert blk.M == 3 and np.array_equal(blk.x, one.x)  # the seed's hidden path
        for s in blk.sources:
            assert s.fields() == tuple(f.name for f in record_for(3) if f.name in s.fields())
            assert s.collided is not None and s.score is not None and s.forced is not None
            assert (s.override_threshold is not None) == aware
            assert np.array_equal(s.t, np.arange(1, 401)) and np.array_equal(s.x, blk.x)
        # the run's arms per slot: one per source, each in range
        arms = np.stack([s.arm for s in blk.sources])
        assert ((arms >= 0) & (arms < inst.K)).all()
        if name.startswith("centralized"):
            assert (np.sort(arms, axis=0)[1:] != np.sort(arms, axis=0)[:-1]).all()
    solo = next(source_blocks(inst, make_policy("rhorand-ts"), 5, 400, 1, block=400))[0]
    assert solo.collided is None  # a single source's record has no collided field


def test_many_runs_slot_columns_are_each_seeds_recorded_run():
    inst = load_instance("I1")
    runs = list(simulate_runs(inst, "mctopm-ucb", [4, 9], 300, sources=2))
    assert [r.seed for r in runs] == [4, 9]
    for r in runs:
        blk = SourcesBlock.concat(list(simulate_run_sources(inst, make_policy("mctopm-ucb"),
                                                            r.seed, 300, 2)))  # fmt: skip
        assert r.arm.shape == r.collided.shape == r.success.shape == (300, 2)
        for m, s in enumerate(blk.sources):
            assert np.array_equal(r.arm[:, m], s.arm)
            assert np.array_equal(r.collided[:, m], s.collided)
            assert np.array_equal(r.success[:, m], s.success)
    assert not np.array_equal(runs[0].arm, runs[1].arm)


def test_musical_chairs_learns_uniformly_then_sits_for_good_on_its_first_free_channel():
    inst = _bernoulli([0.9, 0.1, 0.75, 0.2, 0.5], "chairs")
    M, t0, T = 3, 120, 3000
    for seed in range(4):
        blk = SourcesBlock.concat(list(simulate_run_sources(
            inst, make_policy("chairs-ucb", t0=t0), seed, T, M, block=1000)))  # fmt: skip
        arms = np.stack([s.arm for s in blk.sources])  # (M, T)
        coll = np.stack([s.collided for s in blk.sources])
        # learning: uniform channels, whatever the index says (the index would play each
        # arm once, then mostly arm 0)
        learn = arms[:, :t0]
        assert all(len(set(a.tolist())) == inst.K for a in learn)
        assert not any(blk.sources[m].forced[:t0].any() for m in range(M))
        for m in range(M):
            after = np.flatnonzero(~coll[m, t0:])
            assert after.size, "never seated"
            sat = t0 + int(after[0])  # the first collision-free slot after learning
            chair = arms[m, sat]
            # unseated until then: each choice one of its M best by its index that slot
            # (UCB's scores, recorded); seated from then on: that channel, for good
            assert (arms[m, sat:] == chair).all()
            score = blk.sources[m].score
            for t in range(t0, sat + 1):
                above = (score[t] > score[t, arms[m, t]]).sum()
                assert above < M, (m, t, score[t], arms[m, t])
        # seated sources on distinct channels: no collision once all sat
        assert not coll[:, -100:].any()
        assert len(set(arms[:, -1].tolist())) == M
    # the sweep kernel agrees with the record kernel
    totals = simulate_sources(inst, make_policy("chairs-ucb", t0=t0), [3], T, M)
    assert np.array_equal(totals.regret[0], [s.regret[-1] for s in blk.sources])


@pytest.mark.parametrize(("t0", "says"), [(-1, "t0"), (2.5, "t0"), ("x", "t0")])
def test_musical_chairs_refuses_a_bad_learning_phase_naming_t0(t0, says):
    with pytest.raises(PolicyError, match=says):
        make_policy("chairs-ucb", t0=t0)


def test_a_learning_phase_past_the_horizon_learns_for_the_whole_run():
    # t0 = 1e30 is a valid whole number: it overflowed the kernel's int64 (OverflowError);
    # any t0 past the horizon is the horizon, a uniform channel every slot
    inst = load_instance("I1")
    T, M = 400, 2
    huge = simulate_sources(inst, make_policy("chairs-ucb", t0=1e30), range(3), T, M)
    whole = simulate_sources(inst, make_policy("chairs-ucb", t0=T), range(3), T, M)
    assert np.array_equal(huge.regret, whole.regret) and np.array_equal(huge.pulls, whole.pulls)
    blk = SourcesBlock.concat(list(simulate_run_sources(
        inst, make_policy("chairs-ucb", t0=1e30), 0, T, M, block=T)))  # fmt: skip
    assert all(not s.forced.any() and len(set(s.arm.tolist())) == inst.K for s in blk.sources)


def test_no_two_mctopm_sources_keep_one_channel_as_their_seat():
    """The AoI-aware override puts off UCB's first pulls past the first seats; a forced pull
    then moved a seated source without unseating it, and two sources seated on one channel
    collided there for good (I1, seed 2: ages of 2,000 slots, regret near 2e6)."""
    inst = load_instance("I1")
    for name in ("mctopm-aoi-aware-ucb", "mctopm-aoi-aware-cucb", "mctopm-ucb"):
        sim = SourcesSimulation(inst, make_policy(name), list(range(12)), 2000, 3)
        for _ in range(20):
            sim.advance(100, record=False)
            for r in range(12):
                seats = sim.rank[r][sim.seated[r]].tolist()
                assert len(seats) == len(set(seats)), (name, r, sim.t, seats)
        assert sim.aoi.max() < 200, (name, sim.aoi.max())
