"""``corraoi.load``: logs and sweeps as tables for analysis (pandas, pyarrow).

``import corraoi`` does not import this module; ``corraoi.load`` does, on first use. The
tables are built by ``recorder.slotlog.frames`` (slot logs) and ``recorder.sweeplog.results``
(sweeps),
imported inside :func:`load`. pandas and pyarrow are the optional extra ``analysis``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from corraoi.errors import MissingExtraError, UsageError

if TYPE_CHECKING:
    from recorder.slotlog.frames import RunData
    from recorder.sweeplog.results import SweepData

#: What to install for the tables.
EXTRA = 'pip install "corraoi[analysis]"'


def require_analysis(names: tuple[str, ...] = ("pandas", "pyarrow")) -> None:
    """Raise :class:`MissingExtraError` naming the extra unless ``names`` are installed (found,
    not imported: pandas costs 0.3 s and is imported only where a DataFrame is made)."""
    import importlib.util

    for name in names:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            raise MissingExtraError(
                f"{name} is not installed: corraoi.load and corraoi export need the analysis "
                f"extra, {EXTRA}"
            ) from None


def load(
    path: str | os.PathLike[str], *, slots: tuple[int, int] | None = None
) -> RunData | SweepData:
    """Load a slot log (``RunData``) or a sweep (``SweepData``) for analysis.

    * a slot log (``runs/cucb-I1-s0.mcap``): ``.slots`` is a DataFrame, one row per slot,
      arms and states numbered from 1 as in the file; ``.config``; ``.to_arrow()`` streams
      record batches. ``slots=(first, last)`` reads only the slots first..last (inclusive)
      and leaves the rest of the file undecoded.
    * a sweep folder written by ``corraoi sweep -o DIR`` (or its ``sweep.mcap`` or
      ``results.parquet``): ``.runs`` is the per-run results table, ``.summary`` the
      ``summary.json`` object, ``.curves`` the aggregated curves of the sweep log.
    """
    require_analysis()
    from recorder.sweeplog.results import SweepData, is_sweep_path

    p = Path(path)
    if is_sweep_path(p):
        if slots is not None:
            raise UsageError(f"{p}: slots=... selects slots of a slot log, not of a sweep")
        return SweepData(p)
    from recorder.slotlog.frames import RunData

    return RunData(p, slots=slots)


__all__ = ["EXTRA", "load", "require_analysis"]
