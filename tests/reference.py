"""A slow, plain-Python statement of the policies' decision rules (design.md section 2).

``check_run`` replays a recorded run slot by slot and asserts that every decision the
engine logged is one the rule allows. It is the conformance check every registered policy
passes, and it turns red on a wrong index, a wrong candidate set or a biased tie-break.
"""

from __future__ import annotations

import math

import numpy as np

from corraoi.engine.block import SlotBlock
from corraoi.model.instance import Instance
from corraoi.model.theory import analyse, policy_pseudo_rewards
from corraoi.policies import PolicySpec


def expected_candidates(
    pulls: np.ndarray, succ: np.ndarray, t: int, spol: np.ndarray
) -> tuple[np.ndarray, list[int]]:
    """(A_t, the arms that may be k_emp) from the state before slot t."""
    K = pulls.size
    mu = np.where(pulls > 0, succ / np.maximum(pulls, 1), 0.0)
    in_s = pulls * K >= t - 1
    top = mu[in_s].max()
    kemps = [k for k in range(K) if in_s[k] and mu[k] == top]
    A = np.zeros(K, dtype=bool)
    for k in range(K):
        lo = math.inf
        for l in range(K):
            if in_s[l] and pulls[l] > 0:
                ph = (succ[l] * spol[k, l, 1] + (pulls[l] - succ[l]) * spol[k, l, 0]) / pulls[l]
                lo = min(lo, ph)
        A[k] = lo >= top
    return A, kemps


def check_run(inst: Instance, policy: PolicySpec, run: SlotBlock) -> None:
    K = inst.K
    cls = policy.resolve()
    is_ucb = str(cls.score).endswith(":ucb_score")
    th = analyse(inst)
    spol = policy_pseudo_rewards(inst)
    pulls = np.zeros(K, dtype=np.int64)
    succ = np.zeros(K, dtype=np.int64)
    age, oage, reg, asum = 1, 1, 0, 0
    for i, t in enumerate(run.t):
        assert t == i + 1
        arm = int(run.arm[i])
        x = int(run.x[i])
        mu = np.where(pulls > 0, succ / np.maximum(pulls, 1), 0.0)
        forced = is_ucb and bool((pulls == 0).any())
        # the candidate set
        if cls.correlated and not forced:
            A, kemps = expected_candidates(pulls, succ, int(t), spol)
            options = [A | (np.arange(K) == e) for e in kemps]
            assert any(np.array_equal(run.candidates[i], o) for o in options), (
                t,
                run.candidates[i],
            )
        else:
            assert run.candidates[i].all(), t
        # the AoI-aware override
        override = cls.aoi_aware and mu.max() > 0 and age * mu.max() > 1
        assert bool(run.override[i]) == override, t
        if override:
            assert mu[arm] == mu.max(), t
        elif forced:
            assert arm == int(np.flatnonzero(pulls == 0)[0]), t
        else:
            cand = run.candidates[i]
            assert cand[arm], t
            if is_ucb:
                index = mu + np.sqrt(policy.params["c"] * math.log(t) / pulls)
                assert index[arm] == index[cand].max(), (t, index, arm)
        # outcome, ages, state
        r = int(inst.Y[arm, x])
        assert bool(run.success[i]) == (r == 1)
        pulls[arm] += 1
        succ[arm] += r
        age = 1 if r else age + 1
        oage = 1 if inst.Y[th.best_arm, x] else oage + 1
        reg += age - oage
        asum += age
        assert run.aoi[i] == age and run.oracle_aoi[i] == oage and run.regret[i] == reg, t
        assert run.estimator[i] == asum - t / th.mu_star
        assert np.array_equal(run.pulls[i], pulls), t
        np.testing.assert_array_equal(
            run.mu_hat[i], np.where(pulls > 0, succ / np.maximum(pulls, 1), 0.0)
        )
