"""Paired comparisons of a sweep's policies against a baseline on the same hidden paths.

Every policy of a sweep runs over the same seeds, so run i of each policy sees the same
hidden-state path. The paired difference regret(policy) - regret(baseline), run by run,
has a CI whose width depends on how much the runs' regrets correlate across policies; the
unpaired half-width sqrt(h_policy^2 + h_baseline^2) is reported beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from corraoi.errors import ConfigError
from corraoi.stats import finite, mean_ci95

from .montecarlo import PolicyResult


def paired_diff(policy: np.ndarray, baseline: np.ndarray) -> dict[str, float | None]:
    """Mean and 95% half-widths (paired, unpaired) of policy - baseline, run by run."""
    a = np.asarray(policy, dtype=np.float64)
    b = np.asarray(baseline, dtype=np.float64)
    if a.shape != b.shape:
        raise ConfigError(
            f"paired runs must match: {a.shape[0]} runs against {b.shape[0]} for the baseline"
        )
    mean, half = mean_ci95(a - b)
    _, ha = mean_ci95(a)
    _, hb = mean_ci95(b)
    return {
        "paired_diff_mean": float(mean),
        "paired_diff_ci95": finite(float(half)),
        "unpaired_diff_ci95": finite(math.sqrt(float(ha) ** 2 + float(hb) ** 2)),
    }


def paired_against(results: Sequence[PolicyResult], baseline: str) -> dict[str, dict[str, Any]]:
    """For every policy but ``baseline``: its :func:`paired_diff` of the regret at T."""
    by_name = {r.name: r for r in results}
    if baseline not in by_name:
        raise ConfigError(
            f"--baseline {baseline}: not one of the swept policies "
            f"({', '.join(by_name)}); expected one of them"
        )
    base = by_name[baseline].regret
    return {
        name: paired_diff(r.regret, base) for name, r in by_name.items() if name != baseline
    }


__all__ = ["paired_against", "paired_diff"]
