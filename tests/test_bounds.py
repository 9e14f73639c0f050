"""Theorem 2 and 3 bounds: thresholds, regimes and the cases where they do not apply."""

from __future__ import annotations

import math

import numpy as np
import pytest

from corraoi.model.bounds import cts_bound, cucb_bound, first_tau
from corraoi.model.instance import Instance, load_instance


def test_t0_is_the_first_slot_meeting_the_condition():
    # I1: min(gap_min = 0.1, non-competitive pseudo-gaps 0.2) = 0.1, K = 4
    t0 = cucb_bound(load_instance("I1"), 10).threshold
    assert t0 is not None

    def ok(t: float) -> bool:
        return 0.1 >= 4 * math.sqrt(8 * math.log(t) / t)

    assert ok(t0) and not ok(t0 - 1)


def test_first_tau_small_case():
    assert first_tau(2.0, 1e-9, 2, 1.0) == 2.0


def test_i1_linear_below_t0_and_log_above():
    i1 = load_instance("I1")
    b = cucb_bound(i1, 10_000)
    assert b.regime == "linear"
    assert b.value == (1 / 0.2 - 1 / 0.6) * 10_000
    big = cucb_bound(i1, 1_000_000)  # the theorem's value is above the linear one here
    assert big.regime == "linear (capped)" and big.value == (1 / 0.2 - 1 / 0.6) * 1_000_000
    huge = cucb_bound(i1, 10**9)
    assert huge.regime == "log" and huge.value is not None
    assert huge.value < (1 / 0.2 - 1 / 0.6) * 1e9


def test_i2_constant_in_t():
    i2 = load_instance("I2")
    a, b = cucb_bound(i2, 10_000), cucb_bound(i2, 1_000_000)
    assert a.regime == "linear (capped)" and b.regime == "log"  # the linear bound is smaller at 1e4
    a, b = cucb_bound(i2, 100_000), cucb_bound(i2, 1_000_000)
    assert a.value is not None and b.value is not None
    # C = 0: O(1); only the vanishing sums grow
    assert 0 < b.value - a.value < 1e-3 * a.value


def test_cts_needs_beta_above_one_and_big_horizon():
    i2 = load_instance("I2")
    assert cts_bound(i2, 10_000, beta=1.0).value is None
    b = cts_bound(i2, 10_000, beta=2.0)
    assert b.regime == "linear"  # t_b >= exp(22)
    assert b.threshold is not None and b.threshold >= math.exp(22)


def test_not_applicable_cases():
    tie = Instance("tie", np.array([0.5, 0.5]), np.array([[1, 0], [0, 1], [0, 0]]))
    b = cucb_bound(tie, 100)
    assert b.value is None and "tie for the best mean" in b.note
    same = Instance("same", np.array([0.5, 0.5]), np.array([[1, 0], [1, 0]]))
    assert "regret is 0" in cucb_bound(same, 100).note
    zero = Instance("zero", np.array([0.5, 0.5]), np.array([[1, 0], [0, 0]]))
    assert "mean 0" in cts_bound(zero, 100).note


def _zeta3(T: int) -> float:
    t = np.arange(1, T + 1, dtype=float)
    return float(np.sum(t**-3.0))


def test_i2_cucb_bound_by_hand():
    # C = 0: R <= (1-mu*)/(mu* mu_min) + (1/mu_min - 1/mu*) sum_k gap_k U_nc, with
    # U_nc = K t0 + K^3 sum_{t=K t0}^{T} 2 (t/K)^-2 + sum_t 3 t^-3; K t0 > T empties the
    # middle sum. mu* = .8, mu_min = .1, gaps of arms 1-3: .7 + .6 + .7 = 2.0.
    b = cucb_bound(load_instance("I2"), 10_000)
    t0 = b.threshold
    assert t0 == 2826
    expected = 0.2 / 0.08 + (10 - 1.25) * 2.0 * (4 * t0 + 3 * _zeta3(10_000))
    assert b.formula == pytest.approx(expected, rel=1e-12)
    assert b.formula == pytest.approx(197885.6, abs=0.1)
    assert b.value == (1 / 0.1 - 1 / 0.8) * 10_000  # and the smaller linear bound is reported


def test_i1_cucb_bound_log_regime_by_hand():
    # C = 1 (arm 3, gap .1); non-competitive arms 1, 4 (gaps .4 each); K = 4
    T = 1_000_000
    b = cucb_bound(load_instance("I1"), T)
    t0 = b.threshold
    assert t0 is not None and b.regime == "linear (capped)"
    t = np.arange(1, T + 1, dtype=float)
    mid = np.arange(4 * t0, T + 1, dtype=float)
    u_nc = 4 * t0 + 4**3 * np.sum(2 * (mid / 4) ** -2.0) + np.sum(3 * t**-3.0)
    tail = np.sum(2 * 4 * t * np.exp(-t * 0.1**2 / (2 * 4)))
    u_c = 8 * math.log(T) / 0.1**2 + (1 + math.pi**2 / 3) + tail
    pre = 1 / 0.2 - 1 / 0.6
    expected = (1 - 0.6) / (0.6 * 0.2) + pre * (0.4 * u_nc + 0.4 * u_nc + 0.1 * u_c)
    assert b.formula == pytest.approx(expected, rel=1e-9)


def test_i2_cts_bound_log_regime_by_hand():
    # beta = 1.01: t_b = max(e^(11 beta), the gap condition) and K t_b > T empties the sums
    T = 100_000
    b = cts_bound(load_instance("I2"), T, beta=1.01)
    tb = b.threshold
    assert b.regime in ("log", "linear (capped)") and tb is not None
    assert tb == math.ceil(math.exp(11 * 1.01))
    expected = 2.5 + 8.75 * 2.0 * (4 * tb + 3 * _zeta3(T))
    assert b.formula == pytest.approx(expected, rel=1e-12)
    assert b.value == pytest.approx(min(expected, 8.75 * T), rel=1e-12)


# ---------------------------------------------------------------------------- exact power sums


def test_hurwitz_zeta_is_exact():
    from corraoi.model.bounds import hurwitz_zeta

    # against a direct sum plus its integral tail bounds, and against scipy when installed
    for s in (1.5, 2.0, 3.0, 7.0):
        for q in (1.0, 3.0, 1000.0):
            direct = math.fsum((q + k) ** -s for k in range(200_000))
            lo = direct + (q + 200_000) ** (1 - s) / (s - 1)  # tail >= integral from q+N
            hi = direct + (q + 199_999) ** (1 - s) / (s - 1)
            assert lo * (1 - 1e-14) <= hurwitz_zeta(s, q) <= hi * (1 + 1e-14), (s, q)
    special = pytest.importorskip("scipy.special")
    for s in (1.01, 2.0, 3.0, 11.0, 39.0):
        for q in (1.0, 2.0, 7.5, 1e6, 1e12):
            assert hurwitz_zeta(s, q) == pytest.approx(float(special.zeta(s, q)), rel=1e-14)
    assert hurwitz_zeta(2.0, 1.0) == pytest.approx(math.pi**2 / 6, rel=1e-15)


@pytest.mark.parametrize("name", ["I1", "I2"])
def test_bounds_are_monotone_in_t_from_1e3_to_1e12(name: str):
    inst = load_instance(name)
    horizons = sorted({int(v) for v in np.geomspace(1e3, 1e12, 300)} | {10**7, 10**7 + 10})
    for bound in (lambda T: cucb_bound(inst, T), lambda T: cts_bound(inst, T, 2.0)):
        values = [bound(T).value for T in horizons]
        assert all(v is not None for v in values)
        assert all(b >= a for a, b in zip(values, values[1:], strict=False)), name
    # the case of the report: I2's CUCB bound fell from T = 1e7 to 1e7 + 10
    assert cucb_bound(inst, 10**7 + 10).value >= cucb_bound(inst, 10**7).value  # type: ignore[operator]


def test_a_bound_above_the_linear_one_is_capped_and_says_so():
    inst = load_instance("I1")
    b = cucb_bound(inst, 10**6)
    linear = (1 / 0.2 - 1 / 0.6) * 10**6
    assert b.value == pytest.approx(linear) and b.regime == "linear (capped)"
    assert "the smaller is reported" in b.note
    assert cucb_bound(inst, 10**9).regime == "log"


def test_bound_texts_are_clean():
    from corraoi.experiments.summary import bound_text

    assert bound_text({"value": None, "theorem": "Theorem 3 (CTS)", "regime": "n/a",
                       "note": "stated for beta > 1"}) == "n/a: stated for beta > 1"  # fmt: skip
    assert bound_text({"value": 1234.5, "theorem": "Theorem 2 (CUCB)", "regime": "log",
                       "note": ""}) == "1234 (Theorem 2 (CUCB); log)"  # fmt: skip
