"""Upper bounds on the expected AoI regret: Theorem 2 (CUCB) and Theorem 3 (CTS) of the paper.

Both have the form of the paper's Lemma 4 with the expected sub-optimal pulls of Lemmas 5
and 6 substituted::

    R(T) <= (1 - mu*) / (mu* mu_min)
            + (1/mu_min - 1/mu*) (sum_{k not competitive} gap_k U_nc + sum_{k in C} gap_k U_c(k))

for T past a threshold (t0 for CUCB, t_b for CTS); below it the linear bound
(1/mu_min - 1/mu*) T holds. The threshold conditions ask that the smallest gap and the
pseudo-gaps of the non-competitive arms are at least 4 sqrt(2K log tau / tau) (CUCB) or
6 sqrt(2K beta log tau / tau) (CTS).

Theorem 3 is stated for CTS with Gaussian priors and beta > 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .instance import Instance
from .theory import TIE_TOL, InstanceTheory, analyse

#: beta used for Theorem 3 when none is given (the theorem needs beta > 1).
DEFAULT_BOUND_BETA = 2.0


@dataclass(frozen=True)
class Bound:
    """A bound at one horizon. ``value`` is None where the theorem does not apply."""

    theorem: str
    horizon: int
    value: float | None
    regime: str  # "log" (T past the threshold), "linear" (T at or below it) or "n/a"
    threshold: float | None  # t0 or t_b
    note: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "theorem": self.theorem,
            "horizon": self.horizon,
            "value": self.value,
            "regime": self.regime,
            "threshold": self.threshold,
            "note": self.note,
        }


def _not_applicable(th: InstanceTheory, mu_min: float, inst: Instance) -> str | None:
    if not inst.is_iid:
        return "the theorems assume i.i.d. hidden states; this instance is a Markov chain"
    if len(th.best_tied) > 1:
        arms = ", ".join(str(a + 1) for a in th.best_tied)
        if len(th.best_tied) == th.mu.size:
            return "every arm has the same mean: every policy is optimal, the regret is 0 in mean"
        return f"arms {arms} tie for the best mean (the theorems need a unique best arm)"
    if mu_min <= 0:
        return "an arm has mean 0 (its AoI grows without bound; the bound is infinite)"
    return None


def _threshold(th: InstanceTheory) -> float:
    """min(gap_min, pseudo-gaps of the non-competitive sub-optimal arms)."""
    sub = [k for k in range(th.mu.size) if k != th.best_arm]
    gap_min = min(th.gaps[k] for k in sub)
    nc = [th.pseudo_gap[k] for k in sub if k not in th.competitive]
    return float(min([gap_min, *nc]))


def _first_tau(start: float, coef: float, K: int, level: float) -> float:
    """inf{tau >= start : level >= coef sqrt(2K log tau / tau)} (tau/log tau increases)."""
    tau = max(start, 2.0)

    def ok(t: float) -> bool:
        return level >= coef * math.sqrt(2.0 * K * math.log(t) / t)

    first = float(math.ceil(tau))
    if ok(first):  # log(t)/t rises up to e and falls after: the first integer is the inf
        return first
    lo = max(first, math.e)
    hi = lo
    while not ok(hi):
        hi *= 2.0
        if hi > 1e300:
            return math.inf
    while hi - lo > 0.5:
        mid = (lo + hi) / 2.0
        if ok(mid):
            hi = mid
        else:
            lo = mid
    return float(math.ceil(hi))


def _power_sum(a: float, T: int, power: float, scale: float) -> float:
    """sum_{t = ceil(a)}^{T} (t / scale) ** power, exactly for T up to 1e7, else by integral."""
    start = max(int(math.ceil(a)), 1)
    if start > T:
        return 0.0
    if T - start < 10_000_000:
        t = np.arange(start, T + 1, dtype=np.float64)
        return float(np.sum((t / scale) ** power))
    # Euler-Maclaurin to first order beyond 1e7 terms
    f = lambda t: (t / scale) ** power  # noqa: E731
    if abs(power + 1.0) < 1e-12:
        integral = scale * math.log(T / start)
    else:
        integral = (
            scale * ((T / scale) ** (power + 1) - (start / scale) ** (power + 1)) / (power + 1)
        )
    return integral + (f(start) + f(T)) / 2.0


def _exp_sum(T: int, K: int, gap_min: float) -> float:
    """sum_{t=1}^{T} 2 K t q^t with q = exp(-gap_min^2 / (2K)), in closed form."""
    q = math.exp(-(gap_min**2) / (2.0 * K))
    s = q * (1.0 - (T + 1) * q**T + T * q ** (T + 1)) / (1.0 - q) ** 2
    return 2.0 * K * s


def _assemble(th: InstanceTheory, u_nc: float, u_c: dict[int, float]) -> float:
    mu_star = th.mu_star
    mu_min = float(th.mu.min())
    pre = 1.0 / mu_min - 1.0 / mu_star
    total = 0.0
    for k in range(th.mu.size):
        if k == th.best_arm:
            continue
        total += th.gaps[k] * (u_c[k] if k in th.competitive else u_nc)
    return float((1.0 - mu_star) / (mu_star * mu_min) + pre * total)


def cucb_bound(inst: Instance, horizon: int) -> Bound:
    """Theorem 2: the CUCB bound at ``horizon``."""
    th = analyse(inst)
    mu_min = float(th.mu.min())
    why = _not_applicable(th, mu_min, inst)
    if why:
        return Bound("Theorem 2 (CUCB)", horizon, None, "n/a", None, why)
    K = inst.K
    T = int(horizon)
    level = _threshold(th)
    t0 = _first_tau(2.0, 4.0, K, level) if level > TIE_TOL else math.inf
    linear = (1.0 / mu_min - 1.0 / th.mu_star) * T
    if not T > t0:
        return Bound("Theorem 2 (CUCB)", T, linear, "linear", t0, f"T <= t0 = {t0:g}")
    gap_min = float(min(th.gaps[k] for k in range(K) if k != th.best_arm))
    u_nc = K * t0 + K**3 * 2.0 * _power_sum(K * t0, T, -2.0, K) + 3.0 * _power_sum(1, T, -3.0, 1)
    tail = _exp_sum(T, K, gap_min)
    u_c = {
        k: 8.0 * math.log(T) / th.gaps[k] ** 2 + (1.0 + math.pi**2 / 3.0) + tail
        for k in th.competitive
    }
    return Bound("Theorem 2 (CUCB)", T, _assemble(th, u_nc, u_c), "log", t0, f"T > t0 = {t0:g}")


def cts_bound(inst: Instance, horizon: int, beta: float = DEFAULT_BOUND_BETA) -> Bound:
    """Theorem 3: the CTS (Gaussian priors, beta > 1) bound at ``horizon``."""
    th = analyse(inst)
    name = f"Theorem 3 (CTS, beta={beta:g})"
    mu_min = float(th.mu.min())
    why = _not_applicable(th, mu_min, inst)
    if why:
        return Bound(name, horizon, None, "n/a", None, why)
    if not beta > 1.0:
        return Bound(name, horizon, None, "n/a", None, f"Theorem 3 needs beta > 1, got {beta:g}")
    K = inst.K
    T = int(horizon)
    level = _threshold(th)
    tb = _first_tau(math.exp(11.0 * beta), 6.0 * math.sqrt(beta), K, level)
    linear = (1.0 / mu_min - 1.0 / th.mu_star) * T
    if not T > tb:
        return Bound(name, T, linear, "linear", tb, f"T <= t_b = {tb:g}")
    gap_min = float(min(th.gaps[k] for k in range(K) if k != th.best_arm))
    u_nc = (
        K * tb
        + 3.0 * _power_sum(1, T, -3.0, 1)
        + K**2
        * (
            (2 * K + 3) * _power_sum(K * tb, T, -2.0, K)
            + _power_sum(K * tb, T, 1.0 - 2.0 * beta, K)
        )
    )
    tail = _exp_sum(T, K, gap_min)
    u_c = {
        k: 18.0 * math.log(T * th.gaps[k] ** 2) / th.gaps[k] ** 2
        + math.exp(11.0 * beta)
        + 9.0 / th.gaps[k] ** 2
        + tail
        for k in th.competitive
    }
    return Bound(name, T, _assemble(th, u_nc, u_c), "log", tb, f"T > t_b = {tb:g}")
