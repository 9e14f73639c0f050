"""The GPU backend of sweeps (docs/gpu.md): every built-in policy as a CUDA kernel, one thread
per run, compiled by CuPy (the ``gpu`` extra); aggregates over runs computed on the device.

``corraoi sweep --backend gpu`` / ``experiments.sweep(grid, backend="gpu")``. Per-slot logs
(``record``) stay a CPU feature. Importing this package needs neither CuPy nor a GPU.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from corraoi.errors import GpuUnavailable

from .device import DEVICE_ENV, MAX_ARMS, get_device

if TYPE_CHECKING:
    from corraoi.experiments.grid import Grid


def gpu_problem_of(grid: Grid) -> str | None:
    """Why the GPU backend cannot run ``grid`` here, or None when it can: a policy without
    a GPU form, too many arms, or no device (CuPy missing, no CUDA device)."""
    from .runner import gpu_problem

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


def choose_backend(grid: Grid, *, warn: Callable[[str], None] | None = None) -> Grid:
    """``grid`` with its backend settled: "gpu" checked (GpuUnavailable with the reason when
    it cannot run), "auto" resolved to "gpu" when it can, else to "cpu" with a notice."""
    if grid.backend == "cpu":
        return grid
    problem = gpu_problem_of(grid)
    if problem is None:
        return replace(grid, backend="gpu")
    if grid.backend == "gpu":
        raise GpuUnavailable(f"--backend gpu: {problem}; run with --backend cpu")
    if warn is not None:
        warn(f"--backend auto: running on the CPU ({problem})")
    return replace(grid, backend="cpu")


__all__ = ["DEVICE_ENV", "MAX_ARMS", "GpuUnavailable", "choose_backend", "get_device",
           "gpu_problem_of"]  # fmt: skip
