"""Replay, compare, diff and inspect recorded corraoi runs. Reads logs; never simulates.

``viewer.diff(a, b)`` compares two logs slot by slot (a :class:`DiffReport` with
``.identical``, per-field first divergence and ``.message()``); :func:`compare`,
:func:`replay`, :func:`recover` and :func:`log_info` are what the ``corraoi compare``,
``replay``, ``recover`` and ``info`` commands call. Rerun is imported only by
``compare`` and ``replay``, when they run.
"""

from __future__ import annotations

from .compare import Comparison, compare
from .diff_report import DiffReport, FieldDiff
from .diffs import diff
from .info import log_info
from .recover import Recovered, recover
from .replay import Replayed, replay

__all__ = [
    "Comparison",
    "DiffReport",
    "FieldDiff",
    "Recovered",
    "Replayed",
    "compare",
    "diff",
    "log_info",
    "recover",
    "replay",
]
