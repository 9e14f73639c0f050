"""Monte Carlo sweeps: every policy over the same paired seeds, summarised with 95% CIs."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi.engine.simulation import Simulation, Snapshot
from corraoi.errors import ConfigError
from corraoi.model.channels import Channel
from corraoi.model.instance import Instance
from corraoi.policies import PolicySpec
from corraoi.stats import Moments, SweepPoint, finite, mean_ci95, sweep_points


@dataclass
class PolicyResult:
    """Final figures of one policy over all runs of a sweep.

    ``pulls`` (R, K) per run, or only what the summary needs: ``best_pulls`` (R,) and
    ``pulls_mean`` (K,) (a grid's cells keep sums of pulls, not every run's). ``label``
    names the policy in tables (a policy swept over several parameter values gets one each).
    """

    policy: PolicySpec
    regret: np.ndarray  # (R,) pathwise regret at T
    estimator: np.ndarray  # (R,) sum(aoi) - T / mu*
    pulls: np.ndarray | None  # (R, K)
    best_arm: int
    wall_s: float
    label: str = ""
    best_pulls: np.ndarray | None = None  # (R,)
    pulls_mean: np.ndarray | None = None  # (K,)
    horizon: int = 0
    #: several sources sharing the channels: each run's regret per source (R, M) and its
    #: collisions summed over the sources (R,); ``regret`` is the total (None: one source)
    regret_by_source: np.ndarray | None = None
    collisions: np.ndarray | None = None

    @property
    def name(self) -> str:
        return self.label or self.policy.name

    def summary(self) -> dict[str, Any]:
        m, h = mean_ci95(self.regret)
        em, eh = mean_ci95(self.estimator)
        if self.pulls is not None:
            share = float((self.pulls[:, self.best_arm] / self.pulls.sum(axis=1)).mean())
            means = self.pulls.mean(axis=0)
        else:
            assert self.best_pulls is not None and self.pulls_mean is not None
            share = float((self.best_pulls / self.horizon).mean())
            means = self.pulls_mean
        out: dict[str, Any] = {
            "regret_mean": float(m),
            "regret_ci95": finite(float(h)),
            "estimator_mean": float(em),
            "estimator_ci95": finite(float(eh)),
            "best_arm_share": share,
            "pulls_mean": [float(v) for v in means],
            "wall_s": round(self.wall_s, 4),
        }
        if self.regret_by_source is not None and self.collisions is not None:
            cm, ch = mean_ci95(self.collisions)
            out["sources"] = int(self.regret_by_source.shape[1])
            out["regret_by_source_mean"] = [float(v) for v in self.regret_by_source.mean(axis=0)]
            out["collisions_mean"] = float(cm)
            out["collisions_ci95"] = finite(float(ch))
        return out


#: Called at each checkpoint with (policy, the runs' state there); T is always one.
CheckpointHook = Callable[[PolicySpec, Snapshot], None]

#: A policy's horizon is simulated in about this many compiled calls, so that checkpoints
#: stream out (and the progress bar moves) while a long sweep runs.
SEGMENTS = 10


def checkpoint_point(policy: PolicySpec, snap: Snapshot) -> SweepPoint:
    """The :class:`SweepPoint` of the runs' state at a checkpoint."""
    share = (snap.pulls / snap.t).mean(axis=0)[None]
    points = sweep_points(policy.name, np.array([snap.t]), Moments.of(snap.regret[:, None]),
                          Moments.of(snap.estimator[:, None]), share)  # fmt: skip
    return points[0]


def default_checkpoints(horizon: int, points: int = 200) -> list[int]:
    """About ``points`` checkpoint slots: half evenly spaced, half log-spaced, plus T."""
    even = np.linspace(0, horizon, points // 2 + 1)[1:]
    logs = np.geomspace(1, horizon, points // 2)
    return sorted({int(round(v)) for v in np.concatenate([even, logs])} | {horizon})


def run_policy(
    instance: Instance,
    policy: PolicySpec,
    *,
    seeds: Sequence[int],
    horizon: int,
    checkpoints: Sequence[int] = (),
    on_checkpoint: CheckpointHook | None = None,
    on_slots: Callable[[int], None] | None = None,
    channel: Channel | None = None,
    first_run: int = 0,
) -> PolicyResult:
    """Simulate ``policy`` for every seed to ``horizon`` without keeping per-slot columns
    (``first_run``: the number a failure gives the first seed's run, in a sweep's chunk)."""
    start = time.perf_counter()
    sim = Simulation(instance, policy, seeds, horizon, channel=channel, first_run=first_run)
    stops = sorted({int(c) for c in checkpoints if 0 < c <= horizon} | {horizon})
    ends = np.unique(np.linspace(0, horizon, SEGMENTS + 1).round().astype(np.int64)[1:])
    for end in ends:
        before = sim.t
        snaps = sim.advance_to(int(end), snapshots=stops)
        if on_slots is not None:
            on_slots(int(end) - before)
        if on_checkpoint is not None:
            for snap in snaps:
                on_checkpoint(policy, snap)
    return PolicyResult(
        policy=policy,
        regret=sim.regret.astype(np.float64),
        estimator=sim.estimator.astype(np.float64),
        pulls=sim.pulls.copy(),
        best_arm=sim.best,
        wall_s=time.perf_counter() - start,
    )


def run_sweep(
    instance: Instance,
    policies: Sequence[PolicySpec],
    *,
    runs: int,
    horizon: int,
    seed: int = 0,
    checkpoints: Sequence[int] = (),
    on_checkpoint: CheckpointHook | None = None,
    on_slots: Callable[[int], None] | None = None,
    channel: Channel | None = None,
) -> list[PolicyResult]:
    """Every policy over the same seeds ``seed .. seed + runs - 1`` (paired runs)."""
    if runs < 1:
        raise ConfigError(f"runs must be >= 1, got {runs}")
    seeds = range(seed, seed + runs)
    return [
        run_policy(
            instance,
            p,
            seeds=seeds,
            horizon=horizon,
            checkpoints=checkpoints,
            on_checkpoint=on_checkpoint,
            on_slots=on_slots,
            channel=channel,
        )  # fmt: skip
        for p in policies
    ]


def sweep_config(
    instance: Instance,
    policies: Sequence[PolicySpec],
    *,
    runs: int,
    horizon: int,
    seed: int,
    checkpoints: Sequence[int],
    channel: Channel | None = None,
) -> dict[str, Any]:
    """Everything that determines a sweep (stored inside its log)."""
    from corraoi._version import __version__

    extra = {} if channel is None or channel.iid else {"channel": channel.to_dict()}
    return {
        **extra,
        "instance": instance.to_dict(),
        "policies": [p.to_dict() for p in policies],
        "runs": int(runs),
        "horizon": int(horizon),
        "seed": int(seed),
        "checkpoints": [int(c) for c in checkpoints],
        "version": __version__,
    }
