"""The compiled hooks of the built-in policies (numba).

The policy classes (:mod:`corraoi.policies.paper`, ``forced_exploration``, ``drifting``) name
these functions as ``"corraoi.policies.builtin_hooks:<name>"``, so that the classes -- and
the registry, and every log reader -- import without numba; the engine imports this module
when it composes a kernel. Signatures: see :class:`corraoi.policies.CompiledPolicy`.
"""

from __future__ import annotations

import math

from numba import njit

from corraoi.rng import gamma_dc, integer, normal, uniform


@njit(inline="always", cache=True)
def ucb_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    lt = math.log(t)
    c = params[0]
    for k in range(K):
        vals[k] = muhat[k] + math.sqrt(c * lt / npull[k])


@njit(inline="always", cache=True)
def ts_beta_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    # Beta(S + 1, F + 1) as Gamma(S + 1) / (Gamma(S + 1) + Gamma(F + 1)), with each arm's
    # Marsaglia-Tsang constants cached in ps (d_a, c_a, d_b, c_b; 0 = to compute): the same
    # draws as rng.beta, about 1.5x faster.
    for k in range(K):
        if cand[k]:
            if ps[k] == 0.0:
                da = nsucc[k] + 1.0 - 1.0 / 3.0
                db = npull[k] - nsucc[k] + 1.0 - 1.0 / 3.0
                ps[k] = da
                ps[K + k] = 1.0 / math.sqrt(9.0 * da)
                ps[2 * K + k] = db
                ps[3 * K + k] = 1.0 / math.sqrt(9.0 * db)
            # Gamma(S + 1), then Gamma(F + 1), through one call site: the inlined sampler is
            # compiled once (the TS family's first compile 17.1 -> 15.0 s), the same draws
            ga = 0.0
            for h in range(2):
                j = 2 * h * K + k
                g = gamma_dc(pst, cache, ps[j], ps[K + j])
                if h == 0:
                    ga = g
                else:
                    vals[k] = ga / (ga + g)


@njit(inline="always", cache=True)
def ts_beta_update(t, arm, reward, K, npull, nsucc, params, ps):
    ps[arm] = 0.0  # the played arm's posterior changed: recompute its constants


@njit(inline="always", cache=True)
def ts_gauss_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    b = params[0]
    for k in range(K):
        if cand[k]:
            vals[k] = muhat[k] + math.sqrt(b / (npull[k] + 1.0)) * normal(pst, cache)


@njit(inline="always", cache=True)
def _explore(t, K, pst):
    if t < 2:
        return -1
    lt = math.log(t)
    prob = 3.0 * K * lt * lt / t
    if uniform(pst) < prob:
        return integer(pst, K)
    return -1


@njit(inline="always", cache=True)
def q_ucb_forced(t, K, npull, nsucc, params, ps, pst):
    arm = _explore(t, K, pst)
    if arm >= 0:
        return arm
    for k in range(K):
        if npull[k] == 0:
            return k
    return -1


@njit(inline="always", cache=True)
def q_ts_forced(t, K, npull, nsucc, params, ps, pst):
    return _explore(t, K, pst)


@njit(inline="always", cache=True)
def q_ucb_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    lt = math.log(t)
    for k in range(K):
        vals[k] = muhat[k] + math.sqrt(lt * lt / (2.0 * npull[k]))


@njit(inline="always", cache=True)
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


@njit(inline="always", cache=True)
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


@njit(inline="always", cache=True)
def d_ts_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    # Beta(S~ + 1, F~ + 1) of the discounted counts as rng.beta draws it (Gamma(a) /
    # (Gamma(a) + Gamma(b)), the same draws), through one inlined call site
    for k in range(K):
        if cand[k]:
            ga = 0.0
            for h in range(2):
                d = ps[h * K + k] + 1.0 - 1.0 / 3.0
                g = gamma_dc(pst, cache, d, 1.0 / math.sqrt(9.0 * d))
                if h == 0:
                    ga = g
                else:
                    vals[k] = ga / (ga + g)


@njit(inline="always", cache=True)
def d_ts_update(t, arm, reward, K, npull, nsucc, params, ps):
    g = params[0]
    for k in range(2 * K):
        ps[k] *= g
    ps[arm] += float(reward)
    ps[K + arm] += 1.0 - float(reward)
