"""The names the command line's help lists (a slot record's fields), read from the slot
record's declaration alone, so that ``corraoi --help`` imports nothing heavy."""

from __future__ import annotations

from corraoi.engine.slot_record import FLOAT_FIELDS, NAMES

#: The fields ``corraoi diff`` and :func:`corraoi.diff` compare: every slot field but ``t``.
DIFF_FIELDS = tuple(f for f in NAMES if f != "t")
#: The fields compared with a tolerance (``--atol``); the others compare exactly.
TOLERANT_FIELDS = tuple(FLOAT_FIELDS)

__all__ = ["DIFF_FIELDS", "TOLERANT_FIELDS"]
