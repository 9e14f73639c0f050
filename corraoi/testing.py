"""Helpers for your own test suites: record a run, and assert that two runs are equal.

``assert_runs_equal(a, b)`` compares two slot logs with :func:`viewer.diff` and raises an
AssertionError that names the first differing slot, the field and both values, and how
far the divergence goes. :func:`record_run` records one run into an MCAP slot log (what
the ``corraoi_run`` pytest fixture calls). Everything heavy is imported inside the
functions, so importing this module costs nothing.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def record_run(
    path: str | os.PathLike[str],
    *,
    policy: str = "cucb",
    seed: int = 0,
    horizon: int = 1000,
    instance: str = "I1",
    overwrite: bool = False,
) -> Path:
    """Simulate one run and record it to the slot log ``path`` (as ``corraoi record``)."""
    from recorder.mcap_sink import McapSink

    from .block import RunConfig
    from .engine import check_instance, simulate_run
    from .instance import load_instance
    from .policies import make_policy

    inst = load_instance(instance)
    check_instance(inst)
    config = RunConfig(inst, make_policy(policy), seed, horizon)
    with McapSink(path, config, overwrite=overwrite, fsync=False) as sink:
        for block in simulate_run(inst, config.policy, seed, horizon):
            sink.write(block)
    return sink.path


def _log(run: Any) -> Any:
    """A RunLog for a path, a RunLog, or a loaded run (``corraoi.load`` of a slot log)."""
    log = getattr(run, "log", None)
    return log if log is not None else run


def assert_runs_equal(a: Any, b: Any, *, fields: Sequence[str] | None = None) -> None:
    """Assert that two recorded runs are equal slot by slot (``fields``: default all).

    ``a`` and ``b`` are paths of slot logs, opened ``RunLog`` objects or runs loaded with
    ``corraoi.load``. Runs whose configurations differ (other than the corraoi version) or
    whose slot counts differ are not equal either.
    """
    from viewer.diffs import diff

    report = diff(_log(a), _log(b), fields=fields)
    if report.identical:
        return
    lines = []
    first = report.first_divergence
    if first is not None:
        slot, name = first
        f = report.fields[name]
        lines.append(
            f"runs differ from slot {slot}: field {name} is {f.a_value!r} in a and "
            f"{f.b_value!r} in b"
        )
        spread = [
            f"{n}: {d.slots_differing} of {d.compared} slots differ (first at slot "
            f"{d.first_slot})"
            for n, d in report.fields.items()
            if d.slots_differing and d.first_slot is not None
        ]
        lines.append("divergence: " + "; ".join(spread))
    if report.config:
        diffs = ", ".join(f"{d.key} ({d.a!r} != {d.b!r})" for d in report.config)
        lines.append(f"configurations differ: {diffs}")
    if not report.same_slots:
        lines.append(f"slot counts differ: a has {report.a_slots}, b has {report.b_slots}")
    lines.append("")
    lines.append(report.message())
    raise AssertionError("\n".join(lines))


__all__ = ["assert_runs_equal", "record_run"]
