"""One chunk of a sweep's runs: the task a worker gets (plain data), running it, and compiling
the kernels chunks need. The sweep (:mod:`corraoi.experiments.sweeps`) chooses where chunks run; the
cluster and GPU backends use this module and never call back up."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from corraoi._version import __version__
from corraoi.errors import ConfigError
from corraoi.model.instance import Instance

from .folder import ChunkResult
from .grid import Cell, Chunk, Grid


def checkpoints_of(grid: Grid, horizon: int) -> list[int]:
    from .montecarlo import default_checkpoints

    return [c for c in default_checkpoints(horizon, grid.checkpoints) if 0 < c <= horizon]


def chunk_task(
    grid: Grid, cell: Cell, chunk: Chunk, *, threads: int | None = None
) -> dict[str, Any]:
    """Everything a worker needs to run ``chunk``, as plain data: the cell (instance, policy,
    channel with its trace), the seeds, the checkpoints, and a file plug-in's source."""
    task: dict[str, Any] = {
        "version": __version__,
        "cell": cell.to_dict(),
        "key": cell.key,
        "start": chunk.start,
        "stop": chunk.stop,
        "seed": grid.seed,
        "checkpoints": checkpoints_of(grid, cell.horizon),
        "threads": threads,
    }
    if cell.channel.kind == "trace" and cell.channel.trace is not None:
        task["trace"] = [int(v) for v in cell.channel.trace]
    qual = cell.policy.qualname
    if qual.startswith("file:"):  # the bytes this process loaded (and hashed), not the file now
        from corraoi.policies.loading import loaded_source

        path = qual[len("file:") :].rpartition(":")[0]
        loaded = loaded_source(cell.policy.resolve().__module__)
        source = loaded[1] if loaded is not None else Path(path).read_bytes()
        task["plugin_source"] = {"path": path, "source": source}
    return task


def run_chunk(task: dict[str, Any], on_slots: Callable[[int], None] | None = None) -> ChunkResult:
    """Run one chunk from its :func:`chunk_task` data (in this process or on a worker)."""
    if task.get("version") != __version__:
        raise ConfigError(
            f"this worker runs corraoi {__version__}, the client {task.get('version')}: "
            "install the same version on both"
        )
    given = task.get("plugin_source")
    if given:  # the client's bytes, for this chunk only (the worker may lack the file)
        from corraoi.policies.loading import handed_over

        with handed_over({given["path"]: given["source"]}):
            return _run_chunk(task, on_slots)
    return _run_chunk(task, on_slots)


def _run_chunk(task: dict[str, Any], on_slots: Callable[[int], None] | None) -> ChunkResult:
    from corraoi.engine.block import RunConfig
    from corraoi.engine.threads import set_workers
    from corraoi.model.channels import Channel
    from corraoi.model.theory import analyse
    from corraoi.policies.api import CompiledPolicy

    from .montecarlo import run_policy

    if task.get("threads"):
        set_workers(int(task["threads"]))
    cfg = RunConfig.from_dict({**task["cell"], "seed": 0})
    channel = cfg.channel
    if "trace" in task and channel is not None:
        states = np.asarray(task["trace"], dtype=np.int64)
        channel = Channel("trace", source=channel.source, trace=states, digest=channel.digest)
    inst: Instance = cfg.model
    best = analyse(inst).best_arm
    stops = [int(c) for c in task["checkpoints"]]
    S, K = len(stops), inst.K
    n = int(task["stop"]) - int(task["start"])
    regret = np.empty((n, S))
    estimator = np.empty((n, S))
    best_pulls = np.empty((n, S), dtype=np.int64)
    pulls_sum = np.empty((S, K), dtype=np.int64)
    index = {t: i for i, t in enumerate(stops)}

    def keep(policy: Any, snap: Any) -> None:
        i = index[snap.t]
        regret[:, i] = snap.regret
        estimator[:, i] = snap.estimator
        best_pulls[:, i] = snap.pulls[:, best]
        pulls_sum[i] = snap.pulls.sum(axis=0)

    cls = cfg.policy.resolve()
    if cfg.sources > 1 or getattr(cls, "multi_source", None):
        return _run_sources_chunk(task, cfg, channel, stops, on_slots)
    if isinstance(cls, type) and issubclass(cls, CompiledPolicy):
        from corraoi.engine.kernels import kernel_for

        kernel_for(cls, record=False)  # compiled or loaded now: a chunk's wall_s is its runs
    start = time.perf_counter()
    seed0 = int(task["seed"]) + int(task["start"])
    run_policy(inst, cfg.policy, seeds=range(seed0, seed0 + n), horizon=cfg.horizon,
               checkpoints=stops, on_checkpoint=keep, on_slots=on_slots,
               channel=channel, first_run=int(task["start"]))  # fmt: skip
    return ChunkResult(
        chunk=Chunk(str(task["key"]), int(task["start"]), int(task["stop"])),
        t=np.asarray(stops, dtype=np.int64), regret=regret, estimator=estimator,
        best_pulls=best_pulls, pulls_sum=pulls_sum, wall_s=time.perf_counter() - start,
    )  # fmt: skip


def _run_sources_chunk(task: dict[str, Any], cfg: Any, channel: Any, stops: Sequence[int],
                       on_slots: Callable[[int], None] | None) -> ChunkResult:  # fmt: skip
    """A chunk of a multi-source policy's cell in the engine of many sources (one source
    included: its base policy's runs), advanced checkpoint by checkpoint: each run's regret
    and estimator summed over its sources, its regret per source and its collisions."""
    from corraoi.engine.sources import SourcesSimulation

    inst: Instance = cfg.model
    n = int(task["stop"]) - int(task["start"])
    seed0 = int(task["seed"]) + int(task["start"])
    sim = SourcesSimulation(inst, cfg.policy, range(seed0, seed0 + n), cfg.horizon,
                            cfg.sources, channel=channel)  # fmt: skip
    sim.kernel(False)  # compiled or loaded now (a compiled policy's): wall_s is its runs
    S, M = len(stops), cfg.sources
    regret = np.empty((n, S))
    estimator = np.empty((n, S))
    by_source = np.empty((n, S, M))
    collisions = np.empty((n, S), dtype=np.int64)
    best_pulls = np.empty((n, S), dtype=np.int64)
    pulls_sum = np.empty((S, inst.K), dtype=np.int64)
    best = int(sim.oracle[0])
    start = time.perf_counter()
    for i, stop in enumerate(stops):
        before = sim.t
        sim.advance(stop - sim.t, record=False)
        if on_slots is not None:
            on_slots(stop - before)
        by_source[:, i] = sim.regret
        regret[:, i] = sim.regret.sum(axis=1)
        # the paper's estimator per source, against its oracle channel's mean, summed
        estimator[:, i] = (sim.aoisum - stop / sim.oracle_mu).sum(axis=1)
        collisions[:, i] = sim.collisions.sum(axis=1)
        best_pulls[:, i] = sim.pulls[:, :, best].sum(axis=1)
        pulls_sum[i] = sim.pulls.sum(axis=(0, 1))
    return ChunkResult(
        chunk=Chunk(str(task["key"]), int(task["start"]), int(task["stop"])),
        t=np.asarray(stops, dtype=np.int64), regret=regret, estimator=estimator,
        best_pulls=best_pulls, pulls_sum=pulls_sum, wall_s=time.perf_counter() - start,
        regret_by_source=by_source if M > 1 else None,
        collisions=collisions if M > 1 else None,
    )  # fmt: skip


def prepare_kernels(cells: Sequence[Cell]) -> None:
    """Compile the sweep kernels the cells need and the cache lacks, concurrently: the
    single-source kernel of a cell of one source, the kernel of many sources of the others."""
    from corraoi.engine.kernel_pool import prepare_for

    prepare_for(((cell.policy.resolve(), cell.many) for cell in cells), record=False)
