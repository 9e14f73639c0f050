"""The GPU backend of sweeps (docs/gpu.md): every built-in policy as a CUDA kernel, one thread
per run, compiled by CuPy (the ``gpu`` extra); aggregates over runs computed on the device.

``corraoi sweep --backend gpu`` / ``experiments.sweep(grid, backend="gpu")``: the backend
runs one policy's runs (:func:`corraoi.gpu.runner.simulate`) and knows nothing of grids;
:mod:`corraoi.experiments.backends` decides whether a grid can run here and runs its chunks.
Per-slot logs (``record``) stay a CPU feature. Importing this package needs neither CuPy nor a GPU.
"""

from __future__ import annotations

from corraoi.errors import GpuUnavailable

from .device import get_device

__all__ = ["GpuUnavailable", "get_device"]
