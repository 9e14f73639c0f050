"""Many sources sharing the channels of one instance (issue 43): runs of a multi-source policy.

The compiled kernel (:mod:`corraoi.engine._sources_kernel`, composed per policy family by
:mod:`corraoi.engine.kernels` as the single-source kernel is) loops slot -> source; this
module lays out its per-(run, source) state, calls it and hands the slots over as the slot
record's blocks: :func:`simulate_run_sources` one run as :class:`SourcesBlock` (what
``corraoi record`` streams), :func:`simulate_sources` many runs' totals (what a sweep
keeps).

Randomness: run ``seed``'s hidden path is the single-source engine's (its latent stream,
``SeedSequence(seed).spawn(2)[0]``), shared by every source and by every policy of the seed;
source m has its own policy stream, ``SFC64(SeedSequence(seed, spawn_key=(m,)))`` -- for
source 1 the single-source run's policy stream, ``spawn(2)[1]`` -- so that one source of
``rhorand-ucb`` is ``ucb``'s run slot for slot. The model: docs/model.md, "Many sources".
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi.errors import ConfigError, PolicyError, PolicyRuntimeError
from corraoi.model.candidates import candidate_bitsets
from corraoi.model.channels import Channel
from corraoi.model.instance import Instance
from corraoi.policies.api import RunState
from corraoi.policies.multi_source import CHAIRS_LEARN, OWN
from corraoi.policies.spec import PolicySpec, check_sources, make_policy

from . import threads
from ._kernel import draw_states
from .block import SlotBlock, SourcesBlock
from .problem import Problem
from .pyengine import (
    Streams,
    apply_sources_slot,
    call_policy,
    check_arms,
    construct,
    hook_fault,
    not_by_score,
)
from .seeds import streams_for_seeds
from .simulation import DEFAULT_BLOCK, check_seeds
from .slot_record import BY_NAME

__all__ = [
    "SourceOutputs",
    "SourcesSimulation",
    "SourcesTotals",
    "oracle_channels",
    "RunColumns",
    "simulate_run_sources",
    "simulate_runs",
    "simulate_sources",
    "source_blocks",
]

#: The rule codes of the kernel (``_sources_kernel.RULE_*``), by ``multi_source`` name; a
#: single-source policy run as one source is rhoRand's rank 1: the base policy itself.
RULES = {"rhorand": 0, "mctopm": 1, "centralized": 2, "chairs": 3, "": 0}

#: The per-source fields the kernel buffers, in its argument order (after ``x``).
SOURCE_FIELDS = ("arm", "success", "collided", "aoi", "oracle_aoi", "regret", "override",
                 "mu_hat", "pulls", "candidates", "forced", "override_threshold",
                 "score")  # fmt: skip
_NARROW = {"x": "int32", "arm": "int32"}


class SourceOutputs:
    """The per-slot buffers of one call of the kernel of many sources: ``x`` (R, B), then
    each field of :data:`SOURCE_FIELDS` (R, M, B) or (R, M, B, K), typed by the slot
    record (B = 0 when not recording)."""

    def __init__(self, R: int, M: int, B: int, K: int) -> None:
        self.columns: dict[str, np.ndarray] = {"x": np.empty((R, B), dtype=np.int32)}
        for f in SOURCE_FIELDS:
            shape = (R, M, B, K) if BY_NAME[f].per_arm else (R, M, B)
            self.columns[f] = np.empty(shape, dtype=_NARROW.get(f, BY_NAME[f].dtype))

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def buffers(self) -> tuple[np.ndarray, ...]:
        return tuple(self.columns.values())


def warm_args(K: int = 2, M: int = 2) -> tuple[Any, ...]:
    """Arguments of a zero-slot kernel call with the types the engine passes."""
    R = 1
    f8, i8, b1 = np.float64, np.int64, np.bool_
    return (
        np.ones((1, 2), f8), 0, np.zeros(1, i8), np.zeros((K, 2), np.int8),
        np.zeros((K, 8, 1), np.uint64), np.zeros(M, i8), False,
        False, 0, 0, np.zeros(0, f8), 0, 0,
        np.zeros((R, 4), np.uint64), np.zeros((R, M, 4), np.uint64), np.zeros((R, M, 2), f8),
        np.zeros((R, M, 1), f8), np.full(R, -1, i8), np.zeros((R, M, K), i8),
        np.zeros((R, M, K), i8), np.zeros((R, M), i8), np.zeros((R, M), b1),
        np.zeros((R, M, K), b1), np.ones((R, M), i8), np.ones((R, M), i8), np.zeros((R, M), i8),
        np.zeros((R, M), i8), np.zeros((R, M), i8), np.zeros((R, 3), i8), False,
        *SourceOutputs(R, M, 0, K).buffers(),
    )  # fmt: skip


def oracle_channels(mu: np.ndarray, sources: int) -> np.ndarray:
    """The channel the orthogonal oracle gives each source: source m the m-th best mean,
    ties by lowest index (M,) int64."""
    return np.argsort(-np.asarray(mu, dtype=np.float64), kind="stable")[:sources].astype(np.int64)


def source_streams(seeds: np.ndarray, sources: int) -> tuple[np.ndarray, np.ndarray]:
    """(latent (R, 4), policy (R, M, 4)) SFC64 states: the single-source run's latent and
    policy streams, and source m >= 2's ``SeedSequence(seed, spawn_key=(m,))``."""
    lat, pol1 = streams_for_seeds(seeds)
    pol = np.empty((seeds.size, sources, 4), dtype=np.uint64)
    pol[:, 0] = pol1
    for m in range(2, sources + 1):
        for i, s in enumerate(seeds):
            ss = np.random.SeedSequence(int(s), spawn_key=(m,))
            pol[i, m - 1] = np.random.SFC64(ss).state["state"]["state"]
    return lat, pol


def check_source_count(sources: Any, K: int) -> int:
    """``sources`` as an int in 1..K, else a ConfigError naming it and what is accepted."""
    if type(sources) is not int or not 1 <= sources <= K:
        raise ConfigError(f"sources {sources!r}: expected an integer from 1 to the number of "
                          f"arms, {K}")  # fmt: skip
    return sources


class SourcesSimulation:
    """The state of R runs of M sources of one multi-source policy: a compiled policy's
    advanced in the compiled kernel of many sources, a plain-Python policy's
    (``multi_source = "own"``) slot by slot, one instance of it per source, vectorised over
    runs (the plain-Python tier's parts: :mod:`corraoi.engine.pyengine`)."""

    def __init__(self, instance: Instance, policy: PolicySpec,
                 seeds: Sequence[int] | np.ndarray, horizon: int, sources: int, *,
                 channel: Channel | None = None) -> None:  # fmt: skip
        pb = Problem.of(instance, policy, horizon, channel)
        M = check_source_count(sources, pb.K)
        check_sources(policy, M, pb.cls)
        seed_arr = check_seeds(seeds)
        R, K = seed_arr.size, pb.K
        self.problem, self.policy, self.seeds, self.horizon = pb, policy, seed_arr, pb.horizon
        self.M, self.t = M, 0
        self.cls: Any = pb.cls
        rule = getattr(pb.cls, "multi_source", "")
        if pb.compiled and rule not in RULES:
            raise PolicyError(f"policy {policy.name}: multi_source {rule!r}; expected one of "
                              f"{', '.join(r for r in RULES if r)} (or none; \"{OWN}\" is a "
                              "plain-Python policy's)")  # fmt: skip
        if not pb.compiled and rule not in ("", OWN):
            raise PolicyError(f"policy {policy.name}: multi_source {rule!r}; a plain-Python "
                              f"policy's is \"{OWN}\" (each source an instance of its own; "
                              f"the rules {', '.join(r for r in RULES if r)} are compiled "
                              "policies')")  # fmt: skip
        self.oracle = oracle_channels(pb.theory.mu, M)
        #: each source's oracle channel mean (the estimator's mu*)
        self.oracle_mu = np.asarray(pb.theory.mu, dtype=np.float64)[self.oracle]
        assert self.oracle[0] == pb.theory.best_arm, "the oracle's first channel is the best"
        self.lat, self.pol = source_streams(seed_arr, M)
        self.xprev = np.full(R, -1, dtype=np.int64)
        if pb.compiled:
            self.rule = RULES[rule]
            declared = list(pb.cls.params)
            # t0 past the horizon learns for the whole run: it is the horizon to the kernel
            # (whose int64 a t0 of 1e30 overflowed)
            self.learn = (int(min(pb.params[declared.index(CHAIRS_LEARN)], self.horizon))
                          if rule == "chairs" and CHAIRS_LEARN in declared else 0)  # fmt: skip
            self.ncache = np.zeros((R, M, 2))
            self.pstate = np.zeros((R, M, max(pb.state_size, 1)))
            self.pulls = np.zeros((R, M, K), dtype=np.int64)
            self.succ = np.zeros((R, M, K), dtype=np.int64)
            self.rank = np.full((R, M), -1, dtype=np.int64)
            self.seated = np.zeros((R, M), dtype=np.bool_)
            self.worst = np.zeros((R, M, K), dtype=np.bool_)
            self.aoi = np.ones((R, M), dtype=np.int64)
            self.oracle_aoi = np.ones((R, M), dtype=np.int64)
            self.regret = np.zeros((R, M), dtype=np.int64)
            self.aoisum = np.zeros((R, M), dtype=np.int64)
            self.collisions = np.zeros((R, M), dtype=np.int64)
            self._err = np.zeros((R, 3), dtype=np.int64)
            self._comb = np.require(candidate_bitsets(pb.pclass), np.uint64, ["C", "W"])
            self._kernels: dict[bool, Any] = {}
            self._rate: float | None = None
            self._py: _PythonSources | None = None
        else:
            self._py = _PythonSources(self, R, M, K)

    def kernel(self, record: bool) -> Any:
        """The compiled kernel of many sources this run uses (None for a plain-Python
        policy's): compiled or loaded from the cache on first use."""
        if self._py is not None:
            return None
        kernel = self._kernels.get(record)
        if kernel is None:
            from .kernels import kernel_for

            warm: Callable[[], tuple[Any, ...]] = warm_args
            kernel = self._kernels[record] = kernel_for(self.cls, record=record, sources=warm)
        return kernel

    def advance(self, nslots: int, *, record: bool = True) -> list[list[SlotBlock]] | None:
        """Simulate the next ``nslots`` slots (capped at the horizon) of every run; with
        ``record``, each run's slots as one :class:`SlotBlock` per source. A plain-Python
        policy's failure is one PolicyRuntimeError whose ``done`` and ``partial`` (when
        recording) are the slots before it."""
        nslots = min(int(nslots), self.horizon - self.t)
        if nslots <= 0:
            return None
        R, M, K = self.pulls.shape
        out = SourceOutputs(R, M, nslots if record else 0, K)
        aoisum_before = self.aoisum.copy()
        failure = None
        if self._py is None:
            self._advance_compiled(nslots, record, out)
            done = nslots
        else:
            done, failure = self._py.advance(nslots, record, out)
        t = np.arange(self.t + 1, self.t + done + 1, dtype=np.int64)
        self.t += done
        runs = self._blocks(out, t, aoisum_before) if record and done > 0 else None
        if failure is not None:
            failure.done, failure.partial = done, runs
            raise failure
        return runs

    def _advance_compiled(self, nslots: int, record: bool, out: SourceOutputs) -> None:
        R = self.pulls.shape[0]
        K = self.pulls.shape[2]
        kernel = self.kernel(record)
        pb = self.problem
        per_run = (self.lat, self.pol, self.ncache, self.pstate, self.xprev, self.pulls,
                   self.succ, self.rank, self.seated, self.worst, self.aoi, self.oracle_aoi,
                   self.regret, self.aoisum, self.collisions, self._err)  # fmt: skip
        done = 0
        while done < nslots:
            n, slices = threads.plan(self._rate, R, nslots - done)
            if record:  # the record path: one call into `out`
                n, slices = nslots, [(0, R)]
            common = (pb.cdf_rows, pb.kind, pb.trace, pb.Y, self._comb, self.oracle,
                      bool(self.cls.correlated), bool(self.cls.aoi_aware), self.rule,
                      self.learn, pb.params, self.t + done, n)  # fmt: skip

            def run(a: int, b: int, common: tuple[Any, ...] = common) -> None:
                kernel(*common, *(x[a:b] for x in per_run), record,
                       *(x[a:b] for x in out.buffers()))  # fmt: skip

            start = time.perf_counter()
            threads.run_slices(run, slices)
            self._rate = threads.rate(R * n, time.perf_counter() - start, len(slices),
                                      self._rate)  # fmt: skip
            if self._err[:, 0].any():
                hit = np.flatnonzero(self._err[:, 0])
                r = int(hit[np.argmin(self._err[hit, 0])])
                slot, what, value = (int(v) for v in self._err[r])
                raise hook_fault(self.policy.name, slot, what, value, K,
                                 f"run {r} (seed {int(self.seeds[r])})")  # fmt: skip
            done += n

    def _blocks(self, out: SourceOutputs, t: np.ndarray,
                aoisum_before: np.ndarray) -> list[list[SlotBlock]]:  # fmt: skip
        """Each run's first ``len(t)`` slots in ``out``, a SlotBlock per source."""
        R, M = self.aoisum.shape
        n = t.size
        with np.errstate(divide="ignore"):
            inv = 1.0 / self.oracle_mu
        # a plain-Python policy has no AoI-aware override, and scores only once it gave some
        aware = self._py is None and bool(self.cls.aoi_aware)
        scored = self._py is None or self._py.scored
        runs: list[list[SlotBlock]] = []
        x = out["x"][:, :n].astype(np.int64)
        for r in range(R):
            blocks = []
            for m in range(M):
                col = {f: out[f][r, m, :n] for f in SOURCE_FIELDS}
                estimator = aoisum_before[r, m] + np.cumsum(col["aoi"]) - t * inv[m]
                blocks.append(SlotBlock(
                    t=t, x=x[r], arm=col["arm"].astype(np.int64), success=col["success"],
                    aoi=col["aoi"], oracle_aoi=col["oracle_aoi"], regret=col["regret"],
                    estimator=estimator, override=col["override"], mu_hat=col["mu_hat"],
                    pulls=col["pulls"], candidates=col["candidates"],
                    forced=col["forced"] if scored else None,
                    collided=col["collided"] if M > 1 else None,
                    override_threshold=col["override_threshold"] if aware else None,
                    score=col["score"] if scored else None,
                ))  # fmt: skip
            runs.append(blocks)
        return runs


class _PythonSources:
    """The plain-Python tier of many sources: one instance of the policy per source, each
    seeing its own :class:`~corraoi.policies.api.RunState` (its counts, age, collisions
    and policy stream: source 1's is the single-source run's), called source by source each
    slot; the collisions, ages and regret of the slot in one compiled call
    (:func:`~corraoi.engine.pyengine.apply_sources_slot`). Its arrays are (M, R, ...), each
    source's contiguous; the simulation's (R, M, ...) fields are views of them."""

    def __init__(self, sim: SourcesSimulation, R: int, M: int, K: int) -> None:
        self.sim = sim
        name = sim.policy.name
        self.names = [name if M == 1 else f"{name}, source {m + 1}" for m in range(M)]
        self.policies = [construct(sim.cls, sim.policy) for _ in range(M)]
        self.pulls = np.zeros((M, R, K), dtype=np.int64)
        self.succ = np.zeros((M, R, K), dtype=np.int64)
        self.mu = np.zeros((M, R, K))
        self.aoi = np.ones((M, R), dtype=np.int64)
        self.oracle_aoi = np.ones((M, R), dtype=np.int64)
        self.regret = np.zeros((M, R), dtype=np.int64)
        self.aoisum = np.zeros((M, R), dtype=np.int64)
        self.collisions = np.zeros((M, R), dtype=np.int64)
        self.collided = np.zeros((M, R), dtype=np.bool_)
        self.clock = np.zeros(1, dtype=np.int64)
        #: some source gave scores (Choice(..., scores=...)) at some slot
        self.scored = False
        pols = [np.ascontiguousarray(sim.pol[:, m]) for m in range(M)]
        self.states = [
            RunState(runs=R, arms=K, seeds=sim.seeds, rng=Streams(pols[m], np.zeros((R, 2))),
                     pulls=self.pulls[m], successes=self.succ[m], mu_hat=self.mu[m],
                     aoi=self.aoi[m], clock=self.clock, source=m + 1, sources=M,
                     collided=self.collided[m])
            for m in range(M)
        ]  # fmt: skip
        # the simulation's fields (R, M, ...), as the compiled tier's
        sim.pulls = self.pulls.transpose(1, 0, 2)
        sim.succ = self.succ.transpose(1, 0, 2)
        for field in ("aoi", "oracle_aoi", "regret", "aoisum", "collisions"):
            setattr(sim, field, getattr(self, field).T)

    def run_name(self, r: int) -> str:
        return f"run {r} (seed {int(self.sim.seeds[r])})"

    def advance(self, nslots: int, record: bool,
                out: SourceOutputs) -> tuple[int, PolicyRuntimeError | None]:  # fmt: skip
        """Advance every run slot by slot, writing each slot's columns into ``out`` when
        recording; returns (slots done, the plug-in's failure or None)."""
        sim, pb = self.sim, self.sim.problem
        M, R, K = self.pulls.shape
        xs = np.empty((R, nslots), dtype=np.int64)
        draw_states(pb.cdf_rows, pb.kind, pb.trace, sim.lat, sim.xprev, sim.t, nslots, xs)
        try:
            if sim.t == 0:
                for m, (policy, state) in enumerate(zip(self.policies, self.states, strict=True)):
                    call_policy(self.names[m], 0, state, policy.reset, state)
        except PolicyRuntimeError as exc:
            return 0, exc
        arms = np.empty((M, R), dtype=np.int64)
        for j in range(nslots):
            t = sim.t + j + 1
            self.clock[0] = t
            picks = []
            try:
                for m, (policy, state) in enumerate(zip(self.policies, self.states, strict=True)):
                    picked = call_policy(self.names[m], t, state, policy.select, t, state)
                    picks.append(check_arms(picked, runs=R, arms=K, name=self.names[m], t=t,
                                            who=self.run_name))  # fmt: skip
            except PolicyRuntimeError as exc:
                return j, exc
            for m, (a, _, _) in enumerate(picks):
                arms[m] = a
            x = xs[:, j]
            sensed = np.empty((M, R), dtype=np.int8)  # new each slot: a policy may keep it
            apply_sources_slot(arms, x, pb.Y, sim.oracle, self.pulls, self.succ, self.mu,
                               self.aoi, self.oracle_aoi, self.regret, self.aoisum,
                               self.collisions, self.collided, sensed)  # fmt: skip
            if record:
                out["x"][:, j] = x
                for m, (a, cand, scores) in enumerate(picks):
                    out["arm"][:, m, j] = a
                    out["success"][:, m, j] = (sensed[m] == 1) & ~self.collided[m]
                    out["collided"][:, m, j] = self.collided[m]
                    out["aoi"][:, m, j] = self.aoi[m]
                    out["oracle_aoi"][:, m, j] = self.oracle_aoi[m]
                    out["regret"][:, m, j] = self.regret[m]
                    out["override"][:, m, j] = False
                    out["candidates"][:, m, j] = True if cand is None else cand
                    out["pulls"][:, m, j] = self.pulls[m]
                    out["mu_hat"][:, m, j] = self.mu[m]
                    if scores is not None:
                        self.scored = True
                    out["score"][:, m, j] = np.nan if scores is None else scores
                    out["forced"][:, m, j] = (True if scores is None
                                              else not_by_score(scores, a))  # fmt: skip
            sensed.flags.writeable = False
            try:
                for m, (policy, state) in enumerate(zip(self.policies, self.states, strict=True)):
                    played = arms[m].copy()
                    played.flags.writeable = False
                    call_policy(self.names[m], t, state, policy.update, t, played, sensed[m],
                                state)  # fmt: skip
            except PolicyRuntimeError as exc:
                return j + 1, exc  # the slot itself happened
        return nslots, None


def source_blocks(instance: Instance, policy: PolicySpec, seed: int, horizon: int, sources: int,
                  *, block: int = DEFAULT_BLOCK,
                  channel: Channel | None = None) -> Iterator[tuple[SlotBlock, ...]]:  # fmt: skip
    """One run of ``sources`` sources (1 included), block by block: a SlotBlock per source."""
    if type(block) is not int or block < 1:
        raise ConfigError(f"block size {block!r}: expected an integer >= 1")
    sim = SourcesSimulation(instance, policy, [seed], horizon, sources, channel=channel)
    while True:
        try:
            out = sim.advance(block)
        except PolicyRuntimeError as exc:
            if exc.partial is not None:  # hand over the slots before the failure first
                yield tuple(exc.partial[0])
            raise
        if out is None:
            return
        yield tuple(out[0])


def simulate_run_sources(instance: Instance, policy: PolicySpec, seed: int, horizon: int,
                         sources: int, *, block: int = DEFAULT_BLOCK,
                         channel: Channel | None = None) -> Iterator[SourcesBlock]:  # fmt: skip
    """One run of M >= 2 sources, block by block (what ``corraoi record --sources M``
    streams); a single source's run is :func:`corraoi.engine.simulation.simulate_run`."""
    if type(sources) is int and sources == 1:
        raise ConfigError("sources 1: a single source's run is simulate_run's (expected 2 to "
                          "the number of arms here)")  # fmt: skip
    for parts in source_blocks(instance, policy, seed, horizon, sources, block=block,
                               channel=channel):  # fmt: skip
        yield SourcesBlock(parts)


@dataclass
class SourcesTotals:
    """Many runs of M sources at their horizon: per run and source (R, M) the regret, the
    sum of ages and the collisions; the pulls (R, M, K)."""

    seeds: np.ndarray
    regret: np.ndarray
    aoisum: np.ndarray
    collisions: np.ndarray
    pulls: np.ndarray

    @property
    def total_regret(self) -> np.ndarray:
        """Each run's regret summed over its sources (R,)."""
        return self.regret.sum(axis=1)


def simulate_sources(instance: Instance, policy: PolicySpec, seeds: Sequence[int] | np.ndarray,
                     horizon: int, sources: int, *,
                     channel: Channel | None = None) -> SourcesTotals:  # fmt: skip
    """Many runs of ``sources`` sources to the horizon in the sweep kernel (no per-slot
    columns): each run's and source's totals."""
    sim = SourcesSimulation(instance, policy, seeds, horizon, sources, channel=channel)
    sim.advance(horizon, record=False)
    return SourcesTotals(seeds=sim.seeds, regret=sim.regret, aoisum=sim.aoisum,
                         collisions=sim.collisions, pulls=sim.pulls)  # fmt: skip


@dataclass
class RunColumns:
    """One run of M sources, slot by source: the channel each picked (0-based), whether it
    collided and whether it delivered, each (T, M)."""

    seed: int
    arm: np.ndarray
    collided: np.ndarray
    success: np.ndarray


def simulate_runs(instance: Instance, policy: PolicySpec | str, seeds: Sequence[int],
                  horizon: int, *, sources: int, channel: Channel | None = None,
                  block: int = 10_000) -> Iterator[RunColumns]:  # fmt: skip
    """Each seed's run of ``sources`` sources, in order, as its slot columns ``arm``,
    ``collided`` and ``success`` (what a comparison with another library counts: collisions
    and rewards); ``policy`` a spec or a ``--policy`` word."""
    spec = make_policy(policy) if isinstance(policy, str) else policy
    for seed in check_seeds(seeds):
        parts = list(source_blocks(instance, spec, int(seed), horizon, sources, block=block,
                                   channel=channel))  # fmt: skip
        cols = [SlotBlock.concat([p[m] for p in parts]) for m in range(sources)]
        collided = [c.collided if c.collided is not None else np.zeros(len(c), bool)
                    for c in cols]  # fmt: skip
        yield RunColumns(seed=int(seed), arm=np.stack([c.arm for c in cols], axis=1),
                         collided=np.stack(collided, axis=1),
                         success=np.stack([c.success for c in cols], axis=1))  # fmt: skip
