"""Diff two recorded runs slot by slot, streaming both logs side by side.

``diff(a, b)`` returns a :class:`DiffReport`: the configuration differences, then per
logged field the first slot where the runs diverge and how many slots differ, and the
final figures of both runs. It is what ``corraoi diff`` prints and what a test suite
asserts on::

    report = viewer.diff("a.mcap", "b.mcap")
    assert report.identical, report.message()

Arms and states are numbered from 1 in everything the report shows.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import zip_longest
from typing import Any

import numpy as np

from corraoi.block import ARM_FIELDS, FIELDS, SCALAR_FIELDS, SlotBlock
from corraoi.errors import UsageError

from .runs import LogLike, as_log
from .summary import RunSummary, SummaryAccumulator

#: The fields ``diff`` compares by default: every logged column except the slot number.
DIFF_FIELDS: tuple[str, ...] = SCALAR_FIELDS + ARM_FIELDS
#: Float fields: compared within ``atol``; every other field compares exactly.
FLOAT_FIELDS = ("estimator", "mu_hat")
#: Fields numbered from 1 for people (0-based in SlotBlock).
_ONE_BASED = ("x", "arm")
#: Configuration keys that are reported but do not make two runs different.
NOTE_KEYS = ("version",)
#: Slots read per step from each log.
BLOCK = 4096


@dataclass(frozen=True)
class ConfigDifference:
    """One configuration key (dotted, e.g. ``policy.name``) whose values differ."""

    key: str
    a: Any
    b: Any

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "a": self.a, "b": self.b}


@dataclass(frozen=True)
class FieldDiff:
    """How one field of the two runs compares over the slots both runs recorded.

    ``first_slot`` is the first slot t where they differ (``None``: never), ``a_value`` and
    ``b_value`` the values there (arms and states numbered from 1), ``slots_differing`` how
    many of the ``compared`` common slots differ. ``comparable`` is False when the field
    cannot be compared (per-arm fields of runs with different numbers of arms).
    """

    field: str
    compared: int
    slots_differing: int
    first_slot: int | None
    a_value: Any = None
    b_value: Any = None
    comparable: bool = True

    @property
    def identical(self) -> bool:
        return self.comparable and self.slots_differing == 0

    def to_dict(self) -> dict[str, Any]:
        return {
            "field": self.field,
            "identical": self.identical,
            "comparable": self.comparable,
            "compared": self.compared,
            "slots_differing": self.slots_differing,
            "first_slot": self.first_slot,
            "a": self.a_value,
            "b": self.b_value,
        }


@dataclass(frozen=True)
class DiffReport:
    """The comparison of two runs. ``identical`` is what a test asserts."""

    a: str
    b: str
    a_label: str
    b_label: str
    config: tuple[ConfigDifference, ...]
    notes: tuple[ConfigDifference, ...]
    a_slots: int
    b_slots: int
    a_status: str
    b_status: str
    fields: dict[str, FieldDiff]
    a_summary: RunSummary
    b_summary: RunSummary
    atol: float = 0.0
    warnings: tuple[str, ...] = field(default=())

    @property
    def same_config(self) -> bool:
        return not self.config

    @property
    def same_slots(self) -> bool:
        return self.a_slots == self.b_slots

    @property
    def identical(self) -> bool:
        """Same configuration, same number of slots and every compared field equal."""
        return (
            self.same_config and self.same_slots and all(f.identical for f in self.fields.values())
        )

    @property
    def differing_fields(self) -> list[str]:
        return [name for name, f in self.fields.items() if not f.identical]

    @property
    def first_divergence(self) -> tuple[int, str] | None:
        """(slot, field) of the earliest differing slot over all fields, or None."""
        firsts = [
            (f.first_slot, i, name)
            for i, (name, f) in enumerate(self.fields.items())
            if f.first_slot is not None
        ]
        if not firsts:
            return None
        slot, _, name = min(firsts)
        return slot, name

    def __getitem__(self, name: str) -> FieldDiff:
        return self.fields[name]

    def finals(self) -> list[tuple[str, Any, Any, Any]]:
        """(figure, a, b, b - a) of the final figures; arms numbered from 1."""
        a, b = self.a_summary, self.b_summary
        rows: list[tuple[str, Any, Any, Any]] = [
            ("slots", a.slots, b.slots, b.slots - a.slots),
            ("regret", a.regret, b.regret, _minus(b.regret, a.regret)),
            ("estimator", a.estimator, b.estimator, _minus(b.estimator, a.estimator)),
        ]
        K = max(len(a.pulls), len(b.pulls))
        for k in range(K):
            pa = a.pulls[k] if k < len(a.pulls) else None
            pb = b.pulls[k] if k < len(b.pulls) else None
            rows.append((f"pulls arm {k + 1}", pa, pb, _minus(pb, pa)))
        rows += [
            ("best-arm share", a.best_share, b.best_share, _minus(b.best_share, a.best_share)),
            ("overrides", a.overrides, b.overrides, b.overrides - a.overrides),
            ("on best arm from slot", a.settled_at, b.settled_at,
             _minus(b.settled_at, a.settled_at)),
        ]  # fmt: skip
        return rows

    def message(self) -> str:
        """A readable account (the text ``corraoi diff`` prints; good in an assert)."""
        lines = [
            f"--- {self.a}  {self.a_label}  ({self.a_slots} slots, {self.a_status})",
            f"+++ {self.b}  {self.b_label}  ({self.b_slots} slots, {self.b_status})",
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        if self.config:
            lines.append("configuration differs:")
            lines += [f"  {d.key}: {_fmt(d.a)} != {_fmt(d.b)}" for d in self.config]
        else:
            lines.append("configuration: identical")
        lines += [f"note: {d.key} differs: {_fmt(d.a)} != {_fmt(d.b)}" for d in self.notes]
        if not self.same_slots:
            lines.append(
                f"slots: a has {self.a_slots}, b has {self.b_slots}; fields are compared "
                f"over the first {min(self.a_slots, self.b_slots)}"
            )
        tol = f" (float fields within atol {self.atol:g})" if self.atol else ""
        lines.append(f"per field{tol}:")
        lines.append(f"  {'field':<12} {'first slot':>10} {'slots differing':>18}  values there")
        for name, f in self.fields.items():
            if not f.comparable:
                lines.append(f"  {name:<12} {'-':>10} {'not comparable':>18}  (different arms)")
                continue
            first = "-" if f.first_slot is None else str(f.first_slot)
            count = f"{f.slots_differing} of {f.compared}"
            where = "" if f.first_slot is None else f"a={_fmt(f.a_value)} b={_fmt(f.b_value)}"
            lines.append(f"  {name:<12} {first:>10} {count:>18}  {where}".rstrip())
        lines.append("final figures:")
        lines.append(f"  {'':<22} {'a':>12} {'b':>12} {'b - a':>12}")
        for name, va, vb, d in self.finals():
            pct = name == "best-arm share"
            lines.append(
                f"  {name:<22} {_num(va, pct=pct):>12} {_num(vb, pct=pct):>12} "
                f"{_num(d, sign=True, pct=pct):>12}"
            )
        lines.append(self.verdict())
        return "\n".join(lines)

    def verdict(self) -> str:
        if self.identical:
            return f"identical: {self.a_slots} slots, every field equal"
        parts = []
        if self.config:
            parts.append(f"{len(self.config)} configuration key(s) differ")
        if not self.same_slots:
            parts.append(f"slot counts differ ({self.a_slots} vs {self.b_slots})")
        names = self.differing_fields
        if names:
            parts.append(f"{len(names)} of {len(self.fields)} fields differ ({', '.join(names)})")
        first = self.first_divergence
        if first is not None:
            parts.append(f"first divergence at slot {first[0]} ({first[1]})")
        return "different: " + "; ".join(parts)

    def assert_identical(self) -> None:
        """Raise AssertionError with :meth:`message` unless the runs are identical."""
        if not self.identical:
            raise AssertionError(self.message())

    def to_dict(self) -> dict[str, Any]:
        """The JSON of ``corraoi diff --json``."""
        first = self.first_divergence
        return {
            "identical": self.identical,
            "a": {"path": self.a, "label": self.a_label, "slots": self.a_slots,
                  "status": self.a_status, "summary": self.a_summary.to_dict()},
            "b": {"path": self.b, "label": self.b_label, "slots": self.b_slots,
                  "status": self.b_status, "summary": self.b_summary.to_dict()},
            "config": [d.to_dict() for d in self.config],
            "notes": [d.to_dict() for d in self.notes],
            "atol": self.atol,
            "fields": {name: f.to_dict() for name, f in self.fields.items()},
            "first_divergence": None if first is None else {"slot": first[0], "field": first[1]},
            "finals": {name: {"a": va, "b": vb, "b_minus_a": d}
                       for name, va, vb, d in self.finals()},
            "warnings": list(self.warnings),
        }  # fmt: skip

    def __str__(self) -> str:
        return self.message()


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
    :class:`recorder.errors.LogError` for a file that is not a readable corraoi log.
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
    Ka, Kb = la.config.instance.K, lb.config.instance.K
    warnings = []
    if Ka != Kb:
        warnings.append(
            f"the runs have different numbers of arms ({Ka} and {Kb}): per-arm fields are "
            "not compared"
        )
    state = {n: _FieldState(n, comparable=(n not in ARM_FIELDS or Ka == Kb)) for n in names}
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

    def update(self, a: SlotBlock, b: SlotBlock, atol: float) -> None:
        n = len(a)
        self.compared += n
        if not self.comparable:
            self.differing += n
            if self.first is None and n:
                self.first = int(a.t[0])
            return
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

    def result(self) -> FieldDiff:
        return FieldDiff(
            field=self.name,
            compared=self.compared,
            slots_differing=self.differing,
            first_slot=self.first,
            a_value=self.a_value,
            b_value=self.b_value,
            comparable=self.comparable,
        )


def _person(name: str, value: np.ndarray | np.generic) -> Any:
    """A field value as people read it: arms/states and candidate sets numbered from 1."""
    if name in _ONE_BASED:
        return int(value) + 1
    if name == "candidates":
        return [int(k) + 1 for k in np.flatnonzero(value)]
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value.item()


def _head(b: SlotBlock, n: int) -> SlotBlock:
    return SlotBlock(**{f: b.column(f)[:n] for f in FIELDS})


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out


def _minus(x: Any, y: Any) -> Any:
    if x is None or y is None:
        return None
    return x - y


def _fmt(v: Any) -> str:
    if v is None:
        return "(none)"
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list) and v and isinstance(v[0], float):
        return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
    return str(v)


def _num(v: Any, *, sign: bool = False, pct: bool = False) -> str:
    if v is None:
        return "-"
    if pct:
        return f"{v:+.2%}" if sign else f"{v:.2%}"
    if isinstance(v, float):
        text = f"{v:+.6g}" if sign else f"{v:.6g}"
        return text
    if isinstance(v, int) and sign:
        return f"{v:+d}"
    return str(v)
