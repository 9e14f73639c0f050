"""Running a sweep's grid for ``corraoi sweep`` and ``corraoi reproduce``: the backend settled
(``auto`` resolved, ``gpu`` checked), then the chunks in this process or on a Dask cluster,
with a progress bar, and Ctrl-C saying what is saved.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from corraoi.errors import ConfigError

from .common import keep_pandas_out, warn


def settle_backend(grid: Any) -> Any:
    """The grid with ``auto`` resolved (a notice when it falls back to the CPU) and ``gpu``
    checked; says which device runs it."""
    if grid.backend == "cpu":
        return grid
    from corraoi.gpu import choose_backend, get_device

    grid = choose_backend(grid, warn=warn)
    if grid.backend == "gpu":
        click.echo(f"backend gpu: {get_device().name}", err=True)
    return grid


def run_grid(
    grid: Any,
    *,
    out: Path | None,
    scheduler: str | None,
    resume: bool,
    force: bool,
    workers: int | None,
    label: str,
) -> Any:
    """Run the grid with a progress bar (slots in this process, chunks on a cluster)."""
    from contextlib import ExitStack

    from corraoi.experiments.backends import GPU_NOT_ON_CLUSTER
    from corraoi.experiments.sweeps import sweep as run_sweep
    from corraoi.progress import Progress

    if scheduler is not None and grid.backend == "gpu":  # before a cluster is started
        raise ConfigError(GPU_NOT_ON_CLUSTER)
    outputs = None
    with ExitStack() as stack:
        if out is not None and scheduler is None:
            keep_pandas_out()  # results.parquet is written with pyarrow alone (0.4 s saved)
            # the figures are drawn by a process that imports matplotlib now, while this one
            # runs the sweep and then writes the Rerun recordings (viewer/figure_worker.py)
            from viewer.figure_worker import FigureWorker

            figures = FigureWorker.start()
            if figures is not None:
                from corraoi.face.outputs import FolderOutputs

                outputs = FolderOutputs(stack.enter_context(figures))
        client = None
        if scheduler is not None:
            from corraoi.experiments.cluster import connect

            client = stack.enter_context(connect(scheduler))
        if client is None:
            total = sum(c.horizon for c in grid.cells) * grid.runs // grid.chunk_runs
            bar = stack.enter_context(Progress(max(total, 1), label))
            on_slots = bar.update
            on_chunk = None
        else:
            chunks = sum(-(-grid.runs // grid.chunk_runs) for _ in grid.cells)
            bar = stack.enter_context(Progress(chunks, f"{label} (chunks)"))

            def on_chunk(done: int, total: int) -> None:
                bar.update(1, note=f"{done}/{total} chunks")

            on_slots = None
        try:
            return run_sweep(grid, out=out, client=client, resume=resume, force=force,
                             workers=workers, on_chunk=on_chunk, on_slots=on_slots,
                             warn=warn, outputs=outputs)  # fmt: skip
        except KeyboardInterrupt:
            where = f"; finished chunks are saved in {out}: --resume continues" if out else ""
            click.echo(f"corraoi: interrupted{where}", err=True)
            sys.exit(130)


__all__ = ["run_grid", "settle_backend"]
