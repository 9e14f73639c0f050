"""Random numbers inside compiled code: per-run SFC64 streams and the samplers policies use.

Every run owns two SFC64 streams (a ``(4,)`` uint64 state each): the latent stream draws the
hidden path, the policy stream everything a policy randomises. The SFC64 step is NumPy's
(``numpy.random.SFC64``) bit for bit: a stream seeded here yields exactly
``numpy.random.Generator(SFC64(seed_sequence)).random()``, which the tests check.

These functions are the public toolbox of compiled policies (``docs/extending.md``): call them
from your own ``@njit`` hooks with the ``pst`` (policy stream) and ``cache`` arrays the kernel
hands you (``cache`` held the polar method's spare normal; the ziggurat needs none).

Every sampler a kernel or a hook can call is ``inline="always"``, as are the built-in hooks.
Called out of line, one compiled copy served every kernel of the process, and where that copy
landed against a kernel's code decided whether a policy family ran at full or half rate;
inlined, the rate no longer depends on it (measured in docs/performance.md).
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


@njit(inline="always", cache=True)
def integer(st, high):
    """A uniform integer in [0, high) (``high`` >= 1), from one uniform draw."""
    k = int(uniform(st) * high)
    return k if k < high else high - 1


def _ziggurat() -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Tables of a 256-layer ziggurat for exp(-x^2 / 2) (Marsaglia and Tsang, "The Ziggurat
    Method for Generating Random Variables", J. Stat. Software 5(8), 2000).

    Layer i >= 1 spans [0, x_i] horizontally and [f(x_i), f(x_{i+1})] vertically, with
    x_1 = R, x_256 = 0 and equal areas V; layer 0 is the base [0, R] x [0, f(R)] plus the
    tail beyond R, of width x_0 = V / f(R). Returns (k, w, f, R): a 52-bit magnitude m of
    layer i gives x = m w_i, accepted at once when m < k_i (x < x_{i+1}); f_i = f(x_i).
    """
    r, v = 3.6541528853610088, 4.92867323399e-3

    def f(x: float) -> float:
        return math.exp(-0.5 * x * x)

    x = np.zeros(257)
    x[0], x[1] = v / f(r), r
    for i in range(1, 255):
        x[i + 1] = math.sqrt(-2.0 * math.log(v / x[i] + f(x[i])))
    scale = float(1 << 52)
    k = np.array([int(x[i + 1] / x[i] * scale) for i in range(256)], dtype=np.uint64)
    w = x[:256] / scale
    return k, w, np.array([f(xi) for xi in x]), r


_ZK, _ZW, _ZF, _ZR = _ziggurat()
_ZINV_R = 1.0 / _ZR
_M8 = np.uint64(0xFF)
_M52 = np.uint64((1 << 52) - 1)
_S8 = np.uint64(8)
_S9 = np.uint64(9)


@njit(inline="always", cache=True)
def normal(st, cache):
    """Standard normal by a 256-layer ziggurat (:func:`_ziggurat`): one 64-bit draw for 99%
    of values (8 bits pick the layer, 1 the sign, 52 the magnitude), a wedge test or
    Marsaglia's tail algorithm for the rest: about 3x faster than the polar method it
    replaced (docs/changelog.md). ``cache`` is unused; hooks written against the polar
    method's spare value still compile."""
    while True:
        bits = next_u64(st)
        i = bits & _M8
        neg = (bits >> _S8) & _ONE
        mag = (bits >> _S9) & _M52
        x = mag * _ZW[i]
        if neg:
            x = -x
        if mag < _ZK[i]:
            return x
        if i == 0:  # the tail beyond R
            while True:
                a = -math.log1p(-uniform(st)) * _ZINV_R
                b = -math.log1p(-uniform(st))
                if b + b > a * a:
                    return -(_ZR + a) if neg else _ZR + a
        elif _ZF[i] + uniform(st) * (_ZF[i + 1] - _ZF[i]) < math.exp(-0.5 * x * x):
            return x


@njit(inline="always", cache=True)
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


@njit(inline="always", cache=True)
def beta(st, cache, a, b):
    """Beta(a, b) for a, b >= 1, as Gamma(a) / (Gamma(a) + Gamma(b))."""
    ga = gamma(st, cache, a)
    gb = gamma(st, cache, b)
    return ga / (ga + gb)


@njit(inline="always", cache=True)
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
