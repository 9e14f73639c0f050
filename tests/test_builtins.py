"""The built-ins added on the policy API (q-ucb, q-ts, sw-ucb, d-ts and their forms), the
golden runs of every built-in, and the conformance check plug-in authors run."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from corraoi.engine.simulation import simulate
from corraoi.model.instance import load_instance
from corraoi.policies import builtins, make_policy
from corraoi.testing import check_policy

I1 = load_instance("I1")
GOLDEN = Path(__file__).parent / "golden"


def run(name: str, seeds: list[int], T: int, **params: float):  # type: ignore[no-untyped-def]
    return next(simulate(I1, make_policy(name, **params), seeds, T, block=T))


def test_d_ts_with_gamma_1_is_ts_exactly():
    assert np.array_equal(run("d-ts", [1, 2], 2000, gamma=1.0).arm, run("ts", [1, 2], 2000).arm)
    assert np.array_equal(
        run("aoi-aware-d-ts", [5], 2000, gamma=1.0).arm, run("aoi-aware-ts", [5], 2000).arm
    )


def test_d_ts_forgets():
    # a small gamma keeps exploring: more pulls off the best arm than TS
    d = run("d-ts", list(range(20)), 3000, gamma=0.5).pulls[:, -1, 1].mean()
    assert d < run("ts", list(range(20)), 3000).pulls[:, -1, 1].mean() - 200


def test_sw_ucb_plays_its_windowed_index():
    W, c, T = 50, 2.0, 1500
    b = run("sw-ucb", [7], T, window=W, c=c).run(0)
    for i in range(T):
        t = i + 1
        lo = max(0, i - W)
        arms, succ = b.arm[lo:i], b.success[lo:i]
        n = np.bincount(arms, minlength=4).astype(float)
        s = np.bincount(arms, weights=succ, minlength=4)
        lt = math.log(min(t, W)) if t > 1 else 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            index = np.where(n > 0, s / n + np.sqrt(c * lt / n), np.inf)
        assert index[b.arm[i]] == index.max(), t


def test_q_ucb_explores_at_the_stated_rate_and_otherwise_plays_its_index():
    R, T = 300, 600
    b = run("q-ucb", list(range(R)), T)
    K = 4
    off = np.zeros(T, dtype=int)
    for i in range(K, T):
        t = i + 1
        pulls, mu = b.pulls[:, i - 1], b.mu_hat[:, i - 1]
        index = mu + np.log(t) / np.sqrt(2 * np.maximum(pulls, 1))
        index[pulls == 0] = np.inf
        chosen = np.take_along_axis(index, b.arm[:, i : i + 1], axis=1)[:, 0]
        off[i] = int((chosen < index.max(axis=1)).sum())
    # slots t in [400, 600): explore w.p. 3K ln^2 t / t; an explored arm misses the
    # (unique, almost surely) index argmax w.p. 3/4
    ts = np.arange(400, T) + 1
    expected = (np.minimum(1, 3 * K * np.log(ts) ** 2 / ts) * 0.75 * R).sum()
    observed = off[400:].sum()
    assert abs(observed - expected) < 5 * math.sqrt(expected), (observed, expected)


def test_q_ts_explores_early_and_learns():
    b = run("q-ts", list(range(100)), 4000)
    early = np.bincount(b.arm[:, 5:40].ravel(), minlength=4) / b.arm[:, 5:40].size
    assert np.all(np.abs(early - 0.25) < 0.05)  # min(1, 3K ln^2 t/t) = 1 early: uniform
    late = (b.arm[:, -500:] == 1).mean()
    assert late > 0.6  # mostly the best arm (2) by then


def test_correlated_forms_use_the_candidate_set():
    b = run("cq-ucb", list(range(10)), 1000)
    assert (~b.candidates).any()  # arms 1 and 4 leave the candidate set on I1
    assert not (~run("q-ucb", list(range(10)), 1000).candidates).any()


@pytest.mark.parametrize("name", ["q-ucb", "sw-ucb", "d-ts", "aoi-aware-cq-ts"])
def test_new_builtins_pass_the_conformance_check(name: str, tmp_path: Path):
    check_policy(name, arms=(2, 64), horizon=200, tmp_path=tmp_path)


def test_conformance_check_catches_a_batch_mixing_policy(tmp_path: Path):
    plugin = tmp_path / "mixer.py"
    plugin.write_text(
        "import numpy as np\n"
        "from corraoi.policies import Policy\n"
        "class Mixer(Policy):\n"
        "    name = 'mixer'\n"
        "    def select(self, t, state):\n"
        "        # decides every run from one shared draw: runs depend on their batch\n"
        "        return np.full(state.runs, int(np.random.default_rng(t + state.runs)"
        ".integers(state.arms)))\n"
    )
    with pytest.raises(AssertionError, match="own stream"):
        check_policy(f"{plugin}:Mixer", arms=(3,), horizon=50)
    check_policy(str(Path(__file__).parent / "plugins" / "eps_greedy.py") + ":EpsilonGreedy",
                 arms=(2, 64), horizon=100, tmp_path=tmp_path)  # fmt: skip


def test_every_builtin_has_a_reference_and_a_colour():
    for name, cls in builtins().items():
        assert cls.reference and cls.color is not None, name
