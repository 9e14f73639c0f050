"""The compiled simulation kernel: every policy, every run, block by block.

One numba function advances R independent runs by B slots. Runs are spread over the cores
with ``prange``; each run owns two SFC64 random streams (latent path, policy), so results
do not depend on the number of threads.

The SFC64 step is NumPy's (``numpy.random.SFC64``) bit for bit: a stream seeded here
yields exactly ``numpy.random.Generator(SFC64(seed_sequence)).random()``, which the tests
check. Normals (polar method) and gammas (Marsaglia-Tsang) are our own, drawn from that
stream.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

U64 = np.uint64
_S11 = np.uint64(11)
_S3 = np.uint64(3)
_S24 = np.uint64(24)
_S40 = np.uint64(40)
_ONE = np.uint64(1)
_INV53 = 1.0 / 9007199254740992.0

BASE_UCB, BASE_TS_BETA, BASE_TS_GAUSS = 0, 1, 2


@njit(inline="always", cache=True)
def _next_u64(st):
    a = st[0]
    b = st[1]
    c = st[2]
    w = st[3]
    tmp = a + b + w
    st[3] = w + _ONE
    st[0] = b ^ (b >> _S11)
    st[1] = c + (c << _S3)
    st[2] = ((c << _S24) | (c >> _S40)) + tmp
    return tmp


@njit(inline="always", cache=True)
def _uniform(st):
    return float(_next_u64(st) >> _S11) * _INV53


@njit(cache=True)
def _normal(st, cache):
    """Standard normal by the polar method; the spare value waits in ``cache[1]``."""
    if cache[0] != 0.0:
        cache[0] = 0.0
        return cache[1]
    while True:
        u = 2.0 * _uniform(st) - 1.0
        v = 2.0 * _uniform(st) - 1.0
        s = u * u + v * v
        if 0.0 < s < 1.0:
            break
    f = math.sqrt(-2.0 * math.log(s) / s)
    cache[0] = 1.0
    cache[1] = v * f
    return u * f


@njit(cache=True)
def _gamma(st, cache, shape):
    """Gamma(shape, 1) for shape >= 1 (Marsaglia and Tsang 2000)."""
    d = shape - 1.0 / 3.0
    c = 1.0 / math.sqrt(9.0 * d)
    while True:
        x = _normal(st, cache)
        v = 1.0 + c * x
        if v <= 0.0:
            continue
        v = v * v * v
        u = _uniform(st)
        x2 = x * x
        if u < 1.0 - 0.0331 * x2 * x2:
            return d * v
        if math.log(u) < 0.5 * x2 + d * (1.0 - v + math.log(v)):
            return d * v


@njit(cache=True)
def _beta(st, cache, a, b):
    ga = _gamma(st, cache, a)
    gb = _gamma(st, cache, b)
    return ga / (ga + gb)


@njit(cache=True)
def _argmax_random(vals, mask, st, K):
    """Index of the largest ``vals[k]`` with ``mask[k]``; ties uniformly at random.

    Reservoir sampling: one uniform draw per extra tied arm, none without ties.
    """
    best = -1
    bestv = -np.inf
    ties = 0
    for k in range(K):
        if not mask[k]:
            continue
        v = vals[k]
        if best < 0 or v > bestv:
            best = k
            bestv = v
            ties = 1
        elif v == bestv:
            ties += 1
            if _uniform(st) * ties < 1.0:
                best = k
    return best


@njit(parallel=True, cache=True)
def advance(
    cdf,  # (n,) float64 cumulative distribution of X
    Y,  # (K, n) int8 rewards
    spol,  # (K, K, 2) float64 policy pseudo-rewards s[k, l, r]
    best,  # int: index of the best arm (for the oracle)
    base,  # int: BASE_UCB / BASE_TS_BETA / BASE_TS_GAUSS
    correlated,  # bool
    aware,  # bool: AoI-aware override
    c_ucb,  # float
    beta,  # float
    t0,  # int: slots already simulated
    nslots,  # int: slots to simulate now
    lat,  # (R, 4) uint64 latent streams
    pol,  # (R, 4) uint64 policy streams
    ncache,  # (R, 2) float64 spare normal per run
    pulls,  # (R, K) int64
    succ,  # (R, K) int64
    aoi,  # (R,) int64 current age
    oaoi,  # (R,) int64 oracle's current age
    regret,  # (R,) int64 pathwise regret so far
    aoisum,  # (R,) int64 sum of ages so far
    record,  # bool: write the per-slot columns below
    o_x,  # (R, B) int16
    o_arm,  # (R, B) int16
    o_succ,  # (R, B) bool
    o_aoi,  # (R, B) int64
    o_oaoi,  # (R, B) int64
    o_regret,  # (R, B) int64
    o_override,  # (R, B) bool
    o_cand,  # (R, B, K) bool
    o_pulls,  # (R, B, K) int64
    o_muhat,  # (R, B, K) float64
    snap_t,  # (S,) int64 ascending slots in (t0, t0 + nslots] at which to snapshot
    s_regret,  # (R, S) int64 regret at each snapshot slot
    s_aoisum,  # (R, S) int64 sum of ages at each snapshot slot
    s_pulls,  # (R, S, K) int64 pulls at each snapshot slot
):
    R = pulls.shape[0]
    K = pulls.shape[1]
    n = cdf.shape[0]
    for r in prange(R):
        lst = lat[r]
        pst = pol[r]
        cache = ncache[r]
        npull = pulls[r]
        nsucc = succ[r]
        muhat = np.empty(K)
        vals = np.empty(K)
        cand = np.empty(K, dtype=np.bool_)
        in_s = np.empty(K, dtype=np.bool_)
        age = aoi[r]
        oage = oaoi[r]
        reg = regret[r]
        asum = aoisum[r]
        si = 0
        nsnap = snap_t.shape[0]
        for j in range(nslots):
            t = t0 + j + 1
            # ---- the latent state, from the latent stream only (common random numbers)
            u = _uniform(lst)
            x = n - 1
            for i in range(n - 1):
                if u < cdf[i]:
                    x = i
                    break
            # ---- the policy's decision, from the history and the policy stream only
            maxmu = 0.0
            for k in range(K):
                m = nsucc[k] / npull[k] if npull[k] > 0 else 0.0
                muhat[k] = m
                if m > maxmu:
                    maxmu = m
                cand[k] = True
            unpulled = -1
            for k in range(K):
                if npull[k] == 0:
                    unpulled = k
                    break
            forced = base == BASE_UCB and unpulled >= 0  # UCB's round-robin start
            if correlated and not forced:
                # S_t: arms pulled at least (t-1)/K times
                for k in range(K):
                    in_s[k] = npull[k] * K >= t - 1
                kemp = _argmax_random(muhat, in_s, pst, K)
                target = muhat[kemp]
                for k in range(K):
                    lo = np.inf
                    for l in range(K):
                        if in_s[l] and npull[l] > 0:
                            ph = (
                                nsucc[l] * spol[k, l, 1] + (npull[l] - nsucc[l]) * spol[k, l, 0]
                            ) / npull[l]
                            if ph < lo:
                                lo = ph
                    cand[k] = lo >= target
                cand[kemp] = True
            override = aware and maxmu > 0.0 and age * maxmu > 1.0
            if override:
                for k in range(K):
                    in_s[k] = True
                arm = _argmax_random(muhat, in_s, pst, K)
            elif forced:
                arm = unpulled
            else:
                if base == BASE_UCB:
                    lt = math.log(t)
                    for k in range(K):
                        vals[k] = muhat[k] + math.sqrt(c_ucb * lt / npull[k])
                elif base == BASE_TS_BETA:
                    for k in range(K):
                        if cand[k]:
                            vals[k] = _beta(pst, cache, nsucc[k] + 1.0, npull[k] - nsucc[k] + 1.0)
                else:
                    for k in range(K):
                        if cand[k]:
                            vals[k] = muhat[k] + math.sqrt(beta / (npull[k] + 1.0)) * _normal(
                                pst, cache
                            )
                arm = _argmax_random(vals, cand, pst, K)
            # ---- outcome and ages
            rew = Y[arm, x]
            npull[arm] += 1
            nsucc[arm] += rew
            age = 1 if rew == 1 else age + 1
            oage = 1 if Y[best, x] == 1 else oage + 1
            reg += age - oage
            asum += age
            if record:
                o_x[r, j] = x
                o_arm[r, j] = arm
                o_succ[r, j] = rew == 1
                o_aoi[r, j] = age
                o_oaoi[r, j] = oage
                o_regret[r, j] = reg
                o_override[r, j] = override
                for k in range(K):
                    o_cand[r, j, k] = cand[k]
                    o_pulls[r, j, k] = npull[k]
                    o_muhat[r, j, k] = nsucc[k] / npull[k] if npull[k] > 0 else 0.0
            if si < nsnap and snap_t[si] == t:
                s_regret[r, si] = reg
                s_aoisum[r, si] = asum
                for k in range(K):
                    s_pulls[r, si, k] = npull[k]
                si += 1
        aoi[r] = age
        oaoi[r] = oage
        regret[r] = reg
        aoisum[r] = asum


@njit(cache=True)
def sfc64_doubles(st, count):
    """``count`` uniforms from one SFC64 state (used by tests against NumPy)."""
    out = np.empty(count)
    for i in range(count):
        out[i] = _uniform(st)
    return out
