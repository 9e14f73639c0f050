"""The simulation engine: many runs of one policy, block by block, in compiled code.

Randomness: run ``i`` of a batch started at ``seed`` uses the integer seed ``seed + i``;
``SeedSequence(seed).spawn(2)`` gives its latent stream and its policy stream (both SFC64).
So the hidden path of a run depends on (instance, seed) only -- every policy sees the same
X path (common random numbers) -- and run ``i`` of a sweep is exactly the run that
``corraoi record --seed <seed + i>`` records.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from . import _kernel
from .block import FIELDS, Columns, SlotBlock, check_horizon, check_seed
from .errors import ConfigError
from .instance import Instance
from .policies import PolicySpec
from .theory import InstanceTheory, analyse, policy_pseudo_rewards

DEFAULT_BLOCK = 1000


def streams_for_seed(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(latent, policy) SFC64 states for one integer seed, as NumPy would seed them."""
    lat_ss, pol_ss = np.random.SeedSequence(int(seed)).spawn(2)
    lat = np.random.SFC64(lat_ss).state["state"]["state"]
    pol = np.random.SFC64(pol_ss).state["state"]["state"]
    return np.array(lat, dtype=np.uint64), np.array(pol, dtype=np.uint64)


@dataclass
class RunsBlock(Columns):
    """Consecutive slots of R runs: the columns of :class:`SlotBlock` with a leading run axis
    (``t`` stays (B,); the others are (R, B) and (R, B, K))."""

    @classmethod
    def concat(cls, blocks: list[RunsBlock]) -> RunsBlock:
        """Join consecutive blocks along the slot axis."""
        if not blocks:
            raise ValueError("no blocks to concatenate")
        return cls(
            **{
                f: np.concatenate([b.column(f) for b in blocks], axis=0 if f == "t" else 1)
                for f in FIELDS
            }  # fmt: skip
        )

    def run(self, i: int) -> SlotBlock:
        """Run ``i``'s columns (views, no copy)."""
        per_run = {f: getattr(self, f)[i] for f in FIELDS if f != "t"}
        return SlotBlock(t=self.t, **per_run)


@dataclass
class Snapshot:
    """The state of every run at slot ``t``: regret (R,), estimator (R,), pulls (R, K)."""

    t: int
    regret: np.ndarray
    estimator: np.ndarray
    pulls: np.ndarray


def check_instance(instance: Instance) -> InstanceTheory:
    """The instance's theory, or a ConfigError when it cannot be simulated (mu* = 0)."""
    theory = analyse(instance)
    if theory.mu_star <= 0:
        raise ConfigError(
            f"instance {instance.name}: every arm has mean 0, the AoI grows without bound "
            "and regret is not defined"
        )
    return theory


class Simulation:
    """The state of R runs of one policy on one instance, advanced by :meth:`advance`."""

    def __init__(
        self, instance: Instance, policy: PolicySpec, seeds: Sequence[int], horizon: int
    ) -> None:
        check_horizon(horizon)
        if len(seeds) < 1:
            raise ConfigError("at least one run is needed (runs must be >= 1)")
        for s in seeds:
            check_seed(s)
        self.instance = instance
        self.policy = policy
        self.seeds = [int(s) for s in seeds]
        self.horizon = int(horizon)
        theory = check_instance(instance)
        self.best = theory.best_arm
        self.mu_star = theory.mu_star
        R, K = len(self.seeds), instance.K
        self._cdf = np.cumsum(instance.p)
        self._Y = np.ascontiguousarray(instance.Y, dtype=np.int8)
        self._spol = np.ascontiguousarray(policy_pseudo_rewards(instance))
        self.lat = np.empty((R, 4), dtype=np.uint64)
        self.pol = np.empty((R, 4), dtype=np.uint64)
        for i, s in enumerate(self.seeds):
            self.lat[i], self.pol[i] = streams_for_seed(s)
        self.ncache = np.zeros((R, 2))
        self.pulls = np.zeros((R, K), dtype=np.int64)
        self.succ = np.zeros((R, K), dtype=np.int64)
        self.aoi = np.ones(R, dtype=np.int64)
        self.oracle_aoi = np.ones(R, dtype=np.int64)
        self.regret = np.zeros(R, dtype=np.int64)
        self.aoisum = np.zeros(R, dtype=np.int64)
        self.t = 0

    @property
    def runs(self) -> int:
        return len(self.seeds)

    @property
    def estimator(self) -> np.ndarray:
        """The paper's estimator sum(aoi) - t / mu* of each run, at the current slot."""
        return self.aoisum - self.t / self.mu_star

    def advance(self, nslots: int, *, record: bool = True) -> RunsBlock | None:
        """Simulate the next ``nslots`` slots (capped at the horizon) of every run.

        With ``record``, returns every slot's columns; otherwise only the state advances.
        """
        block, _ = self._advance(nslots, record=record, stops=())
        return block

    def advance_to(self, stop: int, *, snapshots: Sequence[int] = ()) -> list[Snapshot]:
        """Simulate up to slot ``stop`` in one compiled call, snapshotting every run at the
        slots of ``snapshots`` that fall in (t, stop] (cheap: nothing per slot is kept)."""
        _, snaps = self._advance(stop - self.t, record=False, stops=snapshots)
        return snaps

    def _advance(
        self, nslots: int, *, record: bool, stops: Sequence[int]
    ) -> tuple[RunsBlock | None, list[Snapshot]]:
        nslots = min(int(nslots), self.horizon - self.t)
        if nslots <= 0:
            return None, []
        R, K = self.pulls.shape
        snap_t = np.array(
            sorted({int(s) for s in stops if self.t < s <= self.t + nslots}), dtype=np.int64
        )
        S = snap_t.size
        s_regret = np.empty((R, S), dtype=np.int64)
        s_aoisum = np.empty((R, S), dtype=np.int64)
        s_pulls = np.empty((R, S, K), dtype=np.int64)
        B = nslots if record else 0
        o_x = np.empty((R, B), dtype=np.int16)
        o_arm = np.empty((R, B), dtype=np.int16)
        o_succ = np.empty((R, B), dtype=np.bool_)
        o_aoi = np.empty((R, B), dtype=np.int64)
        o_oaoi = np.empty((R, B), dtype=np.int64)
        o_regret = np.empty((R, B), dtype=np.int64)
        o_override = np.empty((R, B), dtype=np.bool_)
        o_cand = np.empty((R, B, K), dtype=np.bool_)
        o_pulls = np.empty((R, B, K), dtype=np.int64)
        o_muhat = np.empty((R, B, K), dtype=np.float64)
        aoisum_before = self.aoisum.copy() if record else None
        p = self.policy
        _kernel.advance(
            self._cdf, self._Y, self._spol, self.best,
            p.base, p.correlated, p.aoi_aware, p.c, p.beta,
            self.t, nslots,
            self.lat, self.pol, self.ncache, self.pulls, self.succ,
            self.aoi, self.oracle_aoi, self.regret, self.aoisum,
            record, o_x, o_arm, o_succ, o_aoi, o_oaoi, o_regret, o_override,
            o_cand, o_pulls, o_muhat,
            snap_t, s_regret, s_aoisum, s_pulls,
        )  # fmt: skip
        snaps = [
            Snapshot(
                t=int(ts),
                regret=s_regret[:, i],
                estimator=s_aoisum[:, i] - ts / self.mu_star,
                pulls=s_pulls[:, i],
            )
            for i, ts in enumerate(snap_t)
        ]
        t = np.arange(self.t + 1, self.t + nslots + 1, dtype=np.int64)
        self.t += nslots
        if not record:
            return None, snaps
        assert aoisum_before is not None
        estimator = aoisum_before[:, None] + np.cumsum(o_aoi, axis=1) - t[None, :] / self.mu_star
        block = RunsBlock(
            t=t,
            x=o_x.astype(np.int64),
            arm=o_arm.astype(np.int64),
            success=o_succ,
            aoi=o_aoi,
            oracle_aoi=o_oaoi,
            regret=o_regret,
            estimator=estimator,
            override=o_override,
            mu_hat=o_muhat,
            pulls=o_pulls,
            candidates=o_cand,
        )
        return block, snaps


def simulate(
    instance: Instance,
    policy: PolicySpec,
    seeds: Sequence[int],
    horizon: int,
    *,
    block: int = DEFAULT_BLOCK,
) -> Iterator[RunsBlock]:
    """Yield blocks of ``block`` consecutive slots of every run until the horizon."""
    if block < 1:
        raise ConfigError(f"block size must be >= 1, got {block}")
    sim = Simulation(instance, policy, seeds, horizon)
    while (out := sim.advance(block)) is not None:
        yield out


def simulate_run(
    instance: Instance, policy: PolicySpec, seed: int, horizon: int, *, block: int = DEFAULT_BLOCK
) -> Iterator[SlotBlock]:
    """One run, block by block (what ``corraoi record`` streams to its sinks)."""
    for b in simulate(instance, policy, [seed], horizon, block=block):
        yield b.run(0)


def set_workers(workers: int | None) -> int:
    """Use ``workers`` threads in the kernel (default: every core). Returns the count used."""
    import numba

    top = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
    if workers is None:
        workers = top
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    workers = min(int(workers), top)
    numba.set_num_threads(workers)
    return workers
