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
    #: The theorem's own value where ``value`` is the smaller linear bound ("linear (capped)").
    theorem_value: float | None = None

    @property
    def formula(self) -> float | None:
        """The theorem's expression at T (``value`` unless the linear bound was smaller)."""
        return self.theorem_value if self.theorem_value is not None else self.value

    def to_dict(self) -> dict[str, Any]:
        out = {
            "theorem": self.theorem,
            "horizon": self.horizon,
            "value": self.value,
            "regime": self.regime,
            "threshold": self.threshold,
            "note": self.note,
        }
        if self.theorem_value is not None:
            out["theorem_value"] = self.theorem_value
        return out


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


def first_tau(start: float, coef: float, K: int, level: float) -> float:
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


#: B_2, B_4, ..., B_16 over (2j)!: the Euler-Maclaurin coefficients of hurwitz_zeta.
_EM = (1 / 12, -1 / 720, 1 / 30240, -1 / 1209600, 1 / 47900160, -691 / 1307674368000,
       1 / 74724249600, -3617 / 10670622842880000)  # fmt: skip
_EM_SHIFT = 10


def hurwitz_zeta(s: float, q: float) -> float:
    """zeta(s, q) = sum_{k >= 0} (q + k)^-s for s > 1, q >= 1, to double precision.

    Euler-Maclaurin after _EM_SHIFT direct terms: with N = q + 10 >= 11 the first omitted
    term, |B_18 / 18!| s (s+1) ... (s+16) N^(-s-17), is below 1e-16 of N^(1-s) / (s - 1)
    (the leading term) for every s <= 40, and bounds the error (the terms alternate in sign
    and decrease). Hand-written rather than scipy.special.zeta because scipy's import costs
    0.15-0.25 s of every sweep's start-up, and the tests check it against scipy.
    """
    if not s > 1.0 or q < 1.0:
        raise ValueError(f"hurwitz_zeta needs s > 1 and q >= 1, got s={s}, q={q}")
    head = math.fsum((q + k) ** -s for k in range(_EM_SHIFT))
    n = q + _EM_SHIFT
    tail = n ** (1.0 - s) / (s - 1.0) + 0.5 * n**-s
    rising = s  # s (s+1) ... (s+2j-2)
    power = n ** (-s - 1.0)
    for j, coef in enumerate(_EM, start=1):
        tail += coef * rising * power
        rising *= (s + 2 * j - 1) * (s + 2 * j)
        power /= n * n
    return head + tail


def _power_sum(a: float, T: int, power: float, scale: float) -> float:
    """sum_{t = ceil(a)}^{T} (t / scale) ** power for power < -1, exactly: by the Hurwitz zeta
    function, zeta(s, start) - zeta(s, T + 1) with s = -power (increasing in T for every T;
    a direct sum switching to an integral approximation made the bounds fall at T = 1e7)."""
    start = max(int(math.ceil(a)), 1)
    if start > T:
        return 0.0
    s = -float(power)
    total = hurwitz_zeta(s, start) - hurwitz_zeta(s, float(T) + 1.0)
    return max(total, 0.0) * float(scale) ** s


def _exp_sum(T: int, K: int, gap_min: float) -> float:
    """sum_{t=1}^{T} 2 K t q^t with q = exp(-gap_min^2 / (2K)), in closed form."""
    q = math.exp(-(gap_min**2) / (2.0 * K))
    s = q * (1.0 - (T + 1) * q**T + T * q ** (T + 1)) / (1.0 - q) ** 2
    return 2.0 * K * s


def _capped(bound: Bound, linear: float) -> Bound:
    """The smaller of the theorem's value and the linear bound (1/mu_min - 1/mu*) T, which
    holds at every T (saying so when the linear one is smaller)."""
    if bound.value is None or bound.value <= linear:
        return bound
    note = (f"{bound.note}; the theorem gives {bound.value:.6g}, more than the linear bound "
            "(1/mu_min - 1/mu*) T that holds for every T: the smaller is reported")  # fmt: skip
    return Bound(bound.theorem, bound.horizon, linear, "linear (capped)", bound.threshold, note,
                 theorem_value=bound.value)  # fmt: skip


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
    t0 = first_tau(2.0, 4.0, K, level) if level > TIE_TOL else math.inf
    linear = (1.0 / mu_min - 1.0 / th.mu_star) * T
    if not T > t0:
        return Bound("Theorem 2 (CUCB)", T, linear, "linear", t0, _below("t0", t0))
    gap_min = float(min(th.gaps[k] for k in range(K) if k != th.best_arm))
    u_nc = K * t0 + K**3 * 2.0 * _power_sum(K * t0, T, -2.0, K) + 3.0 * _power_sum(1, T, -3.0, 1)
    tail = _exp_sum(T, K, gap_min)
    u_c = {
        k: 8.0 * math.log(T) / th.gaps[k] ** 2 + (1.0 + math.pi**2 / 3.0) + tail
        for k in th.competitive
    }
    return _capped(Bound("Theorem 2 (CUCB)", T, _assemble(th, u_nc, u_c), "log", t0,
                         f"T > t0 = {t0:g}"), linear)  # fmt: skip


def _below(name: str, threshold: float) -> str:
    """The note of a bound below its theorem's threshold: what the number is, and why."""
    return (f"T <= {name} = {threshold:g}: the theorem holds from its threshold {name} on (the "
            "slot from which every gap clears its exploration term); below it, the linear "
            "bound (1/mu_min - 1/mu*) T")


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
    tb = first_tau(math.exp(11.0 * beta), 6.0 * math.sqrt(beta), K, level)
    linear = (1.0 / mu_min - 1.0 / th.mu_star) * T
    if not T > tb:
        return Bound(name, T, linear, "linear", tb, _below("t_b", tb))
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
    return _capped(Bound(name, T, _assemble(th, u_nc, u_c), "log", tb, f"T > t_b = {tb:g}"),
                   linear)  # fmt: skip
