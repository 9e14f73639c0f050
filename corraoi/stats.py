"""Means and 95% confidence intervals over runs, from values or from their moments; a
sweep's points (the aggregates at a checkpoint that the sweep log and its recording store)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

#: The runs of a sweep's cell worth watching, by name: the worst, best and median run by
#: final regret, and in a cell of several sources the run of most collisions.
#: ``corraoi.experiments.notable`` chooses them, the sweep log stores them and its recording
#: draws them apart from the means (``corraoi.recorder.sweeplog.layout``).
CELL_RUNS = ("worst", "best", "median", "most-collisions")

# Student t 0.975 quantiles for 1..30 degrees of freedom.
_T975 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip


def t975(df: int) -> float:
    """Two-sided 95% Student t quantile (table to 30 df, Cornish-Fisher beyond)."""
    if df < 1:
        return math.nan
    if df <= 30:
        return _T975[df - 1]
    z = 1.959963984540054
    return z + (z**3 + z) / (4 * df) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * df**2)


@dataclass(frozen=True)
class Moments:
    """Count, mean and sum of squared deviations (M2) of a value over runs, per checkpoint:
    what a device returns instead of every run's value. Parts merge exactly (Chan, Golub,
    LeVeque 1979), so chunks of runs combine into the moments of all of them."""

    n: int
    mean: np.ndarray
    m2: np.ndarray

    @classmethod
    def of(cls, values: Any, axis: int = 0, *,
           host: Callable[[Any], Any] | None = np.asarray) -> Moments:  # fmt: skip
        """The moments along ``axis`` of a NumPy array, or of a device array (CuPy) reduced on
        its device and brought over by ``host`` (None: left on the device, for the caller to
        bring over later without waiting now)."""
        if not hasattr(values, "__cuda_array_interface__"):
            values = np.asarray(values, dtype=np.float64)
        mean = values.mean(axis=axis)
        at: list[Any] = [slice(None)] * values.ndim
        at[axis] = None
        dev = values - mean[tuple(at)]
        m2 = (dev * dev).sum(axis=axis)
        if host is None:
            return cls(int(values.shape[axis]), mean, m2)
        return cls(int(values.shape[axis]), np.asarray(host(mean)), np.asarray(host(m2)))

    def merge(self, other: Moments) -> Moments:
        n = self.n + other.n
        delta = other.mean - self.mean
        mean = self.mean + delta * (other.n / n)
        m2 = self.m2 + other.m2 + delta * delta * (self.n * other.n / n)
        return Moments(n, mean, m2)

    def ci95(self) -> np.ndarray:
        """The 95% CI half-width of the mean (Student t); NaN for one run."""
        if self.n < 2:
            return np.full_like(np.asarray(self.mean, dtype=np.float64), np.nan)
        return t975(self.n - 1) * np.sqrt(self.m2 / (self.n - 1)) / math.sqrt(self.n)


def finite(v: float) -> float | None:
    """``v``, or None where it is not finite (JSON has no NaN: a CI of one run is None)."""
    return v if math.isfinite(v) else None


def mean_ci95(values: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and 95% CI half-width (Student t) along ``axis``; half-width NaN for one value."""
    m = Moments.of(values, axis=axis)
    return m.mean, m.ci95()


__all__ = ["Moments", "mean_ci95", "t975"]


@dataclass(frozen=True)
class SweepPoint:
    """Aggregates over the runs of one policy at checkpoint slot ``t`` (one row of a curve)."""

    policy: str
    t: int
    regret_mean: float
    regret_ci95: float | None  # half-width; None with a single run
    estimator_mean: float
    estimator_ci95: float | None
    pull_share: np.ndarray  # (K,) mean over runs of pulls_k / t
    #: a cell of several sources: the mean over runs of the collisions up to t (summed over
    #: the sources) and its half-width; None for one source
    collisions_mean: float | None = None
    collisions_ci95: float | None = None

    def to_dict(self) -> dict[str, Any]:
        out = {
            "policy": self.policy,
            "t": self.t,
            "regret_mean": self.regret_mean,
            "regret_ci95": self.regret_ci95,
            "estimator_mean": self.estimator_mean,
            "estimator_ci95": self.estimator_ci95,
            "pull_share": [float(v) for v in self.pull_share],
        }
        if self.collisions_mean is not None:
            out["collisions_mean"] = self.collisions_mean
            out["collisions_ci95"] = self.collisions_ci95
        return out


def sweep_points(
    name: str, t: np.ndarray, regret: Moments, estimator: Moments, pull_share: np.ndarray,
    collisions: Moments | None = None,
) -> list[SweepPoint]:
    """The :class:`SweepPoint` of each checkpoint ``t[i]`` from the moments of the runs' values
    there (:meth:`Moments.of` of runs x checkpoints) and the mean shares ((checkpoints, K));
    ``collisions``: those of a cell of several sources."""
    h, eh = regret.ci95(), estimator.ci95()
    ch = collisions.ci95() if collisions is not None else None
    return [
        SweepPoint(
            policy=name, t=int(ts), regret_mean=float(regret.mean[i]),
            regret_ci95=finite(float(h[i])), estimator_mean=float(estimator.mean[i]),
            estimator_ci95=finite(float(eh[i])), pull_share=pull_share[i],
            collisions_mean=float(collisions.mean[i]) if collisions is not None else None,
            collisions_ci95=finite(float(ch[i])) if ch is not None else None,
        )  # fmt: skip
        for i, ts in enumerate(t)
    ]
