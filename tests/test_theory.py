"""Exact theory values (design.md section 2) for the built-ins and edge cases."""

from __future__ import annotations

import numpy as np
import pytest

from corraoi.model.instance import Instance, load_instance
from corraoi.model.theory import analyse, policy_pseudo_rewards, pseudo_reward_table


def test_i1_exact():
    th = analyse(load_instance("I1"))
    np.testing.assert_allclose(th.mu, [0.2, 0.6, 0.5, 0.2], atol=1e-12)
    assert th.best_arm == 1
    np.testing.assert_allclose(th.gaps, [0.4, 0.0, 0.1, 0.4], atol=1e-12)
    np.testing.assert_allclose(th.phi[[0, 2, 3]], [0.4, 1.0, 0.4], atol=1e-12)
    np.testing.assert_allclose(th.pseudo_gap[[0, 2, 3]], [0.2, -0.4, 0.2], atol=1e-12)
    assert th.competitive == (2,)
    assert th.strictly_competitive == (2,)
    assert th.C == 1
    d = th.to_dict()
    assert d["best_arm"] == 2 and d["competitive"] == [3] and d["C"] == 1
    assert d["phi"][0] == 0.4 and d["phi"][2] == 1.0 and d["phi"][3] == 0.4


def test_i2_exact():
    th = analyse(load_instance("I2"))
    np.testing.assert_allclose(th.mu, [0.1, 0.2, 0.1, 0.8], atol=1e-12)
    assert th.best_arm == 3
    assert th.competitive == () and th.C == 0
    np.testing.assert_allclose(th.phi[:3], [0.2, 0.2, 0.2], atol=1e-12)


def test_pseudo_rewards_i1():
    s = pseudo_reward_table(load_instance("I1"))
    # s_{3,2}(r): arm 2 gives 0 in states 1, 4 -> arm 3 there is 0, 1 -> max 1
    assert s[2, 1, 0] == 1.0 and s[2, 1, 1] == 1.0
    # s_{1,2}(1): arm 2 gives 1 in states 2, 3 -> arm 1 is 0 there
    assert s[0, 1, 1] == 0.0 and s[0, 1, 0] == 1.0
    # s_{k,k}(r) = r
    for k in range(4):
        assert s[k, k, 0] == 0.0 and s[k, k, 1] == 1.0


def test_zero_probability_state_is_outside_the_support():
    # state 3 never happens; with it, arm 2's zero-reward would unlock arm 1's reward 1
    inst = Instance("z", np.array([0.5, 0.5, 0.0]), np.array([[0, 0, 1], [1, 0, 0]]))
    s = pseudo_reward_table(inst)
    assert s[0, 1, 0] == 0.0  # theory: only states 1, 2 count
    assert policy_pseudo_rewards(inst)[0, 1, 0] == 1.0  # the policy does not know p


def test_best_arm_tie_lowest_index_and_reported():
    inst = Instance("tie", np.array([0.5, 0.5]), np.array([[1, 0], [0, 1], [0, 0]]))
    th = analyse(inst)
    assert th.best_arm == 0
    assert th.best_tied == (0, 1)
    assert th.to_dict()["best_arm_tied_with"] == [2]


@pytest.mark.parametrize("name", ["I1", "I2"])
def test_phi_of_best_arm_is_its_mean(name: str):
    th = analyse(load_instance(name))
    assert th.phi[th.best_arm] == pytest.approx(th.mu_star)
