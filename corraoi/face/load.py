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
    from recorder.sweeplog.results import is_sweep_path

    p = Path(path)
    if is_sweep_path(p):
        if slots is not None:
            raise UsageError(f"{p}: slots=... selects slots of a slot log, not of a sweep")
        from .sweeps import Sweep

        return Sweep(p)
    from .runs import Run

    return Run(p, slots=slots)


__all__ = ["load"]
