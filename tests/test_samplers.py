"""Thompson sampling: the samplers' moments and the decisions they drive.

The conformance check (tests/reference.py) can only say that a TS arm was a candidate;
these tests pin the distributions: a wrong prior, variance or gamma step turns them red.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from corraoi import rng
from corraoi.engine.simulation import Simulation
from corraoi.model.instance import Instance
from corraoi.policies import make_policy
from corraoi.rng import streams_for_seed

N = 40_000


def draws(fn, *args) -> np.ndarray:  # type: ignore[no-untyped-def]
    st = streams_for_seed(123)[1]
    cache = np.zeros(2)
    return np.array([fn(st, cache, *args) for _ in range(N)])


def test_normal_moments():
    z = draws(rng.normal)
    assert abs(z.mean()) < 5 / np.sqrt(N)
    assert z.var() == pytest.approx(1.0, abs=0.03)
    assert np.mean(np.abs(z) < 1.0) == pytest.approx(0.6827, abs=0.01)


@pytest.mark.parametrize("shape", [1.0, 2.0, 7.0])
def test_gamma_moments(shape: float):
    g = draws(rng.gamma, shape)
    assert g.mean() == pytest.approx(shape, abs=5 * np.sqrt(shape / N))
    assert g.var() == pytest.approx(shape, rel=0.05)


@pytest.mark.parametrize(("a", "b"), [(1.0, 1.0), (3.0, 5.0), (20.0, 2.0)])
def test_beta_moments(a: float, b: float):
    x = draws(rng.beta, a, b)
    mean = a / (a + b)
    var = a * b / ((a + b) ** 2 * (a + b + 1))
    assert x.mean() == pytest.approx(mean, abs=5 * np.sqrt(var / N))
    assert x.var() == pytest.approx(var, rel=0.05)
    assert 0.0 < x.min() and x.max() < 1.0


TWO = Instance("two", np.array([0.5, 0.5]), np.array([[1, 0], [0, 1]]))


def next_choice(policy: str, **params: float) -> float:
    """Share of runs choosing arm 1 at slot 3 after arm 1 succeeded once and arm 2 failed."""
    runs = 6000
    sim = Simulation(TWO, make_policy(policy, **params), list(range(runs)), 3)
    sim.pulls[:] = [1, 1]
    sim.succ[:] = [1, 0]
    sim.t = 2
    blk = sim.advance(1)
    assert blk is not None
    return float((blk.arm[:, 0] == 0).mean())


def test_ts_beta_decision_probability():
    # Beta(2, 1) against Beta(1, 2): P(first is larger) = 5/6
    assert next_choice("ts") == pytest.approx(5 / 6, abs=0.02)


def test_ts_gauss_decision_probability():
    # N(1, beta/2) against N(0, beta/2): P(first is larger) = Phi(1 / sqrt(beta))
    assert next_choice("ts-gauss") == pytest.approx(0.8413, abs=0.02)
    assert next_choice("ts-gauss", beta=4.0) == pytest.approx(0.6915, abs=0.02)


@njit
def _normals(st: np.ndarray, n: int) -> np.ndarray:
    cache = np.zeros(2)
    out = np.empty(n)
    for i in range(n):
        out[i] = rng.normal(st, cache)
    return out


def test_ziggurat_layers_have_equal_areas():
    k, w, f, r = rng.ziggurat_tables()
    x = w * float(1 << 52)
    assert x[1] == r and f[256] == 1.0 and k[255] == 0  # the top layer always takes the wedge
    base = r * f[1] + math.sqrt(math.pi / 2) * math.erfc(r / math.sqrt(2))  # base + tail
    areas = x[1:256] * (f[2:257] - f[1:256])
    assert areas == pytest.approx(np.full(255, base), rel=1e-9)


def test_ziggurat_normal_matches_the_normal_law_in_the_body_the_wedges_and_the_tail():
    n = 2_000_000
    z = _normals(streams_for_seed(5)[1], n)
    # the body, the layers' wedges (any x) and the tail beyond R = 3.654 (Marsaglia's method)
    for q in (-4.0, -3.7, -3.0, -2.0, -1.0, -0.3, 0.0, 0.3, 1.0, 2.0, 3.0, 3.7, 4.0):
        p = 0.5 * math.erfc(-q / math.sqrt(2))
        se = math.sqrt(p * (1 - p) / n)
        assert abs(np.mean(z < q) - p) < 5 * se + 1e-7, q
    assert np.mean(z**4) == pytest.approx(3.0, abs=0.03)
    # the 52-bit magnitude and the sign bit are independent of the layer: no value repeats
    assert np.unique(z[:100_000]).size == 100_000


def test_the_ziggurat_is_the_same_bits_whatever_the_c_library(monkeypatch):
    """The normal sampler's layers are computed with correctly rounded exp and log, not the
    C library's (within an ulp, its last bit differs between libraries and CPUs): a libm one
    ulp off changes nothing, and the tables the sampler uses are those layers."""
    import base64

    want = rng.ziggurat_layers()
    monkeypatch.setattr(math, "exp", lambda x: math.nextafter(np.exp(x), math.inf))
    monkeypatch.setattr(math, "log", lambda x: math.nextafter(np.log(x), -math.inf))
    assert np.array_equal(rng.ziggurat_layers(), want)
    held = np.frombuffer(base64.b64decode(rng.ZIGGURAT_LAYERS), dtype="<f8").reshape(2, 257)
    assert np.array_equal(held, want)
    _, w, f, r = rng.ziggurat_tables()
    assert np.array_equal(w * float(1 << 52), want[0, :256]) and np.array_equal(f, want[1])
