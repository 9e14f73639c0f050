"""Diff two recorded runs slot by slot, streaming both logs side by side.

``diff(a, b)`` returns a :class:`DiffReport`: the configuration differences, then per
logged field the first slot where the runs diverge and how many slots differ, and the
final figures of both runs. It is what ``corraoi diff`` prints and what a test suite
asserts on::

    report = corraoi.viewer.diff("a.mcap", "b.mcap")
    assert report.identical, report.message()

Arms and states are numbered from 1 in everything the report shows.

The report itself (its text and JSON) is :mod:`corraoi.viewer.diff_report`'s; its classes stay
importable from here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from itertools import zip_longest
from typing import Any

import numpy as np

from corraoi.engine.block import SlotBlock, SourcesBlock
from corraoi.engine.slot_record import BY_NAME, NAMES, PER_ARM, SHARED
from corraoi.engine.slot_record import FLOAT_FIELDS as _FLOATS
from corraoi.engine.summary import SummaryAccumulator
from corraoi.errors import UsageError

from .diff_report import ConfigDifference, DiffReport, FieldDiff
from .runs import LogLike, as_log

#: The fields ``diff`` compares by default: every field of the slot record except the slot
#: number (corraoi.engine.slot_record). A field both runs lack compares equal; one that a
#: single run lacks differs at every slot.
DIFF_FIELDS: tuple[str, ...] = tuple(f for f in NAMES if f != "t")
#: Float fields: compared within ``atol`` (NaN equals NaN); every other field exactly.
FLOAT_FIELDS = _FLOATS
#: Configuration keys that are reported but do not make two runs different.
NOTE_KEYS = ("version",)
#: Slots read per step from each log.
BLOCK = 4096


def parse_fields(fields: Iterable[str] | None) -> tuple[str, ...]:
    """Field names from ``--fields`` (names or comma lists); all of DIFF_FIELDS if empty."""
    if not fields:
        return DIFF_FIELDS
    names: list[str] = []
    for item in fields:
        for name in item.split(","):
            name = name.strip()
            if not name:
                continue
            if name not in DIFF_FIELDS:
                raise UsageError(f"unknown field {name!r} (known: {', '.join(DIFF_FIELDS)})")
            if name not in names:
                names.append(name)
    if not names:
        raise UsageError(f"no field given (known: {', '.join(DIFF_FIELDS)})")
    return tuple(names)


def diff(
    a: LogLike,
    b: LogLike,
    *,
    fields: Sequence[str] | None = None,
    atol: float = 0.0,
    block: int = BLOCK,
) -> DiffReport:
    """Compare two recorded runs slot by slot (logs only: nothing is simulated).

    ``a`` and ``b`` are paths of corraoi logs or opened ``RunLog`` objects. ``fields``
    restricts the comparison (default: every logged field); ``atol`` is the absolute
    tolerance of the float fields (``estimator``, ``mu_hat``). Raises
    :class:`corraoi.errors.LogError` for a file that is not a readable corraoi log.
    """
    if not (atol >= 0 and math.isfinite(atol)):
        raise UsageError(f"atol must be a finite number >= 0, got {atol!r}")
    names = parse_fields(fields)
    la, lb = as_log(a), as_log(b)
    ca, cb = la.config.to_dict(), lb.config.to_dict()
    flat_a, flat_b = _flatten(ca), _flatten(cb)
    config: list[ConfigDifference] = []
    notes: list[ConfigDifference] = []
    for key in list(dict.fromkeys([*flat_a, *flat_b])):
        va, vb = flat_a.get(key), flat_b.get(key)
        if va != vb:
            (notes if key in NOTE_KEYS else config).append(ConfigDifference(key, va, vb))
    Ka, Kb = la.config.K, lb.config.K
    warnings = []
    if Ka != Kb:
        warnings.append(
            f"the runs have different numbers of arms ({Ka} and {Kb}): per-arm fields are "
            "not compared"
        )
    missing = [
        n for n in names if BY_NAME[n].may_be_absent and (n in la.absent) != (n in lb.absent)
    ]
    if missing:
        warnings.append(f"only one of the runs logs {', '.join(missing)}: not compared")
    Ma, Mb = la.config.sources, lb.config.sources
    if Ma != Mb:
        warnings.append(
            f"the runs have different numbers of sources ({Ma} and {Mb}): sources "
            f"1..{min(Ma, Mb)} are compared, source by source"
        )
    state = {
        n: _FieldState(n, comparable=(n not in PER_ARM or Ka == Kb) and n not in missing)
        for n in names
    }
    sa, sb = SummaryAccumulator(la.config), SummaryAccumulator(lb.config)
    for pa, pb in zip_longest(la.blocks(block), lb.blocks(block)):
        if pa is not None:
            sa.update(pa)
        if pb is not None:
            sb.update(pb)
        if pa is None or pb is None:
            continue
        n = min(len(pa), len(pb))
        if n < len(pa) or n < len(pb):
            pa, pb = _head(pa, n), _head(pb, n)
        for st in state.values():
            st.update(pa, pb, atol)
    return DiffReport(
        a=str(la.path),
        b=str(lb.path),
        a_label=la.config.label,
        b_label=lb.config.label,
        config=tuple(config),
        notes=tuple(notes),
        a_slots=la.n_slots,
        b_slots=lb.n_slots,
        a_status=la.status,
        b_status=lb.status,
        fields={n: st.result() for n, st in state.items()},
        a_summary=sa.result(),
        b_summary=sb.result(),
        atol=float(atol),
        warnings=tuple(warnings),
    )


class _FieldState:
    def __init__(self, name: str, *, comparable: bool) -> None:
        self.name = name
        self.comparable = comparable
        self.compared = 0
        self.differing = 0
        self.first: int | None = None
        self.a_value: Any = None
        self.b_value: Any = None
        self.source: int | None = None

    def update(self, a: SlotBlock | SourcesBlock, b: SlotBlock | SourcesBlock,
               atol: float) -> None:  # fmt: skip
        if isinstance(a, SourcesBlock) or isinstance(b, SourcesBlock):
            self._update_sources(_sources(a), _sources(b), atol)
            return
        n = len(a)
        self.compared += n
        if not self.comparable:
            self.differing += n
            if self.first is None and n:
                self.first = int(a.t[0])
            return
        if getattr(a, self.name) is None or getattr(b, self.name) is None:
            return  # a field neither run logs (the blocks of one run agree on it)
        ca, cb = a.column(self.name), b.column(self.name)
        if self.name in FLOAT_FIELDS:
            same = np.isclose(ca, cb, rtol=0.0, atol=atol, equal_nan=True)
        else:
            same = ca == cb
        if same.ndim > 1:
            same = same.all(axis=1)
        bad = np.flatnonzero(~same)
        if not bad.size:
            return
        self.differing += int(bad.size)
        if self.first is None:
            i = int(bad[0])
            self.first = int(a.t[i])
            self.a_value = _person(self.name, ca[i])
            self.b_value = _person(self.name, cb[i])

    def _update_sources(self, a: tuple[SlotBlock, ...], b: tuple[SlotBlock, ...],
                        atol: float) -> None:  # fmt: skip
        """Runs of several sources: source m of a against source m of b (as many as both
        have); a slot differs where any pair does, the first difference names its source."""
        n = len(a[0])
        self.compared += n
        if not self.comparable:
            self.differing += n
            if self.first is None and n:
                self.first = int(a[0].t[0])
            return
        pairs = [(x, y) for x, y in zip(a, b, strict=False) if getattr(x, self.name) is not None
                 and getattr(y, self.name) is not None]  # fmt: skip  (the sources both have)
        if not pairs:
            return
        same = np.stack([self._same(x.column(self.name), y.column(self.name), atol)
                         for x, y in pairs])  # fmt: skip
        bad = np.flatnonzero(~same.all(axis=0))
        if not bad.size:
            return
        self.differing += int(bad.size)
        if self.first is None:
            i = int(bad[0])
            m = int(np.argmin(same[:, i]))
            x, y = pairs[m]
            self.first = int(x.t[i])
            self.source = None if self.name in SHARED else m + 1
            self.a_value = _person(self.name, x.column(self.name)[i])
            self.b_value = _person(self.name, y.column(self.name)[i])

    def _same(self, ca: np.ndarray, cb: np.ndarray, atol: float) -> np.ndarray:
        """Per slot: the two columns agree (a float field within ``atol``)."""
        if self.name in FLOAT_FIELDS:
            same = np.isclose(ca, cb, rtol=0.0, atol=atol, equal_nan=True)
        else:
            same = ca == cb
        return same.all(axis=1) if same.ndim > 1 else same

    def result(self) -> FieldDiff:
        return FieldDiff(
            field=self.name,
            compared=self.compared,
            slots_differing=self.differing,
            first_slot=self.first,
            a_value=self.a_value,
            b_value=self.b_value,
            comparable=self.comparable,
            source=self.source,
        )


def _person(name: str, value: np.ndarray | np.generic) -> Any:
    """A field value as people read it: arms/states and candidate sets numbered from 1."""
    if BY_NAME[name].one_based:
        return int(value) + 1
    if name == "candidates":
        return [int(k) + 1 for k in np.flatnonzero(value)]
    if isinstance(value, np.ndarray):
        return [None if v != v else v for v in value.tolist()]  # NaN: no value (null)
    item = value.item()
    return None if item != item else item


def _head(b: SlotBlock | SourcesBlock, n: int) -> SlotBlock | SourcesBlock:
    return b.slice(0, n)


def _sources(b: SlotBlock | SourcesBlock) -> tuple[SlotBlock, ...]:
    """The block of each source (a single source's block: itself)."""
    return b.sources if isinstance(b, SourcesBlock) else (b,)


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


__all__ = [
    "BLOCK",
    "DIFF_FIELDS",
    "FLOAT_FIELDS",
    "NOTE_KEYS",
    "diff",
    "parse_fields",
]
