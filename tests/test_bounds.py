"""Theorem 2 and 3 bounds: thresholds, regimes and the cases where they do not apply."""

from __future__ import annotations

import math

import numpy as np

from corraoi.bounds import _first_tau, cts_bound, cucb_bound
from corraoi.instance import Instance, load_instance


def test_t0_is_the_first_slot_meeting_the_condition():
    # I1: min(gap_min = 0.1, non-competitive pseudo-gaps 0.2) = 0.1, K = 4
    t0 = cucb_bound(load_instance("I1"), 10).threshold
    assert t0 is not None

    def ok(t: float) -> bool:
        return 0.1 >= 4 * math.sqrt(8 * math.log(t) / t)

    assert ok(t0) and not ok(t0 - 1)


def test_first_tau_small_case():
    assert _first_tau(2.0, 1e-9, 2, 1.0) == 2.0


def test_i1_linear_below_t0_and_log_above():
    i1 = load_instance("I1")
    b = cucb_bound(i1, 10_000)
    assert b.regime == "linear"
    assert b.value == (1 / 0.2 - 1 / 0.6) * 10_000
    big = cucb_bound(i1, 1_000_000)
    assert big.regime == "log" and big.value is not None and big.value > 0


def test_i2_constant_in_t():
    i2 = load_instance("I2")
    a, b = cucb_bound(i2, 10_000), cucb_bound(i2, 1_000_000)
    assert a.regime == b.regime == "log"
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
