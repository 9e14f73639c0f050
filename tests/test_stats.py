"""The statistics behind every reported interval: Student t quantiles, mean +- 95% CI, and
the per-policy summary figures, against values computed by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from corraoi.engine.simulation import Simulation
from corraoi.experiments.montecarlo import run_policy
from corraoi.stats import mean_ci95, t975
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy


def test_t_quantiles():
    assert t975(1) == 12.706 and t975(4) == 2.776 and t975(30) == 2.042
    # beyond the table: the Cornish-Fisher expansion, within 1e-3 of the exact quantiles
    assert t975(40) == pytest.approx(2.0211, abs=1e-3)
    assert t975(199) == pytest.approx(1.9720, abs=1e-3)
    assert t975(10_000) == pytest.approx(1.9602, abs=1e-3)
    assert math.isnan(t975(0))


def test_mean_ci95_by_hand():
    m, h = mean_ci95(np.array([1.0, 2.0, 3.0, 4.0]))
    sd = math.sqrt(sum((v - 2.5) ** 2 for v in (1, 2, 3, 4)) / 3)  # ddof = 1
    assert m == 2.5
    assert h == pytest.approx(3.182 * sd / 2.0, rel=1e-12)
    m1, h1 = mean_ci95(np.array([7.0]))
    assert m1 == 7.0 and math.isnan(h1)


def test_policy_summary_figures_match_the_simulation():
    inst = load_instance("I1")
    seeds = list(range(9))
    res = run_policy(inst, make_policy("ucb"), seeds=seeds, horizon=700)
    sim = Simulation(inst, make_policy("ucb"), seeds, 700)
    sim.advance(700, record=False)
    s = res.summary()
    assert s["regret_mean"] == float(sim.regret.mean())
    sd = float(np.std(sim.regret, ddof=1))
    assert s["regret_ci95"] == pytest.approx(2.306 * sd / 3.0, rel=1e-12)  # t975(8) = 2.306
    assert s["estimator_mean"] == pytest.approx(float((sim.aoisum - 700 / 0.6).mean()))
    assert s["best_arm_share"] == pytest.approx(float(sim.pulls[:, 1].mean() / 700))
    assert s["pulls_mean"] == [float(v) for v in sim.pulls.mean(axis=0)]
