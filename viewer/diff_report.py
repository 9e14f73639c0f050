"""What ``diff`` finds, and how it reads: :class:`DiffReport` (the configuration differences,
per field the first slot where two runs diverge, the final figures of both), its text
(``corraoi diff``) and its JSON (``--json``). :func:`corraoi.viewer.diffs.diff` makes one.

Arms and states are numbered from 1 in everything the report shows.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from corraoi.engine.summary import RunSummary

#: What makes a run's hidden path (and the channel's answers on it): two runs are paired
#: (common random numbers: ``diff`` compares the policies alone) only when these agree.
PAIRING = ("instance", "channel", "seed", "streams")
#: Keys under those that only name things: a renamed copy of an instance is still paired.
NAMES_ONLY = ("instance.name", "instance.arms", "instance.states", "channel.source")


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
    cannot be compared (per-arm fields of runs with different numbers of arms). Runs of
    several sources are compared source by source (source m of a with source m of b): a
    slot differs where any pair differs, and ``source`` is the source (from 1) of the
    first difference (None for single-source runs).
    """

    field: str
    compared: int
    slots_differing: int
    first_slot: int | None
    a_value: Any = None
    b_value: Any = None
    comparable: bool = True
    source: int | None = None

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
            **({} if self.source is None else {"source": self.source}),
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
    def unpaired(self) -> tuple[str, ...]:
        """Why the runs are not paired (e.g. ``seed (0 != 1)``): what of :data:`PAIRING`
        differs; empty when they are, one hidden path under both."""
        out = []
        for part in PAIRING:
            keys = [d for d in self.config if (d.key == part or d.key.startswith(part + "."))
                    and d.key not in NAMES_ONLY]  # fmt: skip
            if not keys:
                continue
            if len(keys) == 1 and keys[0].key == part:
                out.append(f"{part} ({_fmt(keys[0].a)} != {_fmt(keys[0].b)})")
                continue
            by = {d.key: d for d in self.config}
            named = by.get(f"{part}.name") or by.get(f"{part}.kind")
            if named is not None:  # an i.i.d. run's log has no channel: iid
                a, b = (("iid" if v is None and part == "channel" else _fmt(v))
                        for v in (named.a, named.b))  # fmt: skip
                out.append(f"{part} ({a} != {b})")
            else:
                which = ", ".join(d.key.removeprefix(part + ".") for d in keys)
                out.append(f"{part} ({which} differ)")
        return tuple(out)

    @property
    def paired(self) -> bool:
        """Whether both runs had one hidden path (the same instance, channel and seed), so
        that every difference is the policies'. False: :meth:`message` says so first."""
        return not self.unpaired

    def pairing_line(self) -> str | None:
        """The line that opens the report of runs that are not paired (None when paired)."""
        if self.paired:
            return None
        return (f"not paired: {', '.join(self.unpaired)}: the runs did not see one hidden "
                "path, so their slots differ by more than the policy")  # fmt: skip

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
        """(slot, field) of the earliest differing slot over the fields both runs hold
        comparably (a field only one run logs, or per-arm fields of runs with other numbers
        of arms, differ everywhere and say nothing of where the runs part), or None."""
        firsts = [
            (f.first_slot, i, name)
            for i, (name, f) in enumerate(self.fields.items())
            if f.first_slot is not None and f.comparable
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
        ea, eb = a.regret_by_source or (), b.regret_by_source or ()
        for m in range(max(len(ea), len(eb))):  # runs of several sources: each one's regret
            ra = ea[m] if m < len(ea) else None
            rb = eb[m] if m < len(eb) else None
            rows.append((f"regret source {m + 1}", ra, rb, _minus(rb, ra)))
        if ea or eb:
            rows.append(("collisions", a.collisions, b.collisions,
                         _minus(b.collisions, a.collisions)))  # fmt: skip
        K = max(len(a.pulls), len(b.pulls))
        for k in range(K):
            pa = a.pulls[k] if k < len(a.pulls) else None
            pb = b.pulls[k] if k < len(b.pulls) else None
            rows.append((f"pulls arm {k + 1}", pa, pb, _minus(pb, pa)))
        rows += [
            ("best-arm share", a.best_share, b.best_share, _minus(b.best_share, a.best_share)),
            ("overrides", a.overrides, b.overrides, _minus(b.overrides, a.overrides)),
            ("on best arm from slot", a.settled_at, b.settled_at,
             _minus(b.settled_at, a.settled_at)),
        ]  # fmt: skip
        return rows

    def message(self) -> str:
        """A readable account (the text ``corraoi diff`` prints; good in an assert). Runs
        that are not paired are said so on the first line (:meth:`pairing_line`)."""
        pairing = self.pairing_line()
        lines = [] if pairing is None else [pairing]
        lines += [
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
        w = max([12, *map(len, self.fields)])  # override_threshold is longer than 12
        lines.append(f"  {'field':<{w}} {'first slot':>10} {'slots differing':>18}  values there")
        for name, f in self.fields.items():
            if not f.comparable:
                lines.append(f"  {name:<{w}} {'-':>10} {'not comparable':>18}  (different arms)")
                continue
            first = "-" if f.first_slot is None else str(f.first_slot)
            count = f"{f.slots_differing} of {f.compared}"
            where = "" if f.first_slot is None else f"a={_fmt(f.a_value)} b={_fmt(f.b_value)}"
            if f.source is not None and f.first_slot is not None:
                where = f"source {f.source}: {where}"
            lines.append(f"  {name:<{w}} {first:>10} {count:>18}  {where}".rstrip())
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
        parts = [] if self.paired else ["not paired"]
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
            "paired": self.paired,
            "unpaired": list(self.unpaired),
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

    def __repr__(self) -> str:
        """One line: the two files and the verdict (:meth:`message` has the whole account)."""
        return f"DiffReport({Path(self.a).name!r}, {Path(self.b).name!r}: {self.verdict()})"

    def _repr_html_(self) -> str:
        """In Jupyter: the pairing first, the two runs, then a table of the fields (the first
        slot where they differ, how many slots, the values there), the final regret and the
        verdict."""

        def cells(tag: str, values: list[Any]) -> str:
            return "".join(f"<{tag} style='text-align:left'>{html.escape(str(v))}</{tag}>"
                           for v in values)  # fmt: skip

        head = ["field", "first slot", "slots differing", "a there", "b there"]
        runs = "<br>".join(
            html.escape(f"{name}: {path}  {label}  ({slots:,} slots, {status})")
            for name, path, label, slots, status in (
                ("a", self.a, self.a_label, self.a_slots, self.a_status),
                ("b", self.b, self.b_label, self.b_slots, self.b_status),
            )
        )
        rows = []
        for name, f in self.fields.items():
            if not f.comparable:
                rows.append([name, "-", "not comparable", "", ""])
                continue
            first = "-" if f.first_slot is None else f"{f.first_slot:,}"
            there = ["", ""] if f.first_slot is None else [_fmt(f.a_value), _fmt(f.b_value)]
            rows.append([name, first, f"{f.slots_differing:,} of {f.compared:,}", *there])
        regret = next(r for r in self.finals() if r[0] == "regret")
        rows.append(["final regret", "", f"b - a = {_num(regret[3], sign=True)}",
                     _num(regret[1]), _num(regret[2])])  # fmt: skip
        pairing = self.pairing_line()
        lead = "" if pairing is None else f"<p><b>{html.escape(pairing)}</b></p>"
        body = "".join(f"<tr>{cells('td', r)}</tr>" for r in rows)
        return (
            f"<div>{lead}<p>{runs}</p><table><thead><tr>{cells('th', head)}</tr></thead>"
            f"<tbody>{body}</tbody></table><p>{html.escape(self.verdict())}</p></div>"
        )


def _minus(x: Any, y: Any) -> Any:
    if x is None or y is None:
        return None
    return x - y


def _fmt(v: Any) -> str:
    if v is None:
        return "(none)"
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list) and any(isinstance(x, float) for x in v):  # None: no value (NaN)
        return "[" + ", ".join("-" if x is None else f"{x:.4g}" for x in v) + "]"
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


__all__ = ["NAMES_ONLY", "PAIRING", "ConfigDifference", "DiffReport", "FieldDiff"]
