"""Replay, compare, diff and inspect recorded corraoi runs. Reads logs; never simulates.

``corraoi.viewer.diff(a, b)`` compares two logs slot by slot (a :class:`DiffReport` with
``.identical``, per-field first divergence and ``.message()``); :func:`compare`,
:func:`replay` and :func:`recover` are what the ``corraoi compare``, ``replay`` and
``recover`` commands call (``info`` is :mod:`corraoi.viewer.info`'s). Rerun is imported only by
``compare`` and ``replay``, when they run.
"""

from __future__ import annotations

from .compare import compare
from .diff_report import DiffReport
from .diffs import diff
from .recover import recover
from .replay import replay

__all__ = ["DiffReport", "compare", "diff", "recover", "replay"]
