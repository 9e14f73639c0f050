"""``corraoi.load``: a recorded run or a sweep folder, read back (nothing is simulated).

``import corraoi`` does not import this module; ``corraoi.load`` does, on first use. Tables
(``.slots``, ``.runs``, ``.curves``) need pandas and pyarrow, the optional extra ``analysis``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from corraoi import arguments
from corraoi.errors import UsageError

if TYPE_CHECKING:
    from corraoi.recorder.export import Exported

    from .runs import Run
    from .sweeps import Sweep


def load(path: str | os.PathLike[str], *, slots: tuple[int, int] | None = None) -> Run | Sweep:
    """Returns the slot log at ``path`` as a :class:`corraoi.Run`, or the sweep there as a
    :class:`corraoi.Sweep`.

    * a slot log (``runs/cucb-I1-s0.mcap``, or its ``.partial``): ``.slots`` is a DataFrame,
      one row per slot, arms and states numbered from 1 as in the file; ``.config``;
      ``.summary``; ``.to_arrow()`` streams record batches. ``slots=(first, last)`` reads only
      the slots first..last (inclusive) and leaves the rest of the file undecoded.
    * a sweep folder written by ``corraoi sweep -o DIR`` (or its ``sweep.mcap`` or
      ``results.parquet``): ``.runs`` is the per-run results table, ``.summary`` the
      ``summary.json`` object, ``.curves`` the aggregated curves of the sweep log.

    Raises :class:`~corraoi.errors.LogError` for a file that is not a readable corraoi log,
    :class:`~corraoi.errors.UsageError` for ``slots`` of a sweep.
    """
    arguments.path(
        path, name="path", kind=UsageError, what="the path of a slot log or a sweep folder"
    )
    slots = arguments.optional(arguments.window, slots, name="slots")
    from corraoi.recorder.sweeplog.results import is_sweep_path

    p = Path(path)
    if is_sweep_path(p):
        if slots is not None:
            raise UsageError(f"{p}: slots=... selects slots of a slot log, not of a sweep")
        from .sweeps import Sweep

        return Sweep(p)
    from .runs import Run

    return Run(p, slots=slots)


def export(
    path: str | os.PathLike[str], out: str | os.PathLike[str], *, force: bool = False
) -> Exported:
    """Write the table :func:`load` gives for ``path`` (a slot log's ``.slots``, a sweep's
    ``.runs``) to ``out``, CSV or Parquet by its extension, as ``corraoi export`` does;
    ``force`` replaces an existing ``out``. Returns what was written (``.path``, ``.rows``,
    ``.kind``, ``.format``); raises :class:`~corraoi.errors.UsageError` for an unknown
    extension, :class:`~corraoi.errors.LogError` for what is not a readable log,
    :class:`~corraoi.errors.OutputError` for an ``out`` that must not be written, and names
    the ``analysis`` extra when pyarrow is missing."""
    from corraoi.recorder.export import export as export_table

    arguments.path(path, name="path", kind=UsageError,
                   what="the path of a slot log or a sweep folder")  # fmt: skip
    arguments.path(out, name="out", what="the table's path (.csv or .parquet)")
    arguments.flag(force, name="force")
    return export_table(path, out, overwrite=force)


__all__ = ["export", "load"]
