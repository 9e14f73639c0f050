"""The slot log written: its JSON Schema, its metadata records and the block encoder.

One MCAP message per slot on the slot topic (:data:`corraoi.recorder.vocab.SLOT_TOPIC`), JSON
encoded, arms and states numbered from 1 (``SlotBlock`` arrays are 0-based: the encoder
adds 1). The reading side, the strict decoder, is :mod:`corraoi.recorder.slotlog.decode`, which
re-exports these names; ``docs/log-format.md`` is the human description.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson

from corraoi.engine.slot_record import (
    BY_NAME,
    FLOAT32_MAX,
    REQUIRED,
    SlotField,
    record_for,
)
from corraoi.recorder.vocab import NS_PER_SLOT
from corraoi.recorder.vocab import SLOT_FLUSH_EVERY as FLUSH_EVERY
from corraoi.recorder.vocab import SLOT_FORMAT_NAME as FORMAT_NAME
from corraoi.recorder.vocab import SLOT_SCHEMA_NAME as SCHEMA_NAME

if TYPE_CHECKING:  # types only: corraoi.engine.block's import circle stays out of this module
    from corraoi.engine.block import RunConfig, SlotBlock, SourcesBlock

_NUMPY = orjson.OPT_SERIALIZE_NUMPY


def field_schema(f: SlotField, K: int, n: int | None) -> dict[str, Any]:
    """The JSON Schema of one field of the slot record (a run with K arms and n states;
    ``n`` None: a run without an instance, whose states are unknown)."""
    bound: dict[str, int | None] = {"K": K, "n": n}

    def number(v: str) -> int | float:
        b = bound.get(v)
        return b if b is not None else (float(v) if "." in v else int(v))

    desc = f.meaning
    if not f.per_arm:  # "numbered 1..K": the run's own numbers
        desc = desc.replace("1..K", f"1..{K}")
        desc = desc.replace("1..n", f"1..{n}") if n is not None else desc
    if f.json == "candidate scores":
        return {
            "type": "array",
            "description": desc + ": the scores of the arms of candidates, in its order (the "
            "others have none); [] at a slot not scored; +-3.4028235e38 is +-infinity",
            "items": {"type": "number"},
            "minItems": 0,
            "maxItems": K,
        }
    if f.json == "arm set":
        return {
            "type": "array",
            "description": desc,
            "items": {"type": "integer", "minimum": 1, "maximum": K},
            "minItems": 1,
            "maxItems": K,
            "uniqueItems": True,
        }
    kind = {"integer": "integer", "boolean": "boolean"}.get(f.json, "number")
    item: dict[str, Any] = {"type": kind}
    if f.minimum:
        item["minimum"] = number(f.minimum)
    if f.maximum and bound.get(f.maximum, 0) is not None:
        item["maximum"] = number(f.maximum)
    if not f.per_arm:
        return {"type": kind, "description": desc, **{k: v for k, v in item.items() if k != "type"}}
    return {"type": "array", "description": desc, "items": item, "minItems": K, "maxItems": K}


def slot_schema(config: RunConfig) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of one slot message of this run: a property per field
    of the slot record (corraoi.engine.slot_record), its required fields required."""
    from corraoi.engine.block import FIELDS  # the columns versions 1 and 2 always hold

    K, n = config.K, config.n_states
    properties = {f.name: field_schema(f, K, n) for f in record_for(config.sources)}
    version = config.format_version  # the run's own: the schema says what its metadata says
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"urn:corraoi:slot-event:v{version}",
        "title": SCHEMA_NAME,
        "description": f"One slot of a corraoi run ({FORMAT_NAME} version {version}); "
        "arms and states are numbered from 1.",
        "type": "object",
        "properties": properties,
        # the fields the run's version always holds (a Logger's log, version 3, may lack
        # every field the slot record says may be absent)
        "required": list(REQUIRED if config.policy.tier == "external" else FIELDS),
        "additionalProperties": False,
    }


def schema_bytes(config: RunConfig) -> bytes:
    return json.dumps(slot_schema(config), indent=1).encode()


def run_metadata(config: RunConfig, *, flush_every: int = FLUSH_EVERY) -> dict[str, str]:
    """The ``corraoi.run`` metadata record: flat strings, plus the full config as JSON."""
    inst, theory = config.instance, config.theory
    model: dict[str, str] = {}  # what the instance says (a run without one: nothing)
    if inst is not None and theory is not None:
        model = {
            "states": str(inst.n_states),
            "p": json.dumps([float(v) for v in inst.p]),
            "Y": json.dumps(inst.Y.astype(int).tolist()),
            "mu": json.dumps([float(v) for v in theory.mu]),
            "best_arm": str(theory.best_arm + 1),
            "mu_star": repr(float(theory.mu_star)),
            "competitive_arms": json.dumps([a + 1 for a in theory.competitive]),
        }
    return {
        "format": FORMAT_NAME,
        "format_version": str(config.format_version),
        "corraoi_version": config.version,
        "label": config.label,
        "instance": config.instance_name,
        "policy": config.policy.name,
        "params": json.dumps(config.policy.params, sort_keys=True),
        "seed": str(config.seed),
        "horizon": str(config.horizon),
        "arms": str(config.K),
        **model,
        "numbering": "arms and states from 1",
        "log_time": f"t * {NS_PER_SLOT} ns",
        "flush_every": str(flush_every),
        "config": json.dumps(config.to_dict(), sort_keys=True),
    }


def end_metadata(
    *,
    slots: int,
    horizon: int,
    last: SlotBlock | None,
    error: str | None = None,
    complete: bool | None = None,
) -> dict[str, str]:
    """The ``corraoi.end`` metadata record written by a writer that finished its file
    (``error``: the run stopped on that error, status ``failed``; ``complete``: the status
    when the writer says it, else complete at the horizon)."""
    done = slots >= horizon if complete is None else complete
    status = "complete" if done else "interrupted"
    out = {"status": "failed" if error is not None else status, "slots": str(slots)}
    if error is not None:
        out["error"] = error
    if last is not None and len(last):  # what the run holds (a Logger's may lack them)
        held = last.fields()
        if "regret" in held:
            out["regret"] = str(int(last.regret[-1]))
        if "estimator" in held:
            out["estimator"] = repr(float(last.estimator[-1]))
        if "pulls" in held:
            out["pulls"] = json.dumps([int(v) for v in last.pulls[-1]])
    return out


def sources_end_metadata(
    *,
    slots: int,
    horizon: int,
    last: SourcesBlock | None,
    error: str | None = None,
    complete: bool | None = None,
) -> dict[str, str]:
    """The ``corraoi.end`` record of a run of several sources: as a single source's, with
    ``regret`` the run's (the sum over the sources), ``regret_by_source`` each source's, and
    ``pulls`` each source's pulls (a list per source); no ``estimator``."""
    out = end_metadata(slots=slots, horizon=horizon, last=None, error=error, complete=complete)
    if last is not None and len(last):
        held = last.sources[0].fields()
        if "regret" in held:
            each = [int(s.regret[-1]) for s in last.sources]
            out["regret"] = str(sum(each))
            out["regret_by_source"] = json.dumps(each)
        if "pulls" in held:
            out["pulls"] = json.dumps([[int(v) for v in s.pulls[-1]] for s in last.sources])
    return out


class BlockEncoder:
    """Encodes a SlotBlock into one JSON message per slot, a column at a time.

    Numbers are formatted by orjson a whole column at a time (shortest round-trip text, so
    the decoder gets back the same float64 values); the messages are then put together by
    one ``bytes.join`` over the columns interleaved with the constant key texts, and split
    at a separator no JSON text of ours contains (a newline). That is about twice as fast
    as formatting each slot with ``bytes %`` (benchmarks/bench_record.py). The slot log
    takes them unsplit (:meth:`encode_framed`): each message after room for its MCAP
    record header, which starts with that newline, so the writer finds them. A column of few
    distinct texts (flags, arm, state, candidate set) is a lookup: the key texts beside it
    and neighbouring lookups are folded into its texts, so the join has fewer parts.
    """

    def __init__(self, K: int) -> None:
        self.K = int(K)
        self._weights = (1 << np.arange(self.K, dtype=np.int64)) if self.K <= 62 else None
        self._sets: dict[int, bytes] = {}

    def _candidates(self, mask: np.ndarray) -> list[bytes] | _Lookup:
        if self._weights is None:  # too many arms for a bit code: one row at a time
            return [orjson.dumps(np.flatnonzero(row) + 1, option=_NUMPY) for row in mask]
        codes, inverse = np.unique(mask.astype(np.int64) @ self._weights, return_inverse=True)
        sets = self._sets
        texts: list[bytes] = []
        for code in codes.tolist():
            text = sets.get(code)
            if text is None:
                text = orjson.dumps([k + 1 for k in range(self.K) if code >> k & 1])
                sets[code] = text
            texts.append(text)
        return _Lookup(texts, inverse)

    def _column(self, f: SlotField, values: np.ndarray, n: int) -> list[bytes] | _Lookup:
        """JSON text of each slot's value of field ``f`` (a list's without its brackets), or
        for a field of few distinct texts those texts and each slot's index into them."""
        if f.json == "arm set":
            return self._candidates(values)
        if f.json == "candidate scores":
            return _candidate_rows(np.clip(values, -FLOAT32_MAX, FLOAT32_MAX))
        if f.json == "boolean":
            return _Lookup(_BOOL_TEXTS, np.asarray(values, dtype=np.intp))
        if f.one_based and not f.per_arm and n:  # an arm or a state: few distinct numbers
            top = int(values.max())
            if top < _LOOKUP_MAX and int(values.min()) >= 0:
                return _Lookup(_numbers(top + 1), np.asarray(values, dtype=np.intp))
        if f.json == "float32":  # JSON has no infinity: +-FLOAT32_MAX stand for it
            values = np.clip(np.asarray(values, dtype=np.float32), -FLOAT32_MAX, FLOAT32_MAX)
        elif f.one_based:
            values = values + 1
        return _rows(values, n) if f.per_arm else _items(values)

    def encode(self, b: SlotBlock) -> list[bytes]:
        """The block's messages, one bytes object per slot."""
        if len(b) == 0:
            return []
        messages = self._join(b, b"", b"\n", b"").split(b"\n")
        messages.pop()  # the empty text after the last newline (no copy of the whole text)
        return messages

    def encode_framed(self, b: SlotBlock, room: bytes) -> bytearray:
        """The block's messages back to back in one buffer, each after ``room`` (where
        :meth:`~corraoi.recorder.slotlog.chunks.ChunkWriter.frame` writes its record header):
        no bytes object per message."""
        return self._join(b, room, b"", bytearray()) if len(b) else bytearray()

    def _join(self, b: SlotBlock, room: bytes, sep: bytes, into: Any) -> Any:
        """The messages of ``b``, each after ``room`` and followed by ``sep``, joined by
        ``into.join`` (bytes or a bytearray)."""
        n = len(b)
        names = b.fields()
        keys = _keys(names)
        end = (b"]}" if _bracketed(BY_NAME[names[-1]]) else b"}") + sep
        # the texts of a message in order: key, value, key, value, ..., end. A field of
        # few distinct texts (a flag, an arm, a state, a candidate set) takes the keys on
        # either side into its texts, and neighbours of that kind are one (their texts'
        # product), so the join has fewer parts
        folded: list[bytes | list[bytes] | _Lookup] = []
        segments = [s for key, f in zip(keys, names, strict=True)
                    for s in (key, self._column(BY_NAME[f], b.column(f), n))]  # fmt: skip
        segments[0] = room + keys[0]
        for seg in (*segments, end):
            prev = folded[-1] if folded else None
            if isinstance(seg, bytes) and isinstance(prev, _Lookup):
                folded[-1] = _Lookup([t + seg for t in prev.texts], prev.index)
                continue
            if isinstance(seg, _Lookup) and isinstance(prev, bytes):
                folded.pop()
                seg = _Lookup([prev + t for t in seg.texts], seg.index)
                prev = folded[-1] if folded else None
            if isinstance(seg, _Lookup) and isinstance(prev, _Lookup):
                m = len(seg.texts)
                if len(prev.texts) * m <= _LOOKUP_MAX:
                    folded[-1] = _Lookup([a + z for a in prev.texts for z in seg.texts],
                                         prev.index * m + seg.index)  # fmt: skip
                    continue
            folded.append(seg)
        step = len(folded)
        parts: list[bytes] = [b""] * (step * n)
        for i, seg in enumerate(folded):
            if isinstance(seg, _Lookup):
                table = np.empty(len(seg.texts), dtype=object)
                table[:] = seg.texts
                parts[i::step] = table[seg.index].tolist()
            else:
                parts[i::step] = [seg] * n if isinstance(seg, bytes) else seg
        return into.join(parts)


def _candidate_rows(table: np.ndarray) -> list[bytes]:
    """JSON text of each row of a (B, K) float32 table without its NaN items (the arms
    outside the candidate set, a slot not scored) nor the brackets. Where every row has its
    NaN at the same arms, the other arms' columns written at once; else the table written
    at once (NaN as null), its nulls dropped by three replaces over the whole text (after
    the first two a row keeps a null only where it was all nulls: ``[null]``), then split
    (0.3 us a slot at K = 4, against 0.15 without the replaces)."""
    has = ~np.isnan(table)
    if len(has) and (has == has[0]).all():  # the same arms scored at every slot (the usual
        # block: a candidate set that holds, or every arm): only those columns are written
        if not has[0].any():
            return [b""] * len(table)
        if not has[0].all():
            table = table[:, has[0]]
        return _rows(table, len(table))
    text = orjson.dumps(np.ascontiguousarray(table), option=_NUMPY)
    if b"null" in text:
        text = text.replace(b"null,", b"").replace(b",null", b"").replace(b"[null]", b"[]")
    return text[2:-2].split(b"],[")


def _bracketed(f: SlotField) -> bool:
    """The encoder writes the field's brackets around its rows (a per-arm list of numbers)."""
    return f.per_arm and f.json != "arm set" or f.json == "candidate scores"


@functools.cache
def _keys(names: tuple[str, ...]) -> tuple[bytes, ...]:
    """The text before each value of a message of these fields (``{"t":``, ``,"x":``, ...,
    ``],"pulls":[``); ``encode`` ends each message with "}\n" (or "]}\n") and splits at the
    newlines (orjson escapes any newline inside a JSON string); ``encode_framed`` puts the
    room for a record header, which starts with a newline, before each."""
    out = []
    for i, name in enumerate(names):
        before = b"]" if i and _bracketed(BY_NAME[names[i - 1]]) else b""
        after = b"[" if _bracketed(BY_NAME[name]) else b""
        out.append(before + (b"," if i else b"{") + orjson.dumps(name) + b":" + after)
    return tuple(out)


_BOOL_TEXTS = [b"false", b"true"]
#: the most texts a lookup column holds (an arm or state numbered beyond is written as
#: numbers are; two neighbouring lookups beyond it stay two)
_LOOKUP_MAX = 4096


@functools.cache
def _numbers(m: int) -> list[bytes]:
    """The texts of 1..m."""
    return [b"%d" % (v + 1) for v in range(m)]


@dataclasses.dataclass
class _Lookup:
    """A column of few distinct texts: ``texts[index[i]]`` is slot i's."""

    texts: list[bytes]
    index: np.ndarray


def _items(column: np.ndarray) -> list[bytes]:
    """JSON text of each element of a 1-D numeric array."""
    return orjson.dumps(np.ascontiguousarray(column), option=_NUMPY)[1:-1].split(b",")


def _rows(table: np.ndarray, n: int) -> list[bytes]:
    """JSON text of each row of a 2-D numeric array, without the brackets."""
    if table.shape[1] == 0:
        return [b""] * n
    return orjson.dumps(np.ascontiguousarray(table), option=_NUMPY)[2:-2].split(b"],[")


__all__ = [
    "BlockEncoder",
    "end_metadata",
    "field_schema",
    "run_metadata",
    "schema_bytes",
    "slot_schema",
    "sources_end_metadata",
]
