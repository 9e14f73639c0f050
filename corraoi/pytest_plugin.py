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

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import pytest


@pytest.fixture
def corraoi_run(tmp_path: Path) -> Callable[..., Any]:
    """``corraoi_run(policy="cucb", *, seed=0, horizon=1000, instance="I1", params=None,
    channel=None) -> corraoi.Run``.

    Records one run with :func:`corraoi.record` into a fresh slot log under the test's
    ``tmp_path`` (no Rerun recording) and returns the :class:`corraoi.Run`, which is also
    the log's path (``os.fspath(run)``); each call writes a new file. ``policy`` is anything
    :func:`corraoi.record` takes, a class defined in the test module included. Its arguments
    are :func:`corraoi.record`'s, checked there before anything runs (the errors it raises).
    """
    count = 0

    def record(
        policy: Any = "cucb",
        *,
        seed: int = 0,
        horizon: int = 1000,
        instance: Any = "I1",
        params: Mapping[str, Any] | None = None,
        channel: str | None = None,
    ) -> Any:
        nonlocal count
        from corraoi.face.recording import record as record_run

        count += 1
        return record_run(
            policy, instance, seed=seed, horizon=horizon, params=params, channel=channel,
            path=tmp_path / "corraoi-runs" / f"{{label}}-{count}.mcap", rrd=False,
        )  # fmt: skip

    return record
