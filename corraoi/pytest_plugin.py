"""The ``corraoi_run`` pytest fixture, registered through the ``pytest11`` entry point.

Installing corraoi makes the fixture available in every test suite; this module imports
only pytest and the standard library, and the engine, the recorder and numba are imported
when a test first calls the fixture::

    def test_cucb_is_reproducible(corraoi_run):
        from corraoi.testing import assert_runs_equal

        a = corraoi_run(policy="cucb", seed=3, horizon=2000)
        b = corraoi_run(policy="cucb", seed=3, horizon=2000)
        assert_runs_equal(a, b)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest


@pytest.fixture
def corraoi_run(tmp_path: Path) -> Callable[..., Path]:
    """``corraoi_run(policy="cucb", seed=0, horizon=1000, instance="I1") -> Path``.

    Records one run into a fresh slot log under the test's ``tmp_path`` and returns its
    path; each call writes a new file.
    """
    count = 0

    def record(
        policy: str = "cucb", *, seed: int = 0, horizon: int = 1000, instance: str = "I1"
    ) -> Path:
        nonlocal count
        from .testing import record_run

        count += 1
        name = f"{policy}-{Path(instance).stem}-s{seed}-{count}.mcap"
        return record_run(
            tmp_path / "corraoi-runs" / name,
            policy=policy, seed=seed, horizon=horizon, instance=instance,
        )  # fmt: skip

    return record
