"""Helpers for your own test suites: assert that two runs are equal, and check a policy.

``assert_runs_equal(a, b)`` compares two recorded runs with :func:`corraoi.diff` and raises
an AssertionError that names the first differing slot, the field and both values, and how
far the divergence goes. :func:`check_policy` is a policy's conformance check (as
scikit-learn's ``check_estimator``, it takes the class itself, or any word ``--policy``
takes): the named ``check_*`` functions of :data:`CHECKS` on the cases of
:func:`policy_cases`, or one test per check with :func:`parametrize_with_checks`. Runs are
recorded with :func:`corraoi.record` (the ``corraoi_run`` pytest fixture calls it).
Everything heavy is imported inside the functions, so importing this module costs nothing.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any


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
    from corraoi.viewer.diffs import diff

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


__all__ = [
    "CHECKS",
    "PolicyCase",
    "assert_runs_equal",
    "check_arms_in_range",
    "check_counts_follow_the_arms",
    "check_deterministic",
    "check_hidden_path",
    "check_log_round_trip",
    "check_policy",
    "check_runs_use_their_own_streams",
    "parametrize_with_checks",
    "policy_cases",
]


# ---------------------------------------------------------------------------- conformance


@dataclass
class PolicyCase:
    """One policy on one random instance (with ``sources`` sharing its channels): what each
    ``check_*`` function examines. The batch of runs is simulated once, on first use, and
    shared by the checks of the case."""

    policy: Any
    spec: Any
    instance: Any
    seeds: list[int]
    horizon: int
    sources: int = 1

    def __str__(self) -> str:  # the pytest id: eps-greedy-K3 (selfish-ucb-K8-M3)
        return f"{self.spec.name}-K{self.instance.K}" + (
            f"-M{self.sources}" if self.sources > 1 else "")

    @property
    def name(self) -> str:
        return str(self.spec.name)

    @cached_property
    def batch(self) -> Any:
        """Every run of the case in one block (``RunsBlock``; with several sources, a row per
        run and source: run r's source m is row ``r * sources + m - 1``)."""
        return self.simulate(self.seeds, block=self.horizon)

    def simulate(self, seeds: Sequence[int], *, block: int) -> Any:
        """The runs of ``seeds``, simulated ``block`` slots at a time, as one ``RunsBlock``
        (rows as :attr:`batch`'s)."""
        from corraoi.engine.simulation import RunsBlock, simulate

        if self.sources == 1:
            return RunsBlock.concat(list(simulate(self.instance, self.spec, seeds,
                                                  self.horizon, block=block)))  # fmt: skip
        import numpy as np

        from corraoi.engine.block import SlotBlock
        from corraoi.engine.sources import SourcesSimulation

        sim = SourcesSimulation(self.instance, self.spec, seeds, self.horizon, self.sources)
        parts = []
        while (part := sim.advance(block)) is not None:
            parts.append(part)
        rows = [SlotBlock.concat([p[r][m] for p in parts])
                for r in range(len(seeds)) for m in range(self.sources)]  # fmt: skip
        columns: dict[str, Any] = {f: np.stack([b.column(f) for b in rows])
                                   for f in rows[0].fields() if f != "t"}  # fmt: skip
        return RunsBlock(t=rows[0].t, **columns)

    def where(self) -> str:
        what = self.policy if isinstance(self.policy, str) else self.name
        return f"{what} (K={self.instance.K}" + (
            f", {self.sources} sources)" if self.sources > 1 else ")")


def policy_cases(
    policy: Any,
    *,
    params: dict[str, float] | None = None,
    arms: Sequence[int] = (2, 3, 8, 64),
    horizon: int = 300,
    runs: int = 4,
    seed: int = 0,
    sources: int = 1,
) -> list[PolicyCase]:
    """``policy`` (a class, an instance of one, or what ``--policy`` takes) with ``params`` on
    one random instance per number of ``arms`` (some arm always has a positive mean), run by
    ``sources`` sources (the numbers of arms below it are left out: M sources need M
    channels)."""
    import numpy as np

    from corraoi import arguments, limits
    from corraoi.errors import ConfigError, InstanceError, PolicyError
    from corraoi.face.resolve import policies
    from corraoi.model.instance import Instance

    # the arguments checked before anything is done (corraoi.arguments)
    if isinstance(arms, (str, bytes)) or not isinstance(arms, Sequence):
        raise arguments.wrong_type(InstanceError, "arms", arms, "a list of numbers of arms")
    if not arms:
        raise arguments.wrong_value(InstanceError, "arms", arms, "at least one number of arms",
                                    "empty")  # fmt: skip
    arms = [arguments.integer(K, name=f"arms[{i}]", lo=2, kind=InstanceError,
                              why="an instance has at least 2 arms")
            for i, K in enumerate(arms)]  # fmt: skip
    horizon = limits.check_horizon(horizon, floats=True)
    runs = limits.check_int(runs, name="runs", lo=1, hi=limits.MAX_RUNS, floats=True)
    seed = limits.check_seed(seed, runs=runs, floats=True)
    sources = arguments.integer(sources, name="sources", lo=1, kind=ConfigError,
                                why="sources share the channels: 1 or more")  # fmt: skip
    if max(arms) < sources:
        raise arguments.wrong_value(InstanceError, "arms", arms,
                                    f"a number of arms of at least sources ({sources})",
                                    "every one is smaller")  # fmt: skip
    if isinstance(policy, (list, tuple)):
        raise arguments.wrong_type(PolicyError, "policy", policy, "one policy")
    spec = policies(policy, params)[0]
    if sources > 1:
        from corraoi.policies.spec import check_sources

        check_sources(spec, sources, spec.resolve())
    cases = []
    for K in (K for K in arms if K >= sources):
        rng = np.random.default_rng([seed, K])
        n = max(2, K)
        p = rng.dirichlet(np.ones(n))
        Y = (rng.random((K, n)) < 0.5).astype(np.int64)
        Y[int(rng.integers(K)), int(np.argmax(p))] = 1
        inst = Instance(f"check-K{K}", p, Y)
        cases.append(PolicyCase(policy, spec, inst, list(range(seed, seed + runs)), horizon,
                                sources))  # fmt: skip
    return cases


def check_deterministic(case: PolicyCase, tmp_path: Any = None) -> None:
    """Two simulations of the same seeds are equal slot by slot, whatever the block size."""
    import numpy as np

    again = case.simulate(case.seeds, block=max(1, case.horizon // 3))
    assert case.batch.fields() == again.fields(), f"{case.where()}: fields differ"
    for f in case.batch.fields():  # every field of the slot record the run logs
        nan = case.batch.column(f).dtype.kind == "f"
        assert np.array_equal(case.batch.column(f), again.column(f), equal_nan=nan), (
            f"{case.where()}: not deterministic for seed {case.seeds[0]}: field {f} differs "
            "between two simulations (or between block sizes)"
        )


def check_arms_in_range(case: PolicyCase, tmp_path: Any = None) -> None:
    """Every arm played is one of the instance's."""
    a = case.batch
    assert a.arm.min() >= 0 and a.arm.max() < case.instance.K, f"{case.where()}: arm out of range"


def check_counts_follow_the_arms(case: PolicyCase, tmp_path: Any = None) -> None:
    """Successes follow the table Y on the hidden state (and, with several sources, no
    collision); pulls add up to the slots."""
    import numpy as np

    a, inst = case.batch, case.instance
    on = inst.Y[a.arm, a.x] == 1
    delivered = on if a.collided is None else on & ~a.collided
    assert np.array_equal(a.success, delivered), f"{case.where()}: wrong successes"
    rows = len(case.seeds) * case.sources
    assert np.array_equal(a.pulls[:, -1].sum(axis=1), np.full(rows, case.horizon)), (
        f"{case.where()}: pulls do not add up to the horizon"
    )


def check_runs_use_their_own_streams(case: PolicyCase, tmp_path: Any = None) -> None:
    """Run i of a batch equals the single run with seed ``seeds[i]`` (vectorised code that
    mixes runs fails here)."""
    import numpy as np

    last = case.seeds[-1]
    single = case.simulate([last], block=case.horizon)
    assert np.array_equal(single.arm, case.batch.arm[-case.sources:]), (
        f"{case.where()}: run {len(case.seeds) - 1} of a batch differs from the single run "
        f"with seed {last}: decisions must use each run's own stream (state.rng) only"
    )


def check_hidden_path(case: PolicyCase, tmp_path: Any = None) -> None:
    """The policy sees the hidden path the built-ins see on the same seeds."""
    import numpy as np

    from corraoi.engine.simulation import simulate

    from .policies import make_policies

    ref = next(simulate(case.instance, make_policies(["ucb"])[0], case.seeds, case.horizon,
                        block=case.horizon))  # fmt: skip
    assert np.array_equal(np.repeat(ref.x, case.sources, axis=0), case.batch.x), (
        f"{case.where()}: not the built-ins' hidden path")


def check_log_round_trip(case: PolicyCase, tmp_path: Any = None) -> None:
    """A run written to a slot log in ``tmp_path`` reads back equal and names the policy
    (nothing to do without ``tmp_path``)."""
    if tmp_path is None:
        return
    from corraoi.engine.block import RunConfig, SourcesBlock
    from corraoi.recorder.slotlog.reader import open_log
    from corraoi.recorder.slotlog.sink import McapSink

    path = Path(tmp_path) / f"check-{case}.mcap"
    config = RunConfig(case.instance, case.spec, case.seeds[0], case.horizon,
                       sources=case.sources)  # fmt: skip
    run: Any = case.batch.run(0)
    if case.sources > 1:
        run = SourcesBlock(tuple(case.batch.run(m) for m in range(case.sources)))
    with McapSink(path, config, overwrite=True, fsync=False) as sink:
        sink.write(run)
    log = open_log(path)
    assert log.config.policy == case.spec, f"{case.name}: the log does not describe the policy"
    assert log.read_all().equals(run), f"{case.where()}: log round-trip differs"


#: Every conformance check, in the order :func:`check_policy` runs them.
CHECKS = (check_deterministic, check_arms_in_range, check_counts_follow_the_arms,
          check_runs_use_their_own_streams, check_hidden_path, check_log_round_trip)  # fmt: skip


def parametrize_with_checks(policies: Sequence[Any], **options: Any) -> Any:
    """A ``pytest.mark.parametrize`` over every check of every case of ``policies`` (the
    ``options`` of :func:`policy_cases`), one test each with a readable id
    (``eps-greedy-K3-runs_use_their_own_streams``)::

        @parametrize_with_checks(["eps_greedy.py:EpsilonGreedy"])
        def test_my_policy(case, check, tmp_path):
            check(case, tmp_path)
    """
    import pytest

    if isinstance(policies, str) or not isinstance(policies, Sequence):  # one, never letters
        policies = [policies]
    items = [(case, check) for p in policies for case in policy_cases(p, **options)
             for check in CHECKS]  # fmt: skip
    ids = [f"{case}-{check.__name__.removeprefix('check_')}" for case, check in items]
    return pytest.mark.parametrize(("case", "check"), items, ids=ids)


def check_policy(
    policy: Any,
    *,
    params: dict[str, float] | None = None,
    arms: Sequence[int] = (2, 3, 8, 64),
    horizon: int = 300,
    runs: int = 4,
    seed: int = 0,
    sources: int = 1,
    tmp_path: str | os.PathLike[str] | None = None,
) -> None:
    """The conformance check a plug-in author runs in their own tests (raises AssertionError):
    every check of :data:`CHECKS` on every case of :func:`policy_cases`.

    ``policy`` is the class itself (or an instance of it), or what ``--policy`` takes
    (``"my_policy.py:MyPolicy"``, ``"pkg.mod:Cls"``, a built-in name); ``params`` its
    parameters (``{name: value}``; a parameter it does not declare is refused). On random
    instances with each number of ``arms`` it checks that the
    policy is deterministic for a seed; plays arms in range, with successes and pulls
    consistent with them; decides each run from that run's own stream (run i of a batch
    equals the single run with seed ``seed + i``); sees the hidden path built-ins see on the
    same seed; and round-trips through a slot log, when ``tmp_path`` is given. With
    ``sources`` M > 1 (a policy of many sources) it checks the same of every source, on the
    instances of at least M arms, and that a source delivers only without a collision. One
    test per check, with readable ids: :func:`parametrize_with_checks`.

    Raises the errors of :func:`corraoi.record` for arguments that are not accepted
    (:class:`~corraoi.errors.PolicyError`, ``ConfigError``, ``InstanceError`` for ``arms``,
    ``OutputError`` for ``tmp_path``), before anything runs; AssertionError for a check
    that fails.
    """
    from corraoi import arguments

    arguments.optional(arguments.path, tmp_path, name="tmp_path", what="a folder's path")
    for case in policy_cases(policy, params=params, arms=arms, horizon=horizon, runs=runs,
                             seed=seed, sources=sources):  # fmt: skip
        for check in CHECKS:
            check(case, tmp_path)
