"""The engine: AoI recursion, regret identity, determinism, common random numbers,
conformance of every policy to its rule, unbiased tie-breaking, and the I2 behaviour."""

from __future__ import annotations

import time

import numpy as np
import pytest

from corraoi import rng
from corraoi.engine.block import SlotBlock
from corraoi.engine.seeds import streams_for_seeds
from corraoi.engine.simulation import RunsBlock, Simulation, simulate, simulate_run
from corraoi.errors import ConfigError
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import make_policy, paper_names
from corraoi.rng import streams_for_seed

from .reference import check_run

POLICY_NAMES = paper_names()

I1 = load_instance("I1")
I2 = load_instance("I2")


def one_run(inst: Instance, name: str, seed: int, horizon: int, block: int = 1000) -> SlotBlock:
    return SlotBlock.concat(list(simulate_run(inst, make_policy(name), seed, horizon, block=block)))


def test_sfc64_matches_numpy():
    lat, pol = streams_for_seed(7)
    ss_lat, ss_pol = np.random.SeedSequence(7).spawn(2)
    ref = np.random.Generator(np.random.SFC64(ss_lat)).random(5000)
    assert np.array_equal(rng.sfc64_doubles(lat, 5000), ref)
    ref = np.random.Generator(np.random.SFC64(ss_pol)).random(10)
    assert np.array_equal(rng.sfc64_doubles(pol, 10), ref)


def test_streams_of_many_seeds_are_numpys_seed_by_seed():
    """The engine seeds every run at once (vectorised SeedSequence and SFC64 seeding): the
    states are NumPy's ``SFC64(SeedSequence(seed).spawn(2)[i])``, bit for bit, for seeds of
    one and two 32-bit words up to the int64 limit."""
    edges = [0, 1, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**32 + 1, 2**62, 2**63 - 1]
    drawn = np.random.default_rng(5).integers(0, 2**63 - 1, 300).tolist()
    seeds = np.array([*range(200), *edges, *drawn], dtype=np.int64)
    lat, pol = streams_for_seeds(seeds)
    assert lat.shape == pol.shape == (seeds.size, 4) and lat.dtype == pol.dtype == np.uint64
    for i, seed in enumerate(seeds.tolist()):
        ss_lat, ss_pol = np.random.SeedSequence(seed).spawn(2)
        assert lat[i].tolist() == np.random.SFC64(ss_lat).state["state"]["state"].tolist()
        assert pol[i].tolist() == np.random.SFC64(ss_pol).state["state"]["state"].tolist()
    for few in (seeds[-1:], seeds[-7:], seeds[-9:]):  # a few seeds: NumPy's, one by one
        got = streams_for_seeds(few)
        assert got[0].tolist() == lat[-few.size :].tolist()
        assert got[1].tolist() == pol[-few.size :].tolist()
    with pytest.raises(ConfigError, match="non-negative"):
        streams_for_seeds(np.array([3, -1]))


def test_a_chunk_of_100000_seeds_is_seeded_in_well_under_a_second():
    """NumPy's SeedSequence took about 37 us a seed (3.7 s for a sweep chunk of 100,000
    runs); all at once it is milliseconds (2 s leaves room for a loaded machine)."""
    seeds = np.arange(10**9, 10**9 + 100_000, dtype=np.int64)
    start = time.perf_counter()
    lat, _ = streams_for_seeds(seeds)
    assert time.perf_counter() - start < 2.0
    assert lat[-1].tolist() == rng.streams_for_seed(10**9 + 99_999)[0].tolist()


def test_x_path_is_numpy_inverse_cdf_and_shared_by_policies():
    T = 3000
    ss_lat, _ = np.random.SeedSequence(11).spawn(2)
    u = np.random.Generator(np.random.SFC64(ss_lat)).random(T)
    expected = np.searchsorted(np.cumsum(I1.p), u, side="right")
    xs = [one_run(I1, name, 11, T).x for name in POLICY_NAMES]
    for x in xs:
        assert np.array_equal(x, expected)
    # and the frequencies match p
    freq = np.bincount(expected, minlength=4) / T
    np.testing.assert_allclose(freq, I1.p, atol=0.03)


@pytest.mark.parametrize("name", ["ucb", "cts", "aoi-aware-ts-gauss"])
def test_aoi_recursion_and_regret_identity(name: str):
    run = one_run(I1, name, 3, 2000)
    success = I1.Y[run.arm, run.x] == 1
    assert np.array_equal(run.success, success)
    aoi = np.empty_like(run.aoi)
    oaoi = np.empty_like(run.aoi)
    prev = oprev = 1
    for i in range(len(run)):
        prev = 1 if success[i] else prev + 1
        oprev = 1 if I1.Y[1, run.x[i]] else oprev + 1
        aoi[i], oaoi[i] = prev, oprev
    assert np.array_equal(run.aoi, aoi)
    assert np.array_equal(run.oracle_aoi, oaoi)
    assert np.array_equal(run.regret, np.cumsum(aoi - oaoi))
    np.testing.assert_allclose(run.estimator, np.cumsum(aoi) - run.t / 0.6, rtol=0, atol=1e-9)
    assert np.array_equal(run.pulls[-1], np.bincount(run.arm, minlength=4))
    assert run.pulls[-1].sum() == 2000


@pytest.mark.parametrize("name", POLICY_NAMES)
def test_conformance_every_policy(name: str):
    """Every decision the engine logged is allowed by the policy's rule (tests/reference.py)."""
    policy = make_policy(name)
    for inst, seed in ((I1, 5), (I2, 6)):
        run = one_run(inst, name, seed, 600, block=97)
        check_run(inst, policy, run)
    # the round-robin start of the UCB family
    if name in ("ucb", "cucb"):
        assert one_run(I1, name, 0, 4).arm.tolist() == [0, 1, 2, 3]


def test_conformance_with_custom_parameters():
    policy = make_policy("cucb", c=0.5)
    run = SlotBlock.concat(list(simulate_run(I1, policy, 2, 500)))
    check_run(I1, policy, run)
    # a different constant changes decisions
    assert not np.array_equal(run.arm, one_run(I1, "cucb", 2, 500).arm)


def test_determinism_blocks_threads_and_batches():
    a = one_run(I1, "cts", 42, 3000, block=1000)
    b = one_run(I1, "cts", 42, 3000, block=1000)
    c = one_run(I1, "cts", 42, 3000, block=333)
    assert a.equals(b) and a.equals(c)
    # run i of a batch started at seed s is the single run with seed s + i
    blocks = list(simulate(I1, make_policy("cts"), [40, 41, 42], 3000, block=1000))
    batch = SlotBlock.concat([blk.run(2) for blk in blocks])
    assert batch.equals(a)
    # and the thread count does not matter
    import numba

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = Simulation(I1, make_policy("ts"), list(range(16)), 2000)
        one.advance(2000, record=False)
    finally:
        numba.set_num_threads(before)
    many = Simulation(I1, make_policy("ts"), list(range(16)), 2000)
    many.advance(2000, record=False)
    assert np.array_equal(one.regret, many.regret) and np.array_equal(one.pulls, many.pulls)


def test_different_seeds_differ():
    assert not np.array_equal(one_run(I1, "ts", 1, 500).x, one_run(I1, "ts", 2, 500).x)


def test_ties_are_broken_uniformly():
    # two identical arms: after the round-robin start, UCB's indices tie exactly whenever
    # the two arms have the same history; a lowest-index rule would always pick arm 1.
    twin = Instance("twin", np.array([0.5, 0.5]), np.array([[1, 0], [1, 0]]))
    sim = Simulation(twin, make_policy("ucb"), list(range(400)), 3)
    blk = sim.advance(3)
    assert blk is not None
    same = blk.success[:, 0] == blk.success[:, 1]  # equal histories after t = 2
    picks = blk.arm[same, 2]
    share = picks.mean()
    assert same.sum() > 100
    assert 0.38 < share < 0.62, share  # 4+ standard deviations from 0 and from 1


def test_argmax_random_is_uniform():
    st = streams_for_seed(0)[1]
    vals = np.array([1.0, 3.0, 3.0, 3.0])
    mask = np.ones(4, dtype=np.bool_)
    counts = np.bincount(
        [rng.argmax_random(vals, mask, st, 4) for _ in range(6000)], minlength=4
    )
    assert counts[0] == 0
    assert np.all(np.abs(counts[1:] - 2000) < 200), counts


def test_i2_non_competitive_arms_are_pulled_o1_times():
    """C = 0 on I2: cucb and cts stop pulling arms 1-3; ucb keeps pulling them (log T)."""
    seeds = list(range(60))
    growth = {}
    for name in ("cucb", "cts", "ucb"):
        sim = Simulation(I2, make_policy(name), seeds, 8000)
        sim.advance(4000, record=False)
        at_t = sim.pulls[:, :3].sum(axis=1).copy()
        sim.advance(4000, record=False)
        growth[name] = (sim.pulls[:, :3].sum(axis=1) - at_t).mean()
    assert growth["cucb"] <= 0.5, growth
    assert growth["cts"] <= 0.5, growth
    # ucb: about 3 arms x 2 ln 2 / gap^2 more pulls per doubling (~13); far from 0
    assert growth["ucb"] >= 5.0, growth


def test_bad_settings():
    with pytest.raises(ConfigError, match=r"horizon 0: out of range, expected 1\.\."):
        Simulation(I1, make_policy("ucb"), [0], 0)
    with pytest.raises(ConfigError, match="at least one run"):
        Simulation(I1, make_policy("ucb"), [], 10)
    with pytest.raises(ConfigError, match=r"seed -1: out of range, expected 0\.\."):
        Simulation(I1, make_policy("ucb"), [-1], 10)
    with pytest.raises(ConfigError, match=r"seed 9223372036854775808: out of range"):
        Simulation(I1, make_policy("ucb"), [2**63], 10)  # one check of seeds, in limits.py
    from corraoi.experiments.grid import build_grid

    with pytest.raises(ConfigError, match=r"and 3 runs use seed \.\. seed\+2"):
        build_grid(instances=["I1"], policies=["ucb"], horizons=[10], runs=3, seed=2**63 - 2)
    dead = Instance("dead", np.array([1.0]), np.array([[0], [0]]))
    with pytest.raises(ConfigError, match="every arm has mean 0"):
        Simulation(dead, make_policy("ucb"), [0], 10)


def test_snapshots_equal_the_recorded_columns():
    seeds = [3, 4, 5]
    stops = [1, 2, 17, 500, 999, 1000]
    sim = Simulation(I1, make_policy("aoi-aware-cts"), seeds, 1000)
    snaps = sim.advance_to(600, snapshots=stops) + sim.advance_to(1000, snapshots=stops)
    assert [s.t for s in snaps] == stops
    blk = next(simulate(I1, make_policy("aoi-aware-cts"), seeds, 1000, block=1000))
    for s in snaps:
        i = s.t - 1
        assert np.array_equal(s.regret, blk.regret[:, i])
        assert np.array_equal(s.pulls, blk.pulls[:, i])
        np.testing.assert_allclose(s.estimator, blk.estimator[:, i], rtol=0, atol=1e-9)
    # and the final state is the same as without snapshots
    plain = Simulation(I1, make_policy("aoi-aware-cts"), seeds, 1000)
    plain.advance(1000, record=False)
    assert np.array_equal(plain.regret, sim.regret) and np.array_equal(plain.pulls, sim.pulls)


def test_runs_blocks_join_along_slots():
    blocks = list(simulate(I1, make_policy("ucb"), [1, 2], 250, block=100))
    joined = RunsBlock.concat(blocks)
    assert len(joined) == 250 and joined.arm.shape == (2, 250) and joined.pulls.shape == (2, 250, 4)
    assert joined.run(1).equals(one_run(I1, "ucb", 2, 250))


@pytest.mark.parametrize("K", [5, 40])
def test_candidate_sets_of_small_and_wide_instances_follow_the_rule(K: int):
    # K <= 16 tests each pair, K > 16 unions bitsets: both must give the rule's sets
    rng = np.random.default_rng(K)
    p = rng.dirichlet(np.ones(2 * K))
    Y = (rng.random((K, 2 * K)) < 0.4).astype(np.int64)
    Y[0, int(np.argmax(p))] = 1
    inst = Instance(f"random-{K}", p, Y)
    for name in ("cucb", "aoi-aware-cts"):
        check_run(inst, make_policy(name), one_run(inst, name, 3, 1500))
