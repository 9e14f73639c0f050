"""corraoi.gym (issue 42): the paper's model as a Gymnasium environment, paired by seed with
``corraoi record`` and logged through corraoi.Logger."""

from __future__ import annotations

import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

gymnasium = pytest.importorskip("gymnasium")

import corraoi  # noqa: E402
from corraoi.errors import SlotError, UsageError  # noqa: E402
from corraoi.recorder.slotlog.reader import open_log  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MAKE = "corraoi.gym:corraoi/CorrelatedAoI-v0"
T = 2500


@pytest.fixture(scope="module")
def cucb(tmp_path_factory):
    path = tmp_path_factory.mktemp("cucb") / "cucb.mcap"
    run = corraoi.record("cucb", "I1", seed=7, horizon=T, path=path, rrd=False)
    return run, run.log.read_all()


def test_check_env_passes():
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(MAKE, instance="I1", horizon=50)
    check_env(env.unwrapped)
    check_env(gymnasium.make(MAKE, instance="I2", horizon=50, pseudo_rewards=True).unwrapped)
    assert env.action_space == gymnasium.spaces.Discrete(4)


def test_cucbs_arms_in_the_environment_give_cucbs_path_ages_and_regret(cucb):
    _, b = cucb
    env = gymnasium.make(MAKE, instance="I1", horizon=T)
    obs, info = env.reset(seed=7)
    assert obs.tolist() == [0, 1] and info["seed"] == 7
    xs, regret, rewards, obs_aoi = [], [], [], []
    for t, arm in enumerate(b.arm.tolist(), start=1):
        obs, reward, terminated, truncated, info = env.step(arm)
        xs.append(info["x"])
        regret.append(info["regret"])
        rewards.append(reward)
        obs_aoi.append(obs[1])
        assert not terminated and truncated == (t == T)
    assert np.array_equal(np.array(xs) - 1, b.x)  # the hidden path of `record --seed 7`
    assert np.array_equal(regret, b.regret)
    assert np.array_equal(obs_aoi, b.aoi) and np.array_equal(rewards, -b.aoi)
    with pytest.raises(UsageError, match=f"slot {T + 1}: the episode ended"):
        env.unwrapped.step(0)


def test_the_reward_can_be_the_regret_increment(cucb):
    _, b = cucb
    env = gymnasium.make(MAKE, instance="I1", horizon=T, reward="regret").unwrapped
    env.reset(seed=7)
    total = sum(env.step(a)[1] for a in b.arm.tolist())
    assert total == -int(b.regret[-1])


def test_recorded_episodes_are_paired_with_corraois_runs(cucb, tmp_path):
    run, b = cucb
    env = gymnasium.make(MAKE, instance="I1", horizon=T,
                         record=tmp_path / "agent-{episode}.mcap", policy="replayed")  # fmt: skip
    for _ in range(2):
        env.reset(seed=7)
        for arm in b.arm.tolist():
            env.step(arm)
    env.reset(seed=8)
    env.step(1)
    env.close()
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["agent-0.mcap", "agent-1.mcap", "agent-2.mcap"]
    log = open_log(tmp_path / "agent-1.mcap")
    assert log.status == "complete" and log.config.seed == 7
    assert log.config.policy.name == "replayed"
    got = log.read_all()
    for f in ("x", "arm", "success", "aoi", "oracle_aoi", "regret", "estimator", "pulls"):
        assert np.array_equal(got.column(f), b.column(f)), f
    report = corraoi.diff(tmp_path / "agent-0.mcap", run)
    # the same slots in every field both hold; the fields only corraoi's run logs differ
    assert report.first_divergence is None
    assert report.differing_fields == ["override", "candidates", "forced", "score"]
    assert not any(report[f].comparable for f in report.differing_fields)
    cut = open_log(tmp_path / "agent-2.mcap")
    assert cut.status == "interrupted" and cut.n_slots == 1 and cut.config.seed == 8


def test_one_path_replaces_the_last_episodes_log(tmp_path):
    env = gymnasium.make(MAKE, instance="I1", horizon=10, record=tmp_path / "one.mcap").unwrapped
    env.reset(seed=1)
    env.step(0)
    env.reset(seed=2)
    for _ in range(10):
        env.step(1)
    log = open_log(tmp_path / "one.mcap")
    assert log.status == "complete" and log.config.seed == 2


def test_bad_steps_are_refused():
    env = gymnasium.make(MAKE, instance="I1", horizon=10).unwrapped
    with pytest.raises(UsageError, match="before reset"):
        env.step(0)
    env.reset(seed=0)
    with pytest.raises(SlotError, match="slot 1: action 4"):
        env.step(4)
    with pytest.raises(SlotError, match="slot 1: action -1"):
        env.step(-1)
    with pytest.raises(UsageError, match="reward 'age'"):
        gymnasium.make(MAKE, instance="I1", reward="age")


def test_reset_costs_the_same_for_any_horizon():
    env = gymnasium.make(MAKE, instance="I1", horizon=10**9).unwrapped
    env.reset(seed=0)
    tracemalloc.start()
    env.reset(seed=1)
    for _ in range(5000):
        env.step(1)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 4 * 2**20, peak  # a block of the path, never the horizon's 8 GB


def test_the_pseudo_rewards_are_the_models():
    from corraoi.model.instance import load_instance
    from corraoi.model.theory import policy_pseudo_rewards

    env = gymnasium.make(MAKE, instance="I2", horizon=20, pseudo_rewards=True).unwrapped
    env.reset(seed=3)
    table = policy_pseudo_rewards(load_instance("I2"))
    obs, *_ = env.step(2)
    success = int(obs["slot"][0])
    assert np.array_equal(obs["pseudo_rewards"], table[2, :, success])


def test_import_corraoi_does_not_import_gymnasium():
    code = "import sys, corraoi; corraoi.Logger; print('gymnasium' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, check=True)  # fmt: skip
    assert out.stdout.strip() == "False"


def test_the_vector_form_steps_each_sub_environments_own_paired_run():
    N, H = 5, 300
    envs = gymnasium.make_vec(MAKE, num_envs=N, instance="I1", horizon=H,
                              vectorization_mode="vector_entry_point")  # fmt: skip
    obs, info = envs.reset(seed=40)
    assert info["seed"].tolist() == [40, 41, 42, 43, 44] and obs.shape == (N, 2)
    actions = np.random.default_rng(1).integers(0, 4, (H, N))
    xs, ages = [], []
    for t, arms in enumerate(actions, start=1):
        obs, reward, terminated, truncated, info = envs.step(arms)
        xs.append(info["x"])
        ages.append(obs[:, 1])
        assert not terminated.any() and truncated.all() == (t == H)
    plain = gymnasium.make(MAKE, instance="I1", horizon=H).unwrapped
    for i in (0, 3):
        plain.reset(seed=40 + i)
        steps = [plain.step(int(a)) for a in actions[:, i]]
        assert [s[4]["x"] for s in steps] == [int(v[i]) for v in xs]
        assert [int(s[0][1]) for s in steps] == [int(v[i]) for v in ages]
        assert steps[-1][4]["regret"] == info["regret"][i]
    obs, reward, terminated, truncated, info = envs.step(actions[0])  # next-step autoreset
    assert obs.tolist() == [[0, 1]] * N and not truncated.any() and len(set(info["seed"])) == N
    with pytest.raises(SlotError, match="slot 1: sub-environment 2: action 4"):
        envs.step(np.array([0, 0, 4, 0, 0]))


def test_a_file_there_before_is_refused_unless_forced(tmp_path):
    (tmp_path / "old.mcap").write_bytes(b"old")
    env = gymnasium.make(MAKE, instance="I1", horizon=5, record=tmp_path / "old.mcap").unwrapped
    with pytest.raises(corraoi.OutputError, match="already exists"):
        env.reset(seed=0)
    env = gymnasium.make(MAKE, instance="I1", horizon=5, record=tmp_path / "old.mcap",
                         force=True).unwrapped  # fmt: skip
    env.reset(seed=0)
    for _ in range(5):
        env.step(1)
    assert open_log(tmp_path / "old.mcap").status == "complete"


def test_mabwisers_ucb1_in_the_environment_matches_corraois_ucb_seed_by_seed():
    """docs/examples/mabwiser_ucb1.py: an agent of another library (MABWiser's UCB1) acting in
    the environment, its final regret paired seed by seed with corraoi's ``ucb`` on the same
    hidden paths: the same algorithm, so the mean paired difference is within 1.96 standard
    errors of zero (20 seeds x 1,000 slots here; the docs show a larger run)."""
    pytest.importorskip("mabwiser")
    from .scripts import load_script

    example = load_script("docs/examples/mabwiser_ucb1.py")
    got = example.compare("I1", 20, 1000)
    assert 100 < got["mabwiser"] < 1000 and 100 < got["corraoi"] < 1000  # UCB's regret on I1
    assert 0 < got["se"] < 100
    assert abs(got["difference"]) <= 1.96 * got["se"], got
