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
    from .block import RunConfig
    from .engine import check_instance
    from .experiments import record_run
    from .instance import load_instance
    from .policies import make_policy

    inst = load_instance(instance)
    check_instance(inst)
    config = RunConfig(inst, make_policy(policy), seed, horizon)
    return record_run(config, path, overwrite=overwrite).mcap


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


def check_policy(
    policy: str,
    *,
    params: dict[str, float] | None = None,
    arms: Sequence[int] = (2, 3, 8, 64),
    horizon: int = 300,
    runs: int = 4,
    seed: int = 0,
    tmp_path: str | os.PathLike[str] | None = None,
) -> None:
    """The conformance check a plug-in author runs in their own tests (raises AssertionError).

    ``policy`` is what ``--policy`` takes (``"my_policy.py:MyPolicy"``, ``"pkg.mod:Cls"``, a
    built-in name). On random instances with each number of ``arms`` it checks that the
    policy

    * is deterministic for a seed (two simulations are equal slot by slot),
    * plays arms in range, with pulls, successes, ages and regret consistent with them,
    * decides each run from that run's own stream (run i of a batch equals the single run
      with seed ``seed + i``: vectorised code that mixes runs fails here),
    * sees the hidden path built-ins see on the same seed,
    * round-trips through a slot log (written and read back equal), when ``tmp_path`` is given.
    """
    import numpy as np

    from .block import RunConfig
    from .engine import simulate
    from .instance import Instance
    from .policies import make_policies

    spec = make_policies([policy], params or {})[0]
    reference = make_policies(["ucb"])[0]
    for K in arms:
        rng = np.random.default_rng([seed, K])
        n = max(2, K)
        p = rng.dirichlet(np.ones(n))
        Y = (rng.random((K, n)) < 0.5).astype(np.int64)
        Y[int(rng.integers(K)), int(np.argmax(p))] = 1  # some arm has a positive mean
        inst = Instance(f"check-K{K}", p, Y)
        seeds = list(range(seed, seed + runs))
        blocks = list(simulate(inst, spec, seeds, horizon, block=horizon))
        again = list(simulate(inst, spec, seeds, horizon, block=max(1, horizon // 3)))
        a, b = blocks[0], type(blocks[0]).concat(again)
        for f in ("x", "arm", "success", "aoi", "regret", "pulls", "candidates", "override"):
            assert np.array_equal(a.column(f), b.column(f)), (
                f"{policy} (K={K}): not deterministic for seed {seed}: field {f} differs "
                "between two simulations (or between block sizes)"
            )
        assert a.arm.min() >= 0 and a.arm.max() < K, f"{policy} (K={K}): arm out of range"
        assert np.array_equal(a.success, inst.Y[a.arm, a.x] == 1), f"{policy}: wrong successes"
        assert np.array_equal(a.pulls[:, -1].sum(axis=1), np.full(runs, horizon)), (
            f"{policy} (K={K}): pulls do not add up to the horizon"
        )
        single = next(simulate(inst, spec, [seeds[-1]], horizon, block=horizon))
        assert np.array_equal(single.arm[0], a.arm[-1]), (
            f"{policy} (K={K}): run {runs - 1} of a batch differs from the single run with "
            f"seed {seeds[-1]}: decisions must use each run's own stream (state.rng) only"
        )
        ref = next(simulate(inst, reference, seeds, horizon, block=horizon))
        assert np.array_equal(ref.x, a.x), f"{policy} (K={K}): not the built-ins' hidden path"
        if tmp_path is not None:
            from recorder.mcap_sink import McapSink
            from recorder.reader import open_log

            path = Path(tmp_path) / f"check-{spec.name}-K{K}.mcap"
            config = RunConfig(inst, spec, seeds[0], horizon)
            with McapSink(path, config, overwrite=True, fsync=False) as sink:
                sink.write(a.run(0))
            log = open_log(path)
            assert log.config.policy == spec, f"{policy}: the log does not describe the policy"
            assert log.read_all().equals(a.run(0)), f"{policy} (K={K}): log round-trip differs"
