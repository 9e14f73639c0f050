"""The simulation engine: many runs of one policy, block by block, in compiled code.

Randomness: run ``i`` of a batch started at ``seed`` uses the integer seed ``seed + i``;
``SeedSequence(seed).spawn(2)`` gives its latent stream and its policy stream (both SFC64).
So the hidden path of a run depends on (instance, seed) only -- every policy sees the same
X path (common random numbers) -- and run ``i`` of a sweep is exactly the run that
``corraoi record --seed <seed + i>`` records.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi.errors import ConfigError, CorraoiError, PolicyRuntimeError
from corraoi.limits import check_seed
from corraoi.model.candidates import candidate_bitsets
from corraoi.model.channels import Channel
from corraoi.model.instance import Instance
from corraoi.policies.api import RunState
from corraoi.policies.spec import PolicySpec

from . import threads
from ._kernel import draw_states
from .block import Columns, Outputs, SlotBlock, absent_fill
from .problem import Problem
from .pyengine import (
    Streams,
    apply_slot,
    call_policy,
    check_arms,
    construct,
    counts_written,
    hook_fault,
    hook_raised,
    hook_wrote,
    not_by_score,
)
from .seeds import streams_for_seeds

__all__ = [
    "RunsBlock",
    "Simulation",
    "Snapshot",
    "simulate",
    "simulate_run",
]

DEFAULT_BLOCK = 1000


@dataclass
class RunsBlock(Columns):
    """Consecutive slots of R runs: the columns of :class:`SlotBlock` with a leading run axis
    (``t`` stays (B,); the others are (R, B) and (R, B, K))."""

    @classmethod
    def concat(cls, blocks: list[RunsBlock]) -> RunsBlock:
        """Join consecutive blocks along the slot axis."""
        if not blocks:
            raise ValueError("no blocks to concatenate")
        names = [f for f in blocks[0].fields() if all(f in b.fields() for b in blocks)]
        names += [f for b in blocks for f in b.fields() if f not in names]
        cols: dict[str, Any] = {
            f: np.concatenate([absent_fill(b, f) for b in blocks], axis=0 if f == "t" else 1)
            for f in dict.fromkeys(names)
        }
        return cls(**cols)

    def run(self, i: int) -> SlotBlock:
        """Run ``i``'s columns (views, no copy)."""
        per_run = {f: self.column(f)[i] for f in self.fields() if f != "t"}
        return SlotBlock(t=self.t, **per_run)


@dataclass
class Snapshot:
    """The state of every run at slot ``t``: regret (R,), estimator (R,), pulls (R, K)."""

    t: int
    regret: np.ndarray
    estimator: np.ndarray
    pulls: np.ndarray


class Simulation:
    """The state of R runs of one policy on one instance, advanced by :meth:`advance`.

    Compiled policies run in their family's kernel (:mod:`corraoi.engine.kernels`); plain-Python
    policies (:class:`corraoi.policies.Policy`) slot by slot, vectorised over runs, with the
    parts of :mod:`corraoi.engine.pyengine`.
    """

    def __init__(
        self,
        instance: Instance,
        policy: PolicySpec,
        seeds: Sequence[int] | np.ndarray,
        horizon: int,
        *,
        channel: Channel | None = None,
        first_run: int = 0,
    ) -> None:
        self._setup(Problem.of(instance, policy, horizon, channel), seeds, first_run)

    @classmethod
    def of(cls, problem: Problem, seeds: Sequence[int] | np.ndarray) -> Simulation:
        """The runs ``seeds`` of a checked :class:`corraoi.engine.problem.Problem`."""
        sim = cls.__new__(cls)
        sim._setup(problem, seeds)
        return sim

    def _setup(self, pb: Problem, seeds: Sequence[int] | np.ndarray, first_run: int = 0) -> None:
        seed_arr = check_seeds(seeds)
        #: the number of run 0 of this batch where a failure names a run (a sweep's chunk)
        self.first_run = int(first_run)
        self.problem = pb
        self.instance = pb.instance
        self.policy = pb.policy
        self.seeds = seed_arr
        self.horizon = pb.horizon
        self.channel = pb.channel
        self.best = pb.theory.best_arm
        self.mu_star = pb.theory.mu_star
        self.cls: Any = pb.cls
        R, K = seed_arr.size, pb.K
        self._cdf_rows, self._kind, self._trace, self._Y = pb.cdf_rows, pb.kind, pb.trace, pb.Y
        self.lat, self.pol = streams_for_seeds(seed_arr)
        self.ncache = np.zeros((R, 2))
        self.xprev = np.full(R, -1, dtype=np.int64)
        self.pulls = np.zeros((R, K), dtype=np.int64)
        self.succ = np.zeros((R, K), dtype=np.int64)
        self.aoi = np.ones(R, dtype=np.int64)
        self.oracle_aoi = np.ones(R, dtype=np.int64)
        self.regret = np.zeros(R, dtype=np.int64)
        self.aoisum = np.zeros(R, dtype=np.int64)
        self.t = 0
        if pb.compiled:
            self._kernels: dict[bool, Any] = {}
            self._err = np.zeros((R, 3), dtype=np.int64)  # a hook's fault (the kernel's err)
            self._params = pb.params
            # a plug-in's hooks are checked for writes into params and the counts (the
            # built-ins are not: no cost)
            self._given: np.ndarray | None = None if pb.policy.builtin else pb.params.copy()
            self.pstate = np.zeros((R, max(pb.state_size, 1)))
            self._comb = np.require(candidate_bitsets(pb.pclass), np.uint64, ["C", "W"])
            self._py: Any = None
            self._rate: float | None = None  # run-slots per second per thread, measured
        else:
            self._py = construct(self.cls, pb.policy)
            self._mu = np.zeros((R, K))
            self._clock = np.zeros(1, dtype=np.int64)  # the slot state.t shows
            # the policy sees these arrays through read-only views
            self._state = RunState(runs=R, arms=K, seeds=seed_arr,
                                   rng=Streams(self.pol, self.ncache), pulls=self.pulls,
                                   successes=self.succ, mu_hat=self._mu, aoi=self.aoi,
                                   clock=self._clock)  # fmt: skip
            #: the policy has given scores (Choice(..., scores=...)) at some slot
            self._scored = False

    def kernel(self, record: bool) -> Any:
        """The compiled kernel this simulation uses: the record kernel (per-slot columns) or
        the sweep kernel. Compiled or loaded from the cache on first use; the time it takes
        goes to ``kernels.compile_seconds`` when it compiles, so rates leave it out."""
        kernel = self._kernels.get(record)
        if kernel is None:
            from .kernels import kernel_for

            kernel = self._kernels[record] = kernel_for(self.cls, record=record)
        return kernel

    def use_kernel(self, kernel: Any, *, record: bool = False) -> None:
        """Run the compiled calls with ``kernel`` instead of the kernel cache's: one of the
        same signature compiled elsewhere (ahead of time: ``benchmarks/bench_aot.py``)."""
        self._kernels[record] = kernel

    def _run_compiled(self, nslots: int, record: bool, out: Outputs, snap_t: np.ndarray,
                      s_regret: np.ndarray, s_aoisum: np.ndarray,
                      s_pulls: np.ndarray) -> tuple[int, PolicyRuntimeError | None]:  # fmt: skip
        """Advance every run ``nslots`` slots in kernel calls of at most about
        ``threads.PIECE_SECONDS`` each (sliced by slots, and by runs across threads), so that a
        signal is handled between two calls within that time, however large the work.

        Returns (slots done, None), or, when a hook returned an arm out of range or a NaN
        score for a candidate (the kernel notes the first such slot of each run and never
        plays that arm: no array is read out of bounds), the slots before the first such
        slot and its PolicyRuntimeError; what came after it is not kept."""
        kernel = self.kernel(record)
        R, K = self.pulls.shape
        done = 0
        check = self._given is not None
        while done < nslots:
            t0 = self.t + done
            n, slices = threads.plan(self._rate, R, nslots - done)
            i0, i1 = (int(i) for i in np.searchsorted(snap_t, [t0 + 1, t0 + n + 1]))
            if n == nslots:  # one piece: straight into the caller's arrays
                piece, st, snaps = out, snap_t, (s_regret, s_aoisum, s_pulls)
            else:  # column slices are not C arrays: separate arrays, copied back
                piece = Outputs(R, n if record else 0, K)
                st = np.ascontiguousarray(snap_t[i0:i1])
                snaps = (np.empty((R, i1 - i0), np.int64), np.empty((R, i1 - i0), np.int64),
                         np.empty((R, i1 - i0, K), np.int64))  # fmt: skip
            counts = (self.pulls.copy(), self.succ.copy()) if check and record else None
            start = time.perf_counter()
            try:
                self._call_kernel(kernel, t0, n, record, piece, st, snaps, slices)
            except (CorraoiError, KeyboardInterrupt):
                raise
            except Exception as exc:  # noqa: BLE001 - a compiled hook raised (numba's raise)
                return done, hook_raised(self.policy.name, t0 + 1, t0 + n, exc)
            self._rate = threads.rate(R * n, time.perf_counter() - start, len(slices),
                                      self._rate)  # fmt: skip
            if piece is not out:
                if record:
                    for name, value in piece.columns.items():
                        out[name][:, done : done + n] = value
                for full, part in zip((s_regret, s_aoisum, s_pulls), snaps, strict=True):
                    full[:, i0:i1] = part
            if self._err[:, 0].any():
                return self._fault(K)
            wrote = self._hooks_wrote(counts, piece, t0, n) if check else None
            if wrote is not None:
                return done + wrote[0], wrote[1]
            done += n
        return nslots, None

    def _fault(self, K: int) -> tuple[int, PolicyRuntimeError]:
        """The first slot at which a compiled hook failed (the kernel's ``err``), with the
        slots before it (corraoi.engine.pyengine.hook_fault says what and where)."""
        hit = np.flatnonzero(self._err[:, 0])
        r = int(hit[np.argmin(self._err[hit, 0])])
        t, what, value = (int(v) for v in self._err[r])
        self._err[:] = 0
        return t - 1 - self.t, hook_fault(self.policy.name, t, what, value, K, self.run_name(r))

    def _hooks_wrote(self, counts: tuple[np.ndarray, np.ndarray] | None, piece: Outputs,
                     t0: int, n: int) -> tuple[int, PolicyRuntimeError] | None:  # fmt: skip
        """Whether a plug-in's hooks wrote into what they may only read in slots
        ``t0 + 1..t0 + n``: ``params``, or the counts (``npull``, ``nsucc``) -- the record
        path finds the first such slot from the columns and the ``counts`` before them, the
        sweep path checks that each run's pulls add up to its slots. None, or (slots before
        it, the error)."""
        name, when = self.policy.name, f"slots {t0 + 1}..{t0 + n}"
        if self._given is not None and not np.array_equal(self._params, self._given):
            return 0, hook_wrote(name, when, "params")
        if counts is not None:
            return counts_written(name, t0, piece["arm"], piece["success"], piece["pulls"],
                                  piece["mu_hat"], *counts, self.run_name)  # fmt: skip
        wrong = (self.succ < 0) | (self.succ > self.pulls)
        bad = (self.pulls.sum(axis=1) != t0 + n) | wrong.any(axis=1)
        if bad.any():
            return 0, hook_wrote(name, when, "npull or nsucc", self.run_name(int(bad.argmax())))
        return None

    def run_name(self, r: int) -> str:
        """How a failure names run ``r`` of this batch: its number and its seed."""
        return f"run {self.first_run + r} (seed {int(self.seeds[r])})"

    def _call_kernel(self, kernel: Any, t0: int, nslots: int, record: bool, out: Outputs,
                     snap_t: np.ndarray, snaps: tuple[np.ndarray, np.ndarray, np.ndarray],
                     slices: list[tuple[int, int]]) -> None:  # fmt: skip
        per_run = (self.lat, self.pol, self.ncache, self.pstate, self.xprev, self.pulls,
                   self.succ, self.aoi, self.oracle_aoi, self.regret, self.aoisum,
                   self._err)  # fmt: skip
        outputs = out.buffers()
        common = (self._cdf_rows, self._kind, self._trace, self._Y, self._comb, self.best,
                  bool(self.cls.correlated), bool(self.cls.aoi_aware),
                  self._params, t0, nslots)  # fmt: skip

        def run(a: int, b: int) -> None:
            # row slices of C arrays are C arrays: the same compiled signature
            kernel(*common, *(x[a:b] for x in per_run), record, *(x[a:b] for x in outputs),
                   snap_t, *(x[a:b] for x in snaps))  # fmt: skip

        threads.run_slices(run, slices)

    def _run_python(self, nslots: int, record: bool, out: Outputs, snap_t: np.ndarray,
                    s_regret: np.ndarray, s_aoisum: np.ndarray,
                    s_pulls: np.ndarray) -> tuple[int, PolicyRuntimeError | None]:  # fmt: skip
        """Advance every run of a plain-Python policy slot by slot, writing each slot's
        columns into ``out`` when recording and the snapshots at ``snap_t``; returns (slots
        done, the plug-in's failure or None)."""
        policy, state = self._py, self._state
        name = self.policy.name
        R, K = self.pulls.shape
        xs = np.empty((R, nslots), dtype=np.int64)
        draw_states(self._cdf_rows, self._kind, self._trace, self.lat, self.xprev, self.t,
                    nslots, xs)  # fmt: skip
        Y = self._Y
        mu = self._mu
        if self.t == 0:
            try:
                call_policy(name, 0, state, policy.reset, state)
            except PolicyRuntimeError as exc:
                return 0, exc
        si = 0
        for j in range(nslots):
            t = self.t + j + 1
            self._clock[0] = t
            try:
                picked = call_policy(name, t, state, policy.select, t, state)
                arms, cand, scores = check_arms(picked, runs=R, arms=K, name=name, t=t,
                                                who=self.run_name)  # fmt: skip
            except PolicyRuntimeError as exc:
                return j, exc
            x = xs[:, j]
            rew = np.empty(R, dtype=np.int8)  # new each slot: the policy may keep it
            apply_slot(arms, x, Y, self.best, self.pulls, self.succ, mu, self.aoi,
                       self.oracle_aoi, self.regret, self.aoisum, rew)  # fmt: skip
            if record:
                out["x"][:, j] = x
                out["arm"][:, j] = arms
                out["success"][:, j] = rew == 1
                out["aoi"][:, j] = self.aoi
                out["oracle_aoi"][:, j] = self.oracle_aoi
                out["regret"][:, j] = self.regret
                out["override"][:, j] = False
                out["candidates"][:, j] = True if cand is None else cand
                out["pulls"][:, j] = self.pulls
                out["mu_hat"][:, j] = mu
                if scores is not None:
                    self._scored = True
                out["score"][:, j] = np.nan if scores is None else scores
                out["forced"][:, j] = True if scores is None else not_by_score(scores, arms)
            if si < snap_t.size and snap_t[si] == t:
                s_regret[:, si] = self.regret
                s_aoisum[:, si] = self.aoisum
                s_pulls[:, si] = self.pulls
                si += 1
            rew.flags.writeable = False
            played = arms.view()
            played.flags.writeable = False
            try:
                call_policy(name, t, state, policy.update, t, played, rew, state)
            except PolicyRuntimeError as exc:
                return j + 1, exc  # the slot itself happened
        return nslots, None

    @property
    def runs(self) -> int:
        return int(self.seeds.size)

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
        out = Outputs(R, B, K)
        aoisum_before = self.aoisum.copy() if record else None
        if self._py is None:
            done, failure = self._run_compiled(nslots, record, out, snap_t, s_regret, s_aoisum,
                                               s_pulls)  # fmt: skip
        else:
            done, failure = self._run_python(nslots, record, out, snap_t, s_regret, s_aoisum,
                                             s_pulls)  # fmt: skip
        if failure is not None:  # keep the slots before the failing one
            nslots = done
            out.trim(done)
            snap_t = snap_t[snap_t <= self.t + done]
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
        if failure is not None:
            failure.done = nslots
        if not record:
            if failure is not None:
                raise failure
            return None, snaps
        assert aoisum_before is not None
        estimator = (
            aoisum_before[:, None] + np.cumsum(out["aoi"], axis=1) - t[None, :] / self.mu_star
        )
        # what a run lacks: the override's threshold but for an AoI-aware policy; the
        # score and forced of a plain-Python policy that gave no scores (so far)
        compiled = self._py is None
        scored = compiled or self._scored
        block = RunsBlock(
            t=t,
            x=out["x"].astype(np.int64),
            arm=out["arm"].astype(np.int64),
            success=out["success"],
            aoi=out["aoi"],
            oracle_aoi=out["oracle_aoi"],
            regret=out["regret"],
            estimator=estimator,
            override=out["override"],
            mu_hat=out["mu_hat"],
            pulls=out["pulls"],
            candidates=out["candidates"],
            forced=out["forced"] if scored else None,
            override_threshold=(
                out["override_threshold"] if compiled and self.cls.aoi_aware else None
            ),
            score=out["score"] if scored else None,
        )
        if failure is not None:
            failure.partial = block if nslots > 0 else None
            raise failure
        return block, snaps


def check_seeds(seeds: Sequence[int] | np.ndarray) -> np.ndarray:
    """The seeds as an int64 array (ConfigError for none, negative or non-integer)."""
    if isinstance(seeds, range):
        if len(seeds) < 1:
            raise ConfigError("at least one run is needed (runs must be >= 1)")
        check_seed(seeds[0])
        check_seed(seeds[-1])
        return np.arange(seeds.start, seeds.stop, seeds.step, dtype=np.int64)
    if len(seeds) < 1:
        raise ConfigError("at least one run is needed (runs must be >= 1)")
    for s in seeds:
        check_seed(s)
    return np.asarray([int(s) for s in seeds], dtype=np.int64)


def simulate(
    instance: Instance,
    policy: PolicySpec,
    seeds: Sequence[int],
    horizon: int,
    *,
    block: int = DEFAULT_BLOCK,
    channel: Channel | None = None,
) -> Iterator[RunsBlock]:
    """Yield blocks of ``block`` consecutive slots of every run until the horizon."""
    if block < 1:
        raise ConfigError(f"block size must be >= 1, got {block}")
    sim = Simulation(instance, policy, seeds, horizon, channel=channel)
    while True:
        try:
            out = sim.advance(block)
        except PolicyRuntimeError as exc:
            if exc.partial is not None:  # hand over the slots before the failure first
                yield exc.partial
            raise
        if out is None:
            return
        yield out


def simulate_run(
    instance: Instance,
    policy: PolicySpec,
    seed: int,
    horizon: int,
    *,
    block: int = DEFAULT_BLOCK,
    channel: Channel | None = None,
) -> Iterator[SlotBlock]:
    """One run, block by block (what ``corraoi record`` streams to its sinks)."""
    for b in simulate(instance, policy, [seed], horizon, block=block, channel=channel):
        yield b.run(0)
