"""The compiled kernel of many sources: M sources share the channels, R runs, block by block.

Like :mod:`corraoi.engine._kernel`, this file is a template as well as a module:
:mod:`corraoi.engine.kernels` writes a record copy and a sweep copy of it per policy family
into the kernel cache, with the ``HOOKS`` lines pointing at the family's compiled hooks, so
numba inlines the hooks and caches the kernel beside its copy. Why a sibling template and not
a loop over sources inside ``_kernel.advance``: the single-source kernel is the hot path of
every sweep and record, measured to the percent (docs/performance.md); a source axis in it
(arrays (R, M, K), a collision pass per slot) would cost every single-source run, and its
golden decisions are pinned. The shared parts are functions both templates call (inlined):
the hidden state (``draw_state``), the correlated candidate set (``candidate_set``), the
hooks' ``inlined`` wrapper. What is new here is the source axis and the multi-player rules.

One call advances R independent runs by ``nslots`` slots, looping slot -> source over
per-(run, source) state: each source its own counts, ages, policy state and policy stream
(source 1's is the single-source run's policy stream), the hidden state drawn once a slot
from the run's latent stream exactly as the single-source kernel draws it.

Per slot and source (docs/model.md, "Many sources"): the source's empirical means, its
forced arm, candidate set, AoI-aware override and scores as a single-source run of the base
policy computes them (but for the correlated candidate set's target: the M-th best mean of
S_t, the M best of S_t kept; ``candidate_set``'s ``depth``); then the rule picks the
channel:

- ``RULE_RHORAND`` (rhoRand): the source's rank r (uniform in 1..M at the start, drawn again
  uniformly after each collision) picks the r-th best arm: the candidates by score, then the
  other arms by empirical mean; ties uniformly at random. Rank 1 is the base policy's own
  argmax (the same draws), so M = 1 is the base policy exactly;
- ``RULE_MCTOPM`` (MCTopM, Besson & Kaufmann 2018): keep the chosen arm while it is among
  the source's M best (same order, ties by lowest index); otherwise move to one of the M
  best whose index was not above the chosen arm's at the previous choice; after a collision
  a source not seated moves to a uniform one of its M best; a slot without collision seats
  it (a seated source ignores collisions); a forced arm other than its chosen one (a first
  pull the AoI-aware override had put off) unseats it;
- ``RULE_CENTRAL`` (the coordinated baseline): sources pick in order, each the base
  policy's choice among the channels the sources before it left free, so no one collides;
- ``RULE_CHAIRS`` (Musical Chairs, Rosenski, Shamir & Szlak 2016): for the first ``learn``
  slots a uniform channel (its counts learn from it as from any play); then, until seated, a
  uniform one of its M best (as MCTopM ranks them); the first of those plays without a
  collision seats it on that channel for the rest of the run.

A forced arm is played as it is, but for a first pull (UCB's round of every arm), which
among several sources is a uniform arm never pulled (as SMPyBandits' +inf indices tied at
random), and but for the coordinated baseline when a source before took it: then the
least-pulled free channel (ties at random). Then the
collisions: a source delivers iff its channel is ON (Y[k, X_t] = 1) and no other source
picked it. Every source learns its channel's state (collision sensing: its counts add
Y[k, X_t], delivered or not); its age counts deliveries only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from corraoi.engine._kernel import (
    FAULT_ARM,
    FAULT_NAN,
    NoAliasCompiler,  # noqa: F401 - the kernel's decorators name it
    candidate_set,
    draw_state,
    inlined,
    removers,
)
from corraoi.policies.hooks import forced_none as _forced  # HOOKS
from corraoi.policies.hooks import score_none as _score  # HOOKS
from corraoi.policies.hooks import update_none as _update  # HOOKS
from corraoi.rng import argmax_random, integer, uniform

_forced = inlined(_forced)
_score = inlined(_score)
_update = inlined(_update)

RULE_RHORAND, RULE_MCTOPM, RULE_CENTRAL, RULE_CHAIRS = 0, 1, 2, 3


@njit(inline="always", cache=True)
def nth_value(values, tier, n, top, K):
    """The n-th largest (0-based, counting repeats) of ``values`` over the arms in ``tier``
    (``top`` scratch of at least n + 1 entries); the tier must hold more than n arms."""
    c = 0
    for k in range(K):
        if not tier[k]:
            continue
        v = values[k]
        if c <= n:
            i = c
            c += 1
        elif v > top[n]:
            i = n
        else:
            continue
        while i > 0 and top[i - 1] < v:
            top[i] = top[i - 1]
            i -= 1
        top[i] = v
    return top[n]


@njit(inline="always", cache=True)
def uniform_in(mask, pst, K):
    """A uniform arm of ``mask`` (one draw; -1 when empty)."""
    n = 0
    for k in range(K):
        if mask[k]:
            n += 1
    if n == 0:
        return -1
    j = integer(pst, n)
    for k in range(K):
        if mask[k]:
            if j == 0:
                return k
            j -= 1
    return -1


@njit(inline="always", cache=True)
def free_best(vals, mask, muhat, allowed, pst, K, tier1, tier2):
    """The best allowed arm: of ``mask`` by ``vals``, else of the others by ``muhat``; ties
    uniformly at random. With every arm allowed it is ``argmax_random`` itself (the
    single-source kernel's draws)."""
    n1 = 0
    for k in range(K):
        tier1[k] = mask[k] and allowed[k]
        tier2[k] = allowed[k] and not mask[k]
        if tier1[k]:
            n1 += 1
    values = vals
    tier = tier1
    if n1 == 0:
        values = muhat
        tier = tier2
    return argmax_random(values, tier, pst, K)  # one call site: one inlined copy


@njit(inline="always", cache=True)
def equal_at(values, tier, v, pst, K):
    """A uniform arm of ``tier`` whose value is ``v`` (reservoir: a draw per extra tie)."""
    best = -1
    ties = 0
    for k in range(K):
        if tier[k] and values[k] == v:
            ties += 1
            if ties == 1 or uniform(pst) * ties < 1.0:
                best = k
    return best


@njit(inline="always", cache=True)
def rank_pick(vals, mask, n1, muhat, r, pst, K, tier2, top):
    """rhoRand's pick: the arm of rank ``r`` (0-based) in the source's order, the ``n1`` arms
    of ``mask`` by ``vals``, then the others by ``muhat``; ties uniformly at random (rank 0
    is ``argmax_random`` itself: the single-source kernel's draws)."""
    if r == 0 and n1 > 0:
        return argmax_random(vals, mask, pst, K)
    values = vals
    tier = mask
    if r >= n1:
        for k in range(K):
            tier2[k] = not mask[k]
        values = muhat
        tier = tier2
        r = min(r - n1, K - n1 - 1)
    return at_rank(values, tier, r, pst, K, top)


@njit(inline="always", cache=True)
def at_rank(values, tier, r, pst, K, top):
    """A uniform arm of ``tier`` whose value is the r-th largest there (0-based, counting
    repeats): that of an arm with at most r above it and more than r at or above it, found
    by branch-free counts (which the compiler vectorizes); ``nth_value`` for NaNs."""
    v = np.nan
    for a in range(K):
        if not tier[a]:
            continue
        va = values[a]
        gt = 0
        ge = 0
        for k in range(K):
            gt += tier[k] & (values[k] > va)
            ge += tier[k] & (values[k] >= va)
        if gt <= r < ge:
            v = va
            break
    if v != v:
        v = nth_value(values, tier, r, top, K)
    return equal_at(values, tier, v, pst, K)


@njit(inline="always", cache=True)
def above(vals, mask, muhat, a, k):
    """Arm ``k`` ranks above arm ``a`` in the source's order (the candidates by score, then
    the others by mean; ties by lowest index)."""
    if mask[k] != mask[a]:
        return mask[k]
    va = vals[a] if mask[a] else muhat[a]
    vk = vals[k] if mask[k] else muhat[k]
    return vk > va or (vk == va and k < a)


@njit(inline="always", cache=True)
def take_top(values, tier, need, out, top, K):
    """Add to ``out`` the ``need`` arms of ``tier`` with the largest ``values`` (ties by
    lowest index); ``need`` <= the tier's size."""
    if need <= 0:
        return
    v = nth_value(values, tier, need - 1, top, K)
    got = 0
    for k in range(K):
        if tier[k] and values[k] > v:
            out[k] = True
            got += 1
    for k in range(K):
        if got >= need:
            break
        if tier[k] and values[k] == v:
            out[k] = True
            got += 1


@njit(inline="always", cache=True)
def best_m(vals, mask, muhat, M, K, out, tier1, tier2, top):
    """``out``: the M best arms (the candidates by score, then the others by mean; ties by
    lowest index)."""
    n1 = 0
    for k in range(K):
        out[k] = False
        tier1[k] = mask[k]
        tier2[k] = not mask[k]
        n1 += mask[k]
    for second in range(2):  # one call site of take_top: each inlined copy costs compile time
        values = vals
        tier = tier1
        need = min(M, n1)
        if second == 1:
            values = muhat
            tier = tier2
            need = min(M - n1, K - n1)
        take_top(values, tier, need, out, top, K)


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=NoAliasCompiler)  # KERNEL
def advance(
    cdf_rows,  # (1 or n + 1, n) float64 CDFs: law of X_1, then transition rows
    kind,  # int: CHANNEL_CDF / CHANNEL_TRACE
    trace,  # (T,) int64 hidden path for CHANNEL_TRACE (else unused)
    Y,  # (K, n) int8 rewards
    comb,  # (K, 8, W) uint64: the candidate set's bitsets (corraoi.engine._kernel)
    oracle,  # (M,) int64: the channel the orthogonal oracle gives each source
    correlated,  # bool: restrict to the correlated candidate set
    aware,  # bool: AoI-aware override
    rule,  # int: RULE_RHORAND / RULE_MCTOPM / RULE_CENTRAL / RULE_CHAIRS
    learn,  # int: Musical Chairs' learning slots (a uniform channel each); 0 for the others
    params,  # (P,) float64 the policy's parameters
    t0,  # int: slots already simulated
    nslots,  # int: slots to simulate now
    lat,  # (R, 4) uint64 latent streams (one per run: the hidden path)
    pol,  # (R, M, 4) uint64 policy streams, one per source
    ncache,  # (R, M, 2) float64 scratch pair per source
    pstate,  # (R, M, S) float64 the policy's own state per source
    xprev,  # (R,) int64 previous hidden state (-1 before slot 1)
    pulls,  # (R, M, K) int64
    succ,  # (R, M, K) int64: the channel ON when the source played it (sensed)
    rank,  # (R, M) int64: rhoRand's rank - 1, MCTopM's and Musical Chairs' arm (-1: none)
    seated,  # (R, M) bool: MCTopM's and Musical Chairs' chair
    worst,  # (R, M, K) bool: MCTopM's arms not above the chosen one at its last choice
    aoi,  # (R, M) int64 current age
    oaoi,  # (R, M) int64 oracle's current age
    regret,  # (R, M) int64 pathwise regret so far
    aoisum,  # (R, M) int64 sum of ages so far
    coll,  # (R, M) int64 collisions so far
    err,  # (R, 3) int64: a hook's fault (slot, what: 1 arm out of range, 2 NaN score, value)
    record,  # bool: write the per-slot columns below
    o_x,  # (R, B) int32
    o_arm,  # (R, M, B) int32
    o_succ,  # (R, M, B) bool: delivered
    o_coll,  # (R, M, B) bool
    o_aoi,  # (R, M, B) int64
    o_oaoi,  # (R, M, B) int64
    o_regret,  # (R, M, B) int64
    o_override,  # (R, M, B) bool
    o_muhat,  # (R, M, B, K) float64
    o_pulls,  # (R, M, B, K) int64
    o_cand,  # (R, M, B, K) bool
    o_forced,  # (R, M, B) bool
    o_thresh,  # (R, M, B) float32
    o_score,  # (R, M, B, K) float32
):
    R = pulls.shape[0]
    M = pulls.shape[1]
    K = pulls.shape[2]
    W = comb.shape[2]
    has1 = np.empty(K, dtype=np.bool_)
    has2 = np.empty(K, dtype=np.bool_)
    removers(comb, has1, has2)
    for r in range(R):
        lst = lat[r]
        muhat = np.empty(K)
        vals = np.empty(K)
        negp = np.empty(K)
        cand = np.empty(K, dtype=np.bool_)
        in_s = np.empty(K, dtype=np.bool_)
        allowed = np.empty(K, dtype=np.bool_)
        tier1 = np.empty(K, dtype=np.bool_)
        tier2 = np.empty(K, dtype=np.bool_)
        pick = np.empty(K, dtype=np.bool_)
        top = np.empty(K)
        fail = np.empty(W, dtype=np.uint64)
        arms = np.empty(M, dtype=np.int64)
        taken = np.empty(K, dtype=np.int64)  # np.zeros would become a parfor (the sweep
        mbest = np.empty(K, dtype=np.bool_)  # kernel's decorator): each is set before use
        byscore = np.empty(M, dtype=np.bool_)
        target = np.empty(M, dtype=np.int64)  # the arm of each source's depth-M target
        for m in range(M):  # (candidate_set's hint; any arm gives the same target)
            target[m] = -1
        xp = xprev[r]
        for j in range(nslots):
            t = t0 + j + 1
            # ---- the hidden state, from the run's latent stream only (one for every source)
            x = draw_state(cdf_rows, kind, trace, lst, xp, t)
            xp = x
            for k in range(K):
                taken[k] = 0
                allowed[k] = True
            # ---- each source's decision, from its own history and policy stream only
            for m in range(M):
                pst = pol[r, m]
                cache = ncache[r, m]
                ps = pstate[r, m]
                npull = pulls[r, m]
                nsucc = succ[r, m]
                if t == 1 and rule == RULE_RHORAND:
                    rank[r, m] = integer(pst, M) if M > 1 else 0
                maxmu = 0.0
                for k in range(K):
                    mu = nsucc[k] / npull[k] if npull[k] > 0 else 0.0
                    muhat[k] = mu
                    if mu > maxmu:
                        maxmu = mu
                    cand[k] = True
                forced = _forced(t, K, npull, nsucc, params, ps, pst)
                if forced >= K:  # out of range: noted, never played (as _kernel does)
                    if err[r, 0] == 0:
                        err[r, 0] = t
                        err[r, 1] = FAULT_ARM
                        err[r, 2] = forced
                    forced = -1
                if M > 1 and forced >= 0 and npull[forced] == 0:
                    # a first pull (UCB's round of every arm): among several sources, a
                    # uniform arm never pulled, as +inf indices tied at random would give
                    for k in range(K):
                        pick[k] = npull[k] == 0
                    forced = uniform_in(pick, pst, K)
                if correlated and forced < 0:
                    target[m] = candidate_set(t, K, npull, nsucc, muhat, cand, in_s, fail,
                                              comb, has1, has2, pst, M, target[m])  # fmt: skip
                override = aware and maxmu > 0.0 and aoi[r, m] * maxmu > 1.0
                scored = False
                if rule == RULE_CHAIRS and (t <= learn or seated[r, m]):
                    # learning: a uniform channel; seated: its chair, for good
                    arm = rank[r, m] if seated[r, m] else integer(pst, K)
                    override = False
                    forced = -1
                    byscore[m] = False
                elif override or forced < 0:
                    if override:
                        for k in range(K):
                            vals[k] = muhat[k]
                            in_s[k] = True
                        mask = in_s
                    else:
                        _score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache)
                        mask = cand
                        scored = True
                        nan = K
                        for k in range(K):
                            if cand[k] and vals[k] != vals[k] and k < nan:
                                nan = k
                        if nan < K and err[r, 0] == 0:
                            err[r, 0] = t
                            err[r, 1] = FAULT_NAN
                            err[r, 2] = nan
                    full = override or not correlated  # every arm in mask
                    if rule == RULE_RHORAND:
                        n1 = K
                        if not full:
                            n1 = 0
                            for k in range(K):
                                n1 += mask[k]
                        rk = rank[r, m]
                        arm = -1
                        if rk > 0 and j > 0 and mask[arms[m]] == (rk < n1):
                            # the arm it played last slot, if it is the only one of rank
                            # rk now (what rank_pick would take, with no draw): one pass
                            a = arms[m]
                            inm = rk < n1
                            want = rk if inm else min(rk - n1, K - n1 - 1)
                            va = vals[a] if inm else muhat[a]
                            gt = 0
                            eq = 0
                            for k in range(K):
                                vk = vals[k] if inm else muhat[k]
                                same = mask[k] == inm
                                gt += same & (vk > va)
                                eq += same & (vk == va)
                            if gt == want and eq == 1:
                                arm = a
                        if arm < 0:
                            arm = rank_pick(vals, mask, n1, muhat, rk, pst, K, tier2, top)
                    elif rule == RULE_CENTRAL:
                        arm = free_best(vals, mask, muhat, allowed, pst, K, tier1, tier2)
                    else:  # MCTopM, or Musical Chairs not seated yet
                        chosen = rank[r, m] if rule == RULE_MCTOPM else -2
                        moved = True
                        if chosen == -1:  # its first choice: the base policy's
                            chosen = argmax_random(vals, mask, pst, K)
                        elif chosen >= 0:  # is its chosen arm still among its M best?
                            nbetter = 0
                            if full:  # by score alone
                                va = vals[chosen]
                                for k in range(K):
                                    up = vals[k] > va or (vals[k] == va and k < chosen)
                                    if up:
                                        nbetter += 1
                                    pick[k] = not up
                            else:
                                for k in range(K):
                                    up = above(vals, mask, muhat, chosen, k)
                                    if up:
                                        nbetter += 1
                                    pick[k] = not up
                            if nbetter < M:  # it stays; pick: the arms not above it
                                moved = False
                                for k in range(K):
                                    worst[r, m, k] = pick[k]
                            else:  # it left them
                                seated[r, m] = False
                                chosen = -3
                        if chosen < -1:
                            # -2: it collided unseated (or sits on no chair yet): a uniform
                            # one of its M best; -3: it left them: one of them not above it
                            # last time, else any (one call of each helper: each inlined
                            # copy costs seconds of compile time)
                            best_m(vals, mask, muhat, M, K, mbest, tier1, tier2, top)
                            some = False
                            for k in range(K):
                                pick[k] = mbest[k] and (chosen == -2 or worst[r, m, k])
                                some |= pick[k]
                            if not some:
                                for k in range(K):
                                    pick[k] = mbest[k]
                            chosen = uniform_in(pick, pst, K)
                        if rule == RULE_MCTOPM:
                            if moved:  # the arms not above the new choice, for its next move
                                for k in range(K):
                                    worst[r, m, k] = not above(vals, mask, muhat, chosen, k)
                            rank[r, m] = chosen
                        arm = chosen
                    byscore[m] = True
                elif rule == RULE_CENTRAL and taken[forced] > 0:
                    for k in range(K):  # its forced arm is taken: the least-pulled free one
                        negp[k] = -npull[k]
                    arm = argmax_random(negp, allowed, pst, K)
                    byscore[m] = False
                else:
                    arm = forced
                    byscore[m] = False
                    if rule == RULE_MCTOPM:
                        if rank[r, m] != forced:  # a forced move leaves its seat: seated
                            seated[r, m] = False  # elsewhere, two sources could share one
                        rank[r, m] = forced
                arms[m] = arm
                taken[arm] += 1
                if rule == RULE_CENTRAL:
                    allowed[arm] = False
                # RECORD-BEGIN
                if record:
                    o_override[r, m, j] = override
                    o_forced[r, m, j] = forced >= 0 and not override
                    o_thresh[r, m, j] = 1.0 / maxmu if maxmu > 0.0 else np.inf
                    for k in range(K):
                        o_cand[r, m, j, k] = cand[k]
                        o_score[r, m, j, k] = vals[k] if scored and cand[k] else np.nan
                # RECORD-END
            # ---- collisions, deliveries, what each source learns, ages
            for m in range(M):
                arm = arms[m]
                npull = pulls[r, m]
                nsucc = succ[r, m]
                sensed = Y[arm, x]
                hit = taken[arm] > 1
                npull[arm] += 1
                nsucc[arm] += sensed
                _update(t, arm, sensed, K, npull, nsucc, params, pstate[r, m])
                if hit:
                    coll[r, m] += 1
                    if rule == RULE_RHORAND and M > 1:
                        rank[r, m] = integer(pol[r, m], M)
                    elif rule == RULE_MCTOPM and not seated[r, m]:
                        rank[r, m] = -2 if byscore[m] else -1  # moves at its next choice
                elif (rule == RULE_MCTOPM or rule == RULE_CHAIRS) and byscore[m]:
                    seated[r, m] = True  # Musical Chairs' chair: byscore only when unseated
                    if rule == RULE_CHAIRS:
                        rank[r, m] = arm
                age = 1 if sensed == 1 and not hit else aoi[r, m] + 1
                oage = 1 if Y[oracle[m], x] == 1 else oaoi[r, m] + 1
                aoi[r, m] = age
                oaoi[r, m] = oage
                regret[r, m] += age - oage
                aoisum[r, m] += age
                # RECORD-BEGIN
                if record:
                    o_arm[r, m, j] = arm
                    o_succ[r, m, j] = sensed == 1 and not hit
                    o_coll[r, m, j] = hit
                    o_aoi[r, m, j] = age
                    o_oaoi[r, m, j] = oage
                    o_regret[r, m, j] = regret[r, m]
                    for k in range(K):
                        o_pulls[r, m, j, k] = npull[k]
                        o_muhat[r, m, j, k] = nsucc[k] / npull[k] if npull[k] > 0 else 0.0
                # RECORD-END
            # RECORD-BEGIN
            if record:
                o_x[r, j] = x
            # RECORD-END
        xprev[r] = xp
