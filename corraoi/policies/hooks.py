"""Default hooks of compiled policies: force nothing, score nothing, keep no state.

Also the hooks several built-in families share (UCB's first pull of every arm).
"""

from __future__ import annotations

from numba import njit


@njit(inline="always", cache=True)
def forced_none(t, K, npull, nsucc, params, ps, pst):
    return -1


@njit(inline="always", cache=True)
def score_none(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    for k in range(K):
        vals[k] = muhat[k]


@njit(inline="always", cache=True)
def update_none(t, arm, reward, K, npull, nsucc, params, ps):
    return


@njit(inline="always", cache=True)
def first_unpulled(t, K, npull, nsucc, params, ps, pst):
    """The lowest-index arm never pulled (play each arm once, in order), or -1."""
    for k in range(K):
        if npull[k] == 0:
            return k
    return -1
