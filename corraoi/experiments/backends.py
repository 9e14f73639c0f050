"""Where the chunks of a sweep run: one small interface, three backends, chosen in one place.

* :class:`InProcess`: the CPU engine in this process, on its own threads (``workers``);
* :class:`OnDask`: the CPU engine on the workers of a ``dask.distributed`` client
  (``corraoi/experiments/cluster.py``);
* :class:`OnGpu`: the built-in policies' CUDA kernel, one thread per run
  (:mod:`corraoi.gpu`: it runs one policy's runs; which runs, in which order, is here).

A backend takes the chunks to run as (cell, chunk) pairs and hands each finished
:class:`corraoi.experiments.folder.ChunkResult` to ``on_done`` (in any order); it never calls back
into the sweep. :func:`settle` settles ``--backend`` (cpu, gpu, auto) and :func:`choose` the
backend that runs a settled grid.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Protocol

from corraoi.errors import ConfigError, GpuUnavailable

from .grid import Cell, Chunk, Grid

if TYPE_CHECKING:
    from corraoi.gpu.device import Device
    from corraoi.gpu.runner import DeviceRun

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
        """Run the chunks ``todo`` on the device, group by group. With a baseline, its runs
        of each chunk's range run first and stay on the device, so that every other
        policy's paired moments are computed there."""
        from corraoi.gpu import get_device

        from .folder import ChunkResult

        dev = get_device()
        for cells in grid.groups().values():
            keys = {c.key for c in cells}
            work = [(c, ch) for c, ch in todo if c.key in keys]
            if not work:
                continue
            base = next((c for c in cells if c.policy.name == grid.baseline), None)
            work.sort(key=lambda item: base is None or item[0].key != base.key)
            kept: dict[tuple[int, int], Any] = {}
            for cell, chunk in work:
                span = (chunk.start, chunk.stop)
                is_base = base is not None and cell.key == base.key
                against = None
                if base is not None and not is_base:
                    if span not in kept:  # the baseline's runs were saved earlier (--resume)
                        kept[span] = _on_device(grid, base, chunk, dev, keep=True).kept
                    against = kept[span]
                result = _on_device(grid, cell, chunk, dev, baseline=against, keep=is_base,
                                    on_slots=on_slots)  # fmt: skip
                if is_base:
                    kept[span] = result.kept
                on_done(ChunkResult.from_device(chunk, result, grid.baseline))


def _on_device(grid: Grid, cell: Cell, chunk: Chunk, dev: Device, *, baseline: Any = None,
               keep: bool = False, on_slots: OnSlots | None = None) -> DeviceRun:  # fmt: skip
    """The runs of ``chunk``'s range of ``cell`` on the device (seeds from the grid's)."""
    from corraoi.gpu.runner import simulate

    from .chunks import checkpoints_of

    return simulate(
        cell.instance, cell.policy, seed0=grid.seed + chunk.start, runs=chunk.stop - chunk.start,
        horizon=cell.horizon, checkpoints=checkpoints_of(grid, cell.horizon),
        channel=cell.channel, baseline=baseline, keep=keep, on_slots=on_slots, device=dev,
    )  # fmt: skip


def settle(grid: Grid, backend: str | None, *, client: Any = None,
           warn: Callable[[str], None] | None = None) -> Grid:  # fmt: skip
    """``grid`` with its backend settled: ``backend`` (else the grid's own) of cpu, gpu or
    auto; "gpu" checked (GpuUnavailable with the reason), "auto" the GPU when it can run
    every cell, else the CPU with a notice through ``warn``; a GPU with a Dask client is
    refused."""
    if backend is not None and backend != grid.backend:
        grid = replace(grid, backend=backend)
    if grid.backend == "cpu":
        return grid
    problem = _gpu_problem(grid)
    if problem is None:
        if client is not None:
            raise ConfigError(GPU_NOT_ON_CLUSTER)
        return replace(grid, backend="gpu")
    if grid.backend == "gpu":
        raise GpuUnavailable(f"--backend gpu: {problem}; run with --backend cpu")
    if warn is not None:
        warn(f"--backend auto: running on the CPU ({problem})")
    return replace(grid, backend="cpu")


def _gpu_problem(grid: Grid) -> str | None:
    """Why the GPU backend cannot run ``grid`` here, or None when it can: a cell of several
    sources, a policy without a GPU form, too many arms, or no device (CuPy missing, no CUDA
    device)."""
    from corraoi.gpu import get_device
    from corraoi.gpu.runner import gpu_problem

    many = next((c for c in grid.cells if c.sources > 1), None)
    if many is not None:  # the CUDA kernel runs one source per run
        return (f"{many.policy.name} with {many.sources} sources: the GPU backend runs one "
                "source (several sources run on the CPU engine)")  # fmt: skip
    seen: set[tuple[str, int]] = set()
    for cell in grid.cells:
        key = (cell.policy.qualname, cell.instance.K)
        if key in seen:
            continue
        seen.add(key)
        problem = gpu_problem(cell.policy, cell.instance.K)
        if problem is not None:
            return problem
    try:
        get_device()
    except GpuUnavailable as exc:
        return str(exc)
    return None


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


