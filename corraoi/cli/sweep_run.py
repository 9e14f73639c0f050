"""Running a sweep's grid for ``corraoi reproduce`` through the face
(:func:`corraoi.face.sweeps.run_with_progress`): the backend settled and said, a progress bar,
and Ctrl-C saying what is saved (:func:`interrupted_or`, ``corraoi sweep``'s too).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from .common import keep_pandas_out, warn
from .reading import progress


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
    from corraoi.face.sweeps import run_with_progress

    done = run_with_progress(grid, out=out, scheduler=scheduler, resume=resume, force=force,
                             workers=workers, warn=warn, progress=progress,
                             before_folder=keep_pandas_out, label=label)  # fmt: skip
    return interrupted_or(done)


def interrupted_or(done: Any) -> Any:
    """The outcome of a sweep the face ran (:class:`corraoi.face.sweeps.SweepRun`); one that
    Ctrl-C stopped says what is saved and exits with status 130."""
    if done.interrupted is not None:
        click.echo(f"corraoi: {done.interrupted}", err=True)
        sys.exit(130)
    return done.outcome


__all__ = ["interrupted_or", "run_grid", "settle_backend"]
