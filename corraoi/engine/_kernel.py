"""The compiled simulation kernel: one policy family, R runs, block by block.

This file is a template as well as a module. :mod:`corraoi.engine.kernels` writes two copies of it
per policy family into the kernel cache, with the ``HOOKS`` import lines below pointing at that
family's compiled hooks (``forced``, ``score``, ``update``), and imports them: numba then
inlines the hooks and caches each compiled kernel on disk beside its copy, so a new process
loads it instead of compiling (closures would miss numba's cache).

The two copies are shaped by their job (docs/performance.md has the measurements):

- the **record kernel** (``corraoi record``, ``simulate``): this file's ``advance`` as it is,
  serial, with the per-slot recording path; it compiles in about 3 s;
- the **sweep kernel** (``corraoi sweep``): the ``KERNEL`` decorator line swapped for
  ``SWEEP_DECORATOR`` and the lines between ``RECORD-BEGIN`` and ``RECORD-END`` dropped. It
  is still serial (``range``, not ``prange``: numba's parfor lowering made every family
  compile for 9-17 s), but ``parallel=True`` keeps numba's parfor IR simplification, which
  makes it as fast as the old ``prange`` kernel; no loop becomes a parfor, so no numba
  thread team starts. The engine spreads runs over cores with Python threads instead (both
  kernels release the GIL).

Both kernels use numpy's error model (as numba's parfor bodies always did) and promise LLVM
that their array arguments never overlap (:class:`NoAliasCompiler`; the engine passes
distinct arrays), so the record kernel, the sweep kernel and the earlier ``prange`` kernel
take the same decisions slot for slot (``tests/golden/``).

One call advances R independent runs by ``nslots`` slots. Each run owns two SFC64 streams
(latent path, policy), so results do not depend on the number of threads or on which other
runs share the batch.

Per slot: draw the hidden state (channel), compute the empirical means, let the policy force
an arm (``forced``), compute the correlated candidate set (bitsets, when ``correlated``), apply
the AoI-aware override (when ``aware``), otherwise play the argmax of the policy's ``score``
over the candidates (ties uniformly at random), then update counts, ages and the policy's own
state (``update``).
"""
from __future__ import annotations

import numpy as np
from numba import njit
from numba.core.compiler import Compiler

from corraoi.policies.hooks import forced_none as _forced  # HOOKS
from corraoi.policies.hooks import score_none as _score  # HOOKS
from corraoi.policies.hooks import update_none as _update  # HOOKS
from corraoi.rng import argmax_random, argmax_random_nan, uniform

#: Hook options under which inlining changes nothing a hook computes (numba's defaults).
_PLAIN_OPTIONS = {"nopython": (True,), "boundscheck": (None, False), "nogil": (True, False)}


def inlined(hook):
    """``hook`` as the kernel calls it: inlined into the per-slot loop.

    Called out of line (its arrays passed as some fifty scalar arguments), a compiled
    UCB-like plug-in's score hook took 0.070 s for 200 runs x 10,000 slots, inlined 0.037 s,
    as built-in UCB; and out-of-line code ran at full or half rate by where it landed in
    memory (docs/performance.md). So a hook with numba's default options
    is re-declared ``inline="always"`` (the same function: only the kernel's numpy error
    model applies to it, as to every built-in hook). A hook declared with options that change
    its code (``fastmath``, ``error_model``, ``boundscheck=True``, ``inline="never"``) is
    called as declared.
    """
    opts = dict(hook.targetoptions)
    if opts.pop("inline", None) is not None:
        return hook
    for key, value in opts.items():
        if value not in _PLAIN_OPTIONS.get(key, ()):
            return hook
    return njit(inline="always")(hook.py_func)


_forced = inlined(_forced)
_score = inlined(_score)
_update = inlined(_update)

CHANNEL_CDF, CHANNEL_TRACE = 0, 1
#: A hook's fault, in ``err[r, 1]``: forced returned an arm >= K; score gave a candidate NaN.
FAULT_ARM, FAULT_NAN = 1, 2
#: The sweep kernel's decorator (see the module's docstring).
SWEEP_DECORATOR = (
    '@njit(cache=True, nogil=True, parallel=True, error_model="numpy", '
    "pipeline_class=NoAliasCompiler)"
)


class NoAliasCompiler(Compiler):
    """numba's default pipeline, compiling with ``noalias`` on the array arguments.

    The engine never passes overlapping arrays to ``advance``; saying so lets LLVM keep
    counts in registers across the hooks' stores (about 13% on the correlated policies,
    measured in docs/performance.md).
    """

    def __init__(self, typingctx, targetctx, library, args, return_type, flags, locals):  # noqa: A002
        flags = flags.copy()
        flags.noalias = True
        super().__init__(typingctx, targetctx, library, args, return_type, flags, locals)


@njit(inline="always", cache=True)
def draw_state(cdf_rows, kind, trace, lst, xprev, t):
    """The hidden state of slot ``t`` (1-based) of one run.

    ``kind`` CHANNEL_CDF: row 0 of ``cdf_rows`` is the law of X_1 (and of every X_t for an
    i.i.d. channel, which has that row only); rows 1..n are the transition rows, so X_t is
    drawn from row X_{t-1} + 1. One uniform per slot, inverted by a scan of the CDF (n <= 8)
    or by bisection (the same state in log n steps). CHANNEL_TRACE: X_t = trace[t - 1].
    """
    if kind == CHANNEL_TRACE:
        return trace[t - 1]
    row = 0
    if cdf_rows.shape[0] > 1 and xprev >= 0:
        row = xprev + 1
    u = uniform(lst)
    n = cdf_rows.shape[1]
    if n <= 8:  # a short scan beats bisection's unpredictable branches
        for i in range(n - 1):
            if u < cdf_rows[row, i]:
                return i
        return n - 1
    lo = 0
    hi = n - 1
    while lo < hi:
        mid = (lo + hi) >> 1
        if u < cdf_rows[row, mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


@njit(inline="always", cache=True)
def candidate_set(t, K, npull, nsucc, muhat, cand, in_s, fail, comb, has1, has2, pst, depth,
                  hint):
    """The correlated candidate set A_t + {k_emp} of one run (or source) at slot ``t`` into
    ``cand`` (``in_s`` and ``fail`` are scratch); returns the arm whose mean is the target
    (k_emp at ``depth`` 1). Shared by the single-source kernel (``depth`` 1) and the kernel of
    many sources (:mod:`corraoi.engine._sources_kernel`), whose sources look for the M best
    arms (``depth`` M): the target is then the M-th best empirical mean of S_t and the M best
    of S_t are candidates too. ``hint``: an arm to try first for that target (the one this
    returned a slot ago, which usually still is: one count instead of half the arms'; -1 for
    none); the target is the same whatever the hint."""
    W = comb.shape[2]
    # S_t: arms pulled at least (t-1)/K times; k_emp: the best of them
    for k in range(K):
        in_s[k] = npull[k] * K >= t - 1
    kemp = argmax_random(muhat, in_s, pst, K)
    target = muhat[kemp]
    at = kemp
    if depth > 1:  # the depth-th best mean of S_t (its lowest when S_t holds fewer arms)
        n = 0
        for k in range(K):
            n += in_s[k]
        d = min(depth, n) - 1
        for i in range(K + 1):  # the hint first, then every arm
            if d <= 0:
                break
            a = hint if i == 0 else i - 1
            if a < 0 or not in_s[a]:
                continue
            gt = 0
            ge = 0
            for k in range(K):
                gt += in_s[k] & (muhat[k] > muhat[a])
                ge += in_s[k] & (muhat[k] >= muhat[a])
            if gt <= d < ge:
                target = muhat[a]
                at = a
                break
    # A_t: arms k with phi_hat_{k,l} >= mu_hat[k_emp] for every pulled l in S_t.
    # phi_hat_{k,l} is 0, l's failure rate, l's success rate or 1, by the 0/1
    # pseudo-rewards (pclass): the arms failing for l are a union of precomputed bitsets,
    # one per l (K / 64 words each; at K = 16 twice as fast as testing every pair, which
    # recomputed l's rates K times and ran longer the lower the target)
    for w in range(W):
        fail[w] = np.uint64(0)
    drop0 = 1 if target > 0.0 else 0
    for l in range(K):
        if not in_s[l] or npull[l] == 0:
            continue
        code = drop0
        if has1[l] and (npull[l] - nsucc[l]) / npull[l] < target:
            code |= 2
        if has2[l] and muhat[l] < target:  # muhat[l] = S_l / n_l
            code |= 4
        if code != 0:
            for w in range(W):
                fail[w] |= comb[l, code, w]
    for k in range(K):
        cand[k] = ((fail[k >> 6] >> np.uint64(k & 63)) & np.uint64(1)) == 0
    cand[kemp] = True
    if depth > 1:
        for k in range(K):
            if in_s[k] and muhat[k] >= target:
                cand[k] = True
    return at


@njit(inline="always", cache=True)
def removers(comb, has1, has2):
    """Which pulled arms can remove candidates through their failure rate (``has1``) or their
    success rate (``has2``) at all (``comb``: :func:`candidate_set`'s bitsets)."""
    for l in range(comb.shape[0]):
        has1[l] = False
        has2[l] = False
        for w in range(comb.shape[2]):
            if comb[l, 2, w] != np.uint64(0):
                has1[l] = True
            if comb[l, 4, w] != np.uint64(0):
                has2[l] = True


@njit(cache=True)
def draw_states(cdf_rows, kind, trace, lat, xprev, t0, nslots, out):
    """``out[r, j]``: the hidden state of slot t0 + j + 1 of run r (the plain-Python tier's
    path; the same draws as the compiled kernel's, so plug-ins see built-ins' paths)."""
    for r in range(lat.shape[0]):
        st = lat[r]
        xp = xprev[r]
        for j in range(nslots):
            xp = draw_state(cdf_rows, kind, trace, st, xp, t0 + j + 1)
            out[r, j] = xp
        xprev[r] = xp


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=NoAliasCompiler)  # KERNEL
def advance(
    cdf_rows,  # (1 or n + 1, n) float64 CDFs: law of X_1, then transition rows
    kind,  # int: CHANNEL_CDF / CHANNEL_TRACE
    trace,  # (T,) int64 hidden path for CHANNEL_TRACE (else unused)
    Y,  # (K, n) int8 rewards
    comb,  # (K, 8, W) uint64: per pulled arm l, the arms k that fall below the target when
    # it exceeds 0 (bit 0 of the code), l's failure rate (bit 1), l's success rate (bit 2)
    best,  # int: index of the best arm (for the oracle)
    correlated,  # bool: restrict to the correlated candidate set
    aware,  # bool: AoI-aware override
    params,  # (P,) float64 the policy's parameters
    t0,  # int: slots already simulated
    nslots,  # int: slots to simulate now
    lat,  # (R, 4) uint64 latent streams
    pol,  # (R, 4) uint64 policy streams
    ncache,  # (R, 2) float64 scratch pair per run (the `cache` argument of corraoi.rng)
    pstate,  # (R, S) float64 the policy's own state per run
    xprev,  # (R,) int64 previous hidden state (-1 before slot 1)
    pulls,  # (R, K) int64
    succ,  # (R, K) int64
    aoi,  # (R,) int64 current age
    oaoi,  # (R,) int64 oracle's current age
    regret,  # (R,) int64 pathwise regret so far
    aoisum,  # (R,) int64 sum of ages so far
    err,  # (R, 3) int64: a hook's fault (slot, what: 1 arm out of range, 2 NaN score, value)
    record,  # bool: write the per-slot columns below (the slot record's fields but t and
    # estimator, in its order: corraoi.engine.simulation.buffered_fields)
    o_x,  # (R, B) int32
    o_arm,  # (R, B) int32
    o_succ,  # (R, B) bool
    o_aoi,  # (R, B) int64
    o_oaoi,  # (R, B) int64
    o_regret,  # (R, B) int64
    o_override,  # (R, B) bool
    o_muhat,  # (R, B, K) float64
    o_pulls,  # (R, B, K) int64
    o_cand,  # (R, B, K) bool
    o_forced,  # (R, B) bool
    o_thresh,  # (R, B) float32
    o_score,  # (R, B, K) float32
    snap_t,  # (S,) int64 ascending slots in (t0, t0 + nslots] at which to snapshot
    s_regret,  # (R, S) int64 regret at each snapshot slot
    s_aoisum,  # (R, S) int64 sum of ages at each snapshot slot
    s_pulls,  # (R, S, K) int64 pulls at each snapshot slot
):
    R = pulls.shape[0]
    K = pulls.shape[1]
    W = comb.shape[2]
    # which pulled arms can remove candidates through their failure or success rate at all
    has1 = np.empty(K, dtype=np.bool_)  # np.zeros would become a parfor in the sweep kernel
    has2 = np.empty(K, dtype=np.bool_)
    removers(comb, has1, has2)
    for r in range(R):
        lst = lat[r]
        pst = pol[r]
        cache = ncache[r]
        ps = pstate[r]
        npull = pulls[r]
        nsucc = succ[r]
        muhat = np.empty(K)
        vals = np.empty(K)
        cand = np.empty(K, dtype=np.bool_)
        in_s = np.empty(K, dtype=np.bool_)
        fail = np.empty(W, dtype=np.uint64)
        age = aoi[r]
        oage = oaoi[r]
        reg = regret[r]
        asum = aoisum[r]
        xp = xprev[r]
        # a hook's fault: kept in locals while the slots run, written once after them
        f_t = err[r, 0]
        f_what = err[r, 1]
        f_value = err[r, 2]
        si = 0
        nsnap = snap_t.shape[0]
        for j in range(nslots):
            t = t0 + j + 1
            # ---- the hidden state, from the latent stream only (common random numbers)
            x = draw_state(cdf_rows, kind, trace, lst, xp, t)
            xp = x
            # ---- the policy's decision, from the history and the policy stream only
            maxmu = 0.0
            for k in range(K):
                m = nsucc[k] / npull[k] if npull[k] > 0 else 0.0
                muhat[k] = m
                if m > maxmu:
                    maxmu = m
                cand[k] = True
            forced = _forced(t, K, npull, nsucc, params, ps, pst)
            if forced >= K:  # an arm out of range: noted (the engine ends the run at this
                if f_t == 0:  # slot) and never played; the loop goes on unbranched
                    f_t = t
                    f_what = FAULT_ARM
                    f_value = forced
                forced = -1
            if correlated and forced < 0:
                candidate_set(t, K, npull, nsucc, muhat, cand, in_s, fail, comb, has1,
                              has2, pst, 1, -1)  # fmt: skip
            override = aware and maxmu > 0.0 and age * maxmu > 1.0
            if override or forced < 0:
                # one argmax for both (each inlined site costs compile time): the override
                # plays the best empirical mean over every arm, otherwise the best score
                # over the candidates
                if override:
                    for k in range(K):
                        vals[k] = muhat[k]
                        in_s[k] = True
                    mask = in_s
                else:
                    _score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache)
                    mask = cand
                # in range even over NaN scores; a NaN score on a candidate is noted (the
                # engine ends the run here), found by the argmax's own pass
                arm, nan = argmax_random_nan(vals, mask, pst, K)
                if nan < K and not override and f_t == 0:
                    f_t = t
                    f_what = FAULT_NAN
                    f_value = nan
            else:
                arm = forced
            # ---- outcome and ages
            rew = Y[arm, x]
            npull[arm] += 1
            nsucc[arm] += rew
            _update(t, arm, rew, K, npull, nsucc, params, ps)
            age = 1 if rew == 1 else age + 1
            oage = 1 if Y[best, x] == 1 else oage + 1
            reg += age - oage
            asum += age
            # RECORD-BEGIN
            if record:
                o_x[r, j] = x
                o_arm[r, j] = arm
                o_succ[r, j] = rew == 1
                o_aoi[r, j] = age
                o_oaoi[r, j] = oage
                o_regret[r, j] = reg
                o_override[r, j] = override
                # why this arm: forced (the score was not asked), the override's threshold,
                # the scores of the candidates (NaN for the others, and when not scored)
                scored = not override and forced < 0
                o_forced[r, j] = forced >= 0 and not override
                o_thresh[r, j] = 1.0 / maxmu if maxmu > 0.0 else np.inf
                for k in range(K):
                    o_cand[r, j, k] = cand[k]
                    o_pulls[r, j, k] = npull[k]
                    o_muhat[r, j, k] = nsucc[k] / npull[k] if npull[k] > 0 else 0.0
                    o_score[r, j, k] = vals[k] if scored and cand[k] else np.nan
            # RECORD-END
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
        xprev[r] = xp
        err[r, 0] = f_t
        err[r, 1] = f_what
        err[r, 2] = f_value
