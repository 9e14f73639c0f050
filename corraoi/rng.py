"""Random numbers inside compiled code: per-run SFC64 streams and the samplers policies use.

Every run owns two SFC64 streams (a ``(4,)`` uint64 state each): the latent stream draws the
hidden path, the policy stream everything a policy randomises. The SFC64 step is NumPy's
(``numpy.random.SFC64``) bit for bit: a stream seeded here yields exactly
``numpy.random.Generator(SFC64(seed_sequence)).random()``, which the tests check.

These functions are the public toolbox of compiled policies (``docs/extending.md``): call them
from your own ``@njit`` hooks with the ``pst`` (policy stream) and ``cache`` (spare normal)
arrays the kernel hands you.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_S11 = np.uint64(11)
_S3 = np.uint64(3)
_S24 = np.uint64(24)
_S40 = np.uint64(40)
_ONE = np.uint64(1)
_INV53 = 1.0 / 9007199254740992.0


@njit(inline="always", cache=True)
def next_u64(st):
    """The next 64 random bits of the SFC64 stream ``st`` ((4,) uint64, advanced in place)."""
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
def uniform(st):
    """A uniform double in [0, 1), as NumPy's ``Generator.random()``."""
    return float(next_u64(st) >> _S11) * _INV53


@njit(cache=True)
def integer(st, high):
    """A uniform integer in [0, high) (``high`` >= 1), from one uniform draw."""
    k = int(uniform(st) * high)
    return k if k < high else high - 1


@njit(inline="always", cache=True)
def normal(st, cache):
    """Standard normal by the polar method; the spare value waits in ``cache[1]``."""
    if cache[0] != 0.0:
        cache[0] = 0.0
        return cache[1]
    while True:
        u = 2.0 * uniform(st) - 1.0
        v = 2.0 * uniform(st) - 1.0
        s = u * u + v * v
        if 0.0 < s < 1.0:
            break
    f = math.sqrt(-2.0 * math.log(s) / s)
    cache[0] = 1.0
    cache[1] = v * f
    return u * f


@njit(cache=True)
def gamma(st, cache, shape):
    """Gamma(shape, 1) for shape >= 1 (Marsaglia and Tsang 2000)."""
    d = shape - 1.0 / 3.0
    return gamma_dc(st, cache, d, 1.0 / math.sqrt(9.0 * d))


@njit(inline="always", cache=True)
def gamma_dc(st, cache, d, c):
    """Gamma(d + 1/3, 1) given Marsaglia and Tsang's constants d = shape - 1/3 and
    c = 1 / sqrt(9 d): a policy that samples the same shape many times caches them (the
    square root is a third of a draw's cost); the draws are those of :func:`gamma`."""
    while True:
        x = normal(st, cache)
        v = 1.0 + c * x
        if v <= 0.0:
            continue
        v = v * v * v
        u = uniform(st)
        x2 = x * x
        if u < 1.0 - 0.0331 * x2 * x2:
            return d * v
        if math.log(u) < 0.5 * x2 + d * (1.0 - v + math.log(v)):
            return d * v


@njit(cache=True)
def beta(st, cache, a, b):
    """Beta(a, b) for a, b >= 1, as Gamma(a) / (Gamma(a) + Gamma(b))."""
    ga = gamma(st, cache, a)
    gb = gamma(st, cache, b)
    return ga / (ga + gb)


@njit(cache=True)
def argmax_random(vals, mask, st, K):
    """Index of the largest ``vals[k]`` with ``mask[k]``; ties uniformly at random.

    Reservoir sampling: one uniform draw per extra tied arm, none without ties. Returns -1
    when no arm is in ``mask``.
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
            if uniform(st) * ties < 1.0:
                best = k
    return best


@njit(cache=True)
def sfc64_doubles(st, count):
    """``count`` uniforms from one SFC64 state (used by tests against NumPy)."""
    out = np.empty(count)
    for i in range(count):
        out[i] = uniform(st)
    return out


def streams_for_seed(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(latent, policy) SFC64 states for one integer seed, as NumPy would seed them."""
    lat_ss, pol_ss = np.random.SeedSequence(int(seed)).spawn(2)
    lat = np.random.SFC64(lat_ss).state["state"]["state"]
    pol = np.random.SFC64(pol_ss).state["state"]["state"]
    return np.array(lat, dtype=np.uint64), np.array(pol, dtype=np.uint64)


_STREAMS_CACHE: dict[int, tuple[np.ndarray, np.ndarray]] = {}
_STREAMS_CACHE_MAX = 1 << 16


def streams_for_seeds(seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(latent, policy) states of many seeds: ((R, 4), (R, 4)) uint64.

    ``SeedSequence.spawn`` costs about 37 us a seed and every policy of a sweep needs the same
    seeds, so states are memoised (up to 65,536 seeds; the arrays are copied out).
    """
    R = len(seeds)
    lat = np.empty((R, 4), dtype=np.uint64)
    pol = np.empty((R, 4), dtype=np.uint64)
    for i, s in enumerate(seeds):
        key = int(s)
        pair = _STREAMS_CACHE.get(key)
        if pair is None:
            pair = streams_for_seed(key)
            if len(_STREAMS_CACHE) < _STREAMS_CACHE_MAX:
                _STREAMS_CACHE[key] = pair
        lat[i], pol[i] = pair
    return lat, pol
