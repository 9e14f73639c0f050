"""Where the chunks of a sweep run: one small interface, three backends, chosen in one place.

* :class:`InProcess`: the CPU engine in this process, on its own threads (``workers``);
* :class:`OnDask`: the CPU engine on the workers of a ``dask.distributed`` client
  (``corraoi/experiments/cluster.py``);
* :class:`OnGpu`: the built-in policies' CUDA kernel, one thread per run
  (``corraoi/gpu/runner.py``).

A backend takes the chunks to run as (cell, chunk) pairs and hands each finished
:class:`corraoi.experiments.folder.ChunkResult` to ``on_done`` (in any order); it never calls back
into the sweep. :func:`choose` settles ``--backend`` (cpu, gpu, auto) and the scheduler.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol

from corraoi.errors import ConfigError

from .grid import Cell, Chunk, Grid

if TYPE_CHECKING:
    from .folder import ChunkResult

#: Why a GPU sweep and a Dask client do not go together.
GPU_NOT_ON_CLUSTER = ("--backend gpu runs in this process, on its GPU; leave out --scheduler "
                      "(or use --backend cpu on the cluster)")  # fmt: skip

OnDone = Callable[["ChunkResult"], None]
OnSlots = Callable[[int], None]


class Backend(Protocol):
    """What runs the chunks of a sweep."""

    @property
    def workers(self) -> int:
        """Threads per chunk (the summary's ``workers``)."""
        ...

    def run(self, grid: Grid, todo: Sequence[tuple[Cell, Chunk]], *, on_done: OnDone,
            on_slots: OnSlots | None) -> None: ...  # fmt: skip


@dataclass
class InProcess:
    """The engine in this process: chunk by chunk, each on ``workers`` threads; the kernels
    the chunks need are compiled first (several families at once, one notice)."""

    workers: int

    def run(self, grid: Grid, todo: Sequence[tuple[Cell, Chunk]], *, on_done: OnDone,
            on_slots: OnSlots | None) -> None:  # fmt: skip
        from .chunks import chunk_task, prepare_kernels, run_chunk

        if todo:
            prepare_kernels([cell for cell, _ in todo])
        for cell, chunk in todo:
            on_done(run_chunk(chunk_task(grid, cell, chunk), on_slots=on_slots))


@dataclass
class OnDask:
    """The engine on a Dask cluster: every chunk submitted as plain data, results handed
    over as they arrive (no progress within a chunk: ``on_slots`` is not called)."""

    client: Any
    #: engine threads per chunk on a worker (None: the worker's default, every core)
    threads: int | None = None

    @property
    def workers(self) -> int:
        return int(self.threads or 1)

    def run(self, grid: Grid, todo: Sequence[tuple[Cell, Chunk]], *, on_done: OnDone,
            on_slots: OnSlots | None) -> None:  # fmt: skip
        from .chunks import chunk_task
        from .cluster import run_on_cluster

        tasks = [(chunk, chunk_task(grid, cell, chunk, threads=self.threads))
                 for cell, chunk in todo]  # fmt: skip
        run_on_cluster(self.client, tasks, on_done=on_done)


@dataclass
class OnGpu:
    """The CUDA kernel (or its emulation on the host), group by group."""

    workers: int = 1

    def run(self, grid: Grid, todo: Sequence[tuple[Cell, Chunk]], *, on_done: OnDone,
            on_slots: OnSlots | None) -> None:  # fmt: skip
        from corraoi.gpu.runner import execute

        execute(grid, todo, on_done=on_done, on_slots=on_slots)


def settle(grid: Grid, backend: str | None, *, client: Any = None,
           warn: Callable[[str], None] | None = None) -> Grid:  # fmt: skip
    """``grid`` with its backend settled: ``backend`` (else the grid's own) of cpu, gpu or
    auto; "gpu" checked (GpuUnavailable with the reason), "auto" the GPU when it can run
    every cell, else the CPU with a notice through ``warn``; a GPU with a Dask client is
    refused."""
    if backend is not None and backend != grid.backend:
        grid = replace(grid, backend=backend)
    if grid.backend != "cpu":
        from corraoi.gpu import choose_backend

        grid = choose_backend(grid, warn=warn)
        if grid.backend == "gpu" and client is not None:
            raise ConfigError(GPU_NOT_ON_CLUSTER)
    return grid


def choose(grid: Grid, *, client: Any = None, workers: int | None = None,
           threads_per_worker: int | None = None) -> Backend:  # fmt: skip
    """The backend of a settled grid (:func:`settle`): the GPU, Dask with ``client`` (each
    chunk on ``threads_per_worker`` threads), else this process on ``workers`` threads."""
    if grid.backend == "gpu":
        return OnGpu()
    if client is not None:
        return OnDask(client, threads_per_worker)
    from corraoi.engine.threads import set_workers

    return InProcess(set_workers(workers))
def sweep_backend(grid_backend: str) -> str:
    """The backend a sweep's runs came from: ``cpu``, or the GPU backend's device kind."""
    if grid_backend != "gpu":
        return "cpu"
    from corraoi.gpu.device import EmulatedDevice, get_device

    return "gpu-emulated" if isinstance(get_device(), EmulatedDevice) else "gpu-cuda"


