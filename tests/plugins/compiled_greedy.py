"""A compiled plug-in: UCB with a tunable bonus, written with numba hooks."""

import math

from numba import njit

from corraoi.policies import CompiledPolicy, Param


@njit(cache=True)
def bonus_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    for k in range(K):
        vals[k] = muhat[k] + params[0] * math.sqrt(math.log(t) / npull[k])


class BonusUCB(CompiledPolicy):
    """UCB with index mu_hat + a sqrt(ln t / n)."""

    name = "bonus-ucb"
    params = {"a": Param(1.0, "bonus scale", low=0.0)}
    forced = "corraoi.policies.hooks:first_unpulled"
    score = bonus_score
