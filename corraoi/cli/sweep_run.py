"""Running a sweep's grid for ``corraoi sweep`` and ``corraoi reproduce`` through the face
(:func:`corraoi.face.sweeps.run_grid`): the backend settled and said, a progress bar, and
Ctrl-C saying what is saved.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from .common import keep_pandas_out, warn


def settle_backend(grid: Any) -> Any:
    """The grid with ``auto`` resolved (a notice when it falls back to the CPU) and ``gpu``
    checked; says which device runs it."""
    from corraoi.face.sweeps import device_name
    from corraoi.face.sweeps import settle_backend as settle

    grid = settle(grid, warn=warn)
    name = device_name(grid)
    if name is not None:
        click.echo(f"backend gpu: {name}", err=True)
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
    from corraoi.face.sweeps import run_grid as run
    from corraoi.progress import Progress

    if out is not None and scheduler is None:
        keep_pandas_out()  # results.parquet is written with pyarrow alone (0.4 s saved)
    if scheduler is None:
        total = sum(c.horizon for c in grid.cells) * grid.runs // grid.chunk_runs
        bar = Progress(max(total, 1), label)
    else:
        bar = Progress(sum(-(-grid.runs // grid.chunk_runs) for _ in grid.cells),
                       f"{label} (chunks)")  # fmt: skip

    def on_chunk(done: int, total: int) -> None:
        bar.update(1, note=f"{done}/{total} chunks")

    try:
        with bar:
            return run(grid, out=out, scheduler=scheduler, resume=resume, force=force,
                       workers=workers, warn=warn,
                       on_slots=bar.update if scheduler is None else None,
                       on_chunk=on_chunk if scheduler is not None else None)  # fmt: skip
    except KeyboardInterrupt:
        where = f"; finished chunks are saved in {out}: --resume continues" if out else ""
        click.echo(f"corraoi: interrupted{where}", err=True)
        sys.exit(130)


__all__ = ["run_grid", "settle_backend"]
