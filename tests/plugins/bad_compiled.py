"""Compiled plug-ins that misbehave in their hooks, one way each (tests/test_hook_faults.py),
and one whose +inf scores are legitimate (UCB that scores unpulled arms +inf)."""

import math

import numpy as np
from numba import njit

from corraoi.policies import CompiledPolicy, Param, Policy


@njit(cache=True)
def far_forced(t, K, npull, nsucc, params, ps, pst):
    if t >= params[0]:
        return 1000000
    return -1


@njit(cache=True)
def very_negative_forced(t, K, npull, nsucc, params, ps, pst):
    return -1000000  # any negative number: no forced arm


@njit(cache=True)
def nan_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    for k in range(K):
        vals[k] = math.nan if t >= params[0] and k == 2 else muhat[k]


@njit(cache=True)
def inf_ucb_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    for k in range(K):
        if npull[k] == 0:
            vals[k] = math.inf
        else:
            vals[k] = muhat[k] + math.sqrt(2.0 * math.log(t) / npull[k])


class FarArm(CompiledPolicy):
    name = "far-arm"
    params = {"at": Param(7.0, "slot from which forced returns arm 10^6", low=1.0)}
    forced = far_forced
    score = "corraoi.policies.hooks:score_none"


class NaNScore(CompiledPolicy):
    name = "nan-score"
    params = {"at": Param(9.0, "slot from which arm 3 scores NaN", low=1.0)}
    score = nan_score


class InfUCB(CompiledPolicy):
    """UCB whose unpulled arms score +inf (ties at +inf broken at random)."""

    name = "inf-ucb"
    forced = very_negative_forced
    score = inf_ucb_score


class InfUCBPython(Policy):
    """InfUCB's rule in plain Python: the same arms, from the same policy stream."""

    name = "inf-ucb-python"

    def select(self, t, state):
        n = state.pulls
        bonus = np.sqrt(2.0 * math.log(t) / np.maximum(n, 1))
        score = np.where(n == 0, np.inf, state.mu_hat + bonus)
        return state.rng.argmax(score)


class RaisesInInit(Policy):
    name = "raises-in-init"

    def __init__(self, **params):
        super().__init__(**params)
        raise RuntimeError("no licence for this policy")

    def select(self, t, state):
        return np.zeros(state.runs, dtype=np.int64)


@njit(cache=True)
def raising_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    if t > 5:
        raise ValueError("score gave up")
    for k in range(K):
        vals[k] = muhat[k]


@njit(cache=True)
def two_argument_forced(t, K):
    return 0


class RaisingScore(CompiledPolicy):
    name = "raising-score"
    score = raising_score


class WrongSignature(CompiledPolicy):
    name = "wrong-signature"
    forced = two_argument_forced
    score = "corraoi.policies.hooks:score_none"


class NegativeState(CompiledPolicy):
    name = "negative-state"
    score = "corraoi.policies.hooks:score_none"

    @classmethod
    def state_size(cls, K, params):
        return -5


class HugeState(CompiledPolicy):
    name = "huge-state"
    score = "corraoi.policies.hooks:score_none"

    @classmethod
    def state_size(cls, K, params):
        return 10**15


class RaisingState(CompiledPolicy):
    name = "raising-state"
    score = "corraoi.policies.hooks:score_none"

    @classmethod
    def state_size(cls, K, params):
        raise RuntimeError("state size unknown")


@njit(cache=True)
def writing_update(t, arm, reward, K, npull, nsucc, params, ps):
    if t != params[1]:
        return
    what = params[0]
    if what == 1.0:  # one pull too many
        npull[0] += 1
    elif what == 2.0:  # the played arm's successes
        nsucc[arm] = 0 if nsucc[arm] > 0 else npull[arm]
    elif what == 3.0:  # a pull moved: the pulls still add up to the slots
        other = 1 if arm == 0 else 0
        npull[arm] -= 1
        npull[other] += 1
    elif what == 4.0:  # its own parameter
        params[2] = 1.0


class WritesCounts(CompiledPolicy):
    """Writes into what its hooks may only read (params: what, at which slot)."""

    name = "writes-counts"
    params = {"what": Param(0.0, "0 nothing, 1 npull, 2 nsucc, 3 a pull moved, 4 params",
                            low=0.0, high=4.0, integer=True),
              "at": Param(5.0, "the slot", low=1.0),
              "spare": Param(0.0, "a parameter it overwrites")}  # fmt: skip
    forced = "corraoi.policies.hooks:first_unpulled"
    score = "corraoi.policies.hooks:score_none"
    update = writing_update
