"""Markov hidden states: checking a transition matrix, its stationary law and mixing time.

An instance with a ``transition`` matrix P (n x n, row-stochastic) draws X_1 ~ p and then
X_t from row X_{t-1} (corraoi.model.channels). The chain must be irreducible and aperiodic, so that
the stationary law p is unique, every state is visited, and empirical means converge to
mu_k = sum_x p_x Y[k, x] (the quantities the policies estimate and the regret is measured
against); a reducible or periodic chain is refused with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from corraoi.errors import InstanceError

#: Rows must sum to 1 within this; p must match the stationary law within STATIONARY_TOL.
ROW_TOLERANCE = 1e-9
STATIONARY_TOL = 1e-6
#: Mixing times beyond this many steps are reported as "more than".
MIXING_CAP = 100_000


def check_transition(P: object, n: int | None, where: str) -> np.ndarray:
    """The transition matrix as a read-only float64 array, or one InstanceError naming the
    row: wrong shape, non-finite or negative entries, rows not summing to 1."""
    try:
        rows = np.asarray(P, dtype=np.float64)
    except (TypeError, ValueError):
        raise InstanceError(f"{where}: transition must be a matrix of numbers (n x n)") from None
    if rows.ndim != 2 or rows.shape[0] != rows.shape[1] or rows.shape[0] == 0:
        raise InstanceError(
            f"{where}: transition must be a square n x n matrix, got shape {rows.shape}"
        )
    if n is not None and rows.shape[0] != n:
        raise InstanceError(
            f"{where}: transition is {rows.shape[0]} x {rows.shape[0]}, but there are {n} states"
        )
    for i, row in enumerate(rows):
        if not np.all(np.isfinite(row)):
            raise InstanceError(f"{where}: transition row {i + 1} has a non-finite entry")
        if np.any(row < 0):
            raise InstanceError(
                f"{where}: transition row {i + 1} has a negative entry {float(row.min())!r}"
            )
        total = math.fsum(row)
        if abs(total - 1.0) > ROW_TOLERANCE:
            raise InstanceError(
                f"{where}: transition row {i + 1} sums to {total!r}, expected 1 "
                f"(within {ROW_TOLERANCE:g})"
            )
    out = rows.copy()
    out.setflags(write=False)
    return out


def _reached(adj: np.ndarray, start: int) -> np.ndarray:
    """The states reachable from ``start`` (breadth first over the adjacency matrix)."""
    seen = np.zeros(adj.shape[0], dtype=bool)
    seen[start] = True
    frontier = seen.copy()
    while frontier.any():
        nxt = adj[frontier].any(axis=0) & ~seen
        seen |= nxt
        frontier = nxt
    return seen


def period(P: np.ndarray) -> int:
    """The period of an irreducible chain (gcd of cycle lengths through state 0)."""
    n = P.shape[0]
    adj = P > 0
    level = np.full(n, -1)
    level[0] = 0
    order = [0]
    for i in order:
        for j in np.flatnonzero(adj[i]):
            if level[j] < 0:
                level[j] = level[i] + 1
                order.append(int(j))
    g = 0
    for i in range(n):
        for j in np.flatnonzero(adj[i]):
            g = math.gcd(g, int(level[i] + 1 - level[j]))
    return abs(g) or 1


def check_chain(P: np.ndarray, where: str, names: Sequence[str] | None = None) -> None:
    """InstanceError unless the chain is irreducible and aperiodic (with the reason)."""
    n = P.shape[0]
    label = list(names) if names is not None else [f"x{i + 1}" for i in range(n)]
    adj = P > 0
    # irreducible iff every state is reached from state 1 and reaches it (reversed graph)
    for graph, forward in ((adj, True), (adj.T, False)):
        seen = _reached(graph, 0)
        if not seen.all():
            j = int(np.flatnonzero(~seen)[0])
            a, b = (label[0], label[j]) if forward else (label[j], label[0])
            raise InstanceError(
                f"{where}: the chain is reducible: state {b} cannot be reached from "
                f"state {a} (expected every state to reach every other)"
            )
    d = period(P)
    if d > 1:
        raise InstanceError(
            f"{where}: the chain is periodic with period {d} (expected aperiodic: some state "
            "must be able to return to itself in steps of coprime lengths)"
        )


def stationary(P: np.ndarray) -> np.ndarray:
    """The stationary law pi = pi P of an irreducible chain, the same bits on every machine.

    By the GTH elimination (Grassmann, Taksar and Heyman 1985: state elimination that reads
    only off-diagonal entries, so it never subtracts and a row's diagonal is 1 minus the rest
    of the row, exactly), in arithmetic that no CPU or BLAS can change:

    * up to :data:`EXACT_STATES` states, in exact rational arithmetic on the entries as given
      (``fractions.Fraction`` of each float), each probability then rounded once to the
      nearest float: the Gilbert-Elliott chain's law is 0.75 / 0.25 exactly;
    * beyond, in float64 with every step fixed: elementwise numpy operations (each one
      IEEE-rounded, whatever the SIMD width) and sums by ``math.fsum`` (correctly rounded,
      so independent of summation order), never BLAS or LAPACK.

    p is logged with the run and feeds mu, mu* and the estimator: a least-squares solve
    (LAPACK) gave 0.7500000000000007 or 0.7500000000000006 for the same chain by the CPU's
    kernels (``OPENBLAS_CORETYPE``), and so two logs of one run (docs/model.md).
    """
    n = P.shape[0]
    if n <= EXACT_STATES:
        return np.array(_gth_exact(P), dtype=np.float64)
    return _gth_float(P)


#: Chains of at most this many states get their stationary law in exact arithmetic (at 16
#: states about 20 ms; the exact numbers' size grows with the chain).
EXACT_STATES = 16


def _gth_exact(P: np.ndarray) -> list[float]:
    n = P.shape[0]
    A = [[Fraction(float(v)) for v in row] for row in P]
    for k in range(n - 1, 0, -1):
        # state k eliminated: its mass to the lower states, then the paths through it
        rk = A[k]
        out = sum(rk[:k], Fraction(0))
        for i in range(k):
            aik = A[i][k] / out
            A[i][k] = aik
            if aik:
                row = A[i]
                for j in range(k):
                    if rk[j]:
                        row[j] += aik * rk[j]
    pi = [Fraction(1)] + [Fraction(0)] * (n - 1)
    for k in range(1, n):
        pi[k] = sum((pi[i] * A[i][k] for i in range(k)), Fraction(0))
    total = sum(pi, Fraction(0))
    return [float(v / total) for v in pi]  # Fraction -> float rounds to nearest


def _gth_float(P: np.ndarray) -> np.ndarray:
    A = np.array(P, dtype=np.float64)
    n = A.shape[0]
    for k in range(n - 1, 0, -1):
        A[:k, k] /= math.fsum(A[k, :k])
        A[:k, :k] += np.multiply.outer(A[:k, k], A[k, :k])
    pi = np.zeros(n)
    pi[0] = 1.0
    for k in range(1, n):
        pi[k] = math.fsum(pi[:k] * A[:k, k])
    total = math.fsum(pi)
    out: np.ndarray = pi / total
    return out


@dataclass(frozen=True)
class Mixing:
    """How fast the chain forgets where it started."""

    t_mix: int | None  # steps until max_x TV(P^t(x, .), pi) <= 1/4; None beyond MIXING_CAP
    spectral_gap: float  # 1 - |second largest eigenvalue modulus|

    def describe(self) -> str:
        t = f"{self.t_mix}" if self.t_mix is not None else f"more than {MIXING_CAP}"
        return (
            f"mixing time t_mix(1/4) = {t} steps (the first t with max over starting states of "
            f"the total-variation distance of P^t(x, .) to the stationary law <= 1/4); "
            f"spectral gap {self.spectral_gap:.4g}"
        )


def mixing(P: np.ndarray, pi: np.ndarray) -> Mixing:
    """t_mix(1/4) by doubling then bisection over t (the worst-start distance to pi does not
    increase with t), each P^t by repeated squaring: O(log^2 t) matrix products."""
    eig = np.sort(np.abs(np.linalg.eigvals(P)))[::-1]
    gap = float(1.0 - eig[1]) if eig.size > 1 else 1.0

    def mixed(t: int) -> bool:
        M = np.linalg.matrix_power(P, t)
        return bool(0.5 * np.abs(M - pi[None, :]).sum(axis=1).max() <= 0.25)

    hi = 1
    while not mixed(hi):
        hi *= 2
        if hi > MIXING_CAP:
            return Mixing(None, gap)
    lo = hi // 2  # not mixed at lo (or lo = 0)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if mixed(mid):
            hi = mid
        else:
            lo = mid
    return Mixing(hi, gap)


def gilbert_elliott(*, p_gb: float = 0.1, p_bg: float = 0.3) -> np.ndarray:
    """The two-state Gilbert-Elliott chain: good -> bad w.p. p_gb, bad -> good w.p. p_bg."""
    return np.array([[1.0 - p_gb, p_gb], [p_bg, 1.0 - p_bg]])
