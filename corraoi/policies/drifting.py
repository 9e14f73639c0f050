"""Policies for channels that drift: sliding-window UCB and discounted Thompson sampling.

* ``sw-ucb``: Garivier and Moulines (2011), "On upper-confidence bound policies for switching
  bandit problems" (ALT): the index of arm k is its mean over the last ``window`` slots plus
  sqrt(c ln(min(t, window)) / N_k), N_k its pulls within the window; an arm not pulled within
  the window has an infinite index (ties uniformly at random).
* ``d-ts``: Raj and Kalyani (2017), "Taming non-stationary bandits: a Bayesian approach"
  (arXiv:1707.09727): every slot all arms' success and failure counts are multiplied by
  ``gamma`` and the played arm's gain its reward; arm k samples Beta(S_k + 1, F_k + 1).

Their correlated forms are left out on purpose: the candidate set rests on pseudo-rewards
estimated from the whole history, which a drifting channel invalidates. The AoI-aware form
uses the whole-history mu_hat, as for every policy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from numba import njit

from ..rng import beta as beta_sample
from .api import CompiledPolicy, Param
from .paper import C_PARAM
from .variants import family


@njit(cache=True)
def sw_ucb_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    window = int(params[0])
    c = params[1]
    lt = math.log(min(t, window)) if t > 1 else 0.0
    for k in range(K):
        n = ps[k]
        if n == 0.0:
            vals[k] = math.inf
        else:
            vals[k] = ps[K + k] / n + math.sqrt(c * lt / n)


@njit(cache=True)
def sw_ucb_update(t, arm, reward, K, npull, nsucc, params, ps):
    # ps: [0, K) pulls in the window, [K, 2K) successes in the window, then a ring of the last
    # `window` slots: arm + 1 (0 = empty) and reward.
    window = int(params[0])
    pos = (t - 1) % window
    ring_arm = 2 * K + pos
    ring_rew = 2 * K + window + pos
    old = int(ps[ring_arm])
    if old > 0:
        ps[old - 1] -= 1.0
        ps[K + old - 1] -= ps[ring_rew]
    ps[ring_arm] = arm + 1.0
    ps[ring_rew] = float(reward)
    ps[arm] += 1.0
    ps[K + arm] += float(reward)


@njit(cache=True)
def d_ts_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    for k in range(K):
        if cand[k]:
            vals[k] = beta_sample(pst, cache, ps[k] + 1.0, ps[K + k] + 1.0)


@njit(cache=True)
def d_ts_update(t, arm, reward, K, npull, nsucc, params, ps):
    g = params[0]
    for k in range(2 * K):
        ps[k] *= g
    ps[arm] += float(reward)
    ps[K + arm] += 1.0 - float(reward)


class SWUCB(CompiledPolicy):
    """Sliding-window UCB: mean and count over the last `window` slots."""

    name = "sw-ucb"
    params = {
        "window": Param(500.0, "slots in the sliding window", low=1.0, high=1e7, integer=True),
        "c": C_PARAM,
    }
    color = (227, 119, 194)  # pink
    reference = "Garivier and Moulines (2011), ALT"
    score = sw_ucb_score
    update = sw_ucb_update

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        return 2 * K + 2 * int(params["window"])


class DTS(CompiledPolicy):
    """Discounted Thompson sampling: counts decay by `gamma` every slot."""

    name = "d-ts"
    params = {"gamma": Param(0.95, "discount factor of the counts", low=0.0, high=1.0,
                             open_low=True)}  # fmt: skip
    color = (127, 127, 127)  # grey
    reference = "Raj and Kalyani (2017), arXiv:1707.09727"
    score = d_ts_score
    update = d_ts_update

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        return 2 * K


POLICIES = {
    cls.name: cls
    for fam in (family(SWUCB, correlated_name=None), family(DTS, correlated_name=None))
    for cls in fam
}
