"""The slot log read back: the strict decoder of slot messages.

One MCAP message per slot on :data:`SLOT_TOPIC`, JSON encoded. Arms and states are numbered
from 1 in the log (``SlotBlock`` arrays are 0-based: the decoder subtracts 1). The names
of the format are defined in :mod:`corraoi.recorder.vocab` and its writing side (schema, metadata,
encoder) in :mod:`corraoi.recorder.slotlog.encode`, whose functions are re-exported here.
``docs/log-format.md`` is the human description.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import orjson

from corraoi.engine.block import FIELDS, NONE_FIELDS, RunConfig, SlotBlock, absent_column
from corraoi.engine.slot_record import BY_NAME, FLOAT32_MAX, NAMES, REQUIRED
from corraoi.errors import LogError

# The slot log's names (corraoi.recorder.vocab)
from corraoi.recorder.vocab import (
    RUN_METADATA,
    SLOT_FORMAT_NAME,
    SLOT_FORMAT_VERSION,
)

#: Message keys in the order the encoder writes them: the required fields, then those of
#: the optional ones a run gives (corraoi.engine.slot_record).
MESSAGE_KEYS = NAMES


def empty_block(K: int) -> SlotBlock:
    i64 = np.zeros(0, dtype=np.int64)
    return SlotBlock(
        t=i64,
        x=i64.copy(),
        arm=i64.copy(),
        success=np.zeros(0, dtype=bool),
        aoi=i64.copy(),
        oracle_aoi=i64.copy(),
        regret=i64.copy(),
        estimator=np.zeros(0, dtype=np.float64),
        override=np.zeros(0, dtype=bool),
        mu_hat=np.zeros((0, K), dtype=np.float64),
        pulls=np.zeros((0, K), dtype=np.int64),
        candidates=np.zeros((0, K), dtype=bool),
    )


#: Slot values are int64 in every array: a value beyond is refused by the reader.
_I64_MIN, _I64_MAX = -(2**63), 2**63 - 1
_INT_FIELDS = ("t", "x", "arm", "aoi", "oracle_aoi", "regret")
#: The flags a block holds as None when its run lacks them (``forced``, ``collided``).
_NONE_FLAGS = tuple(f for f in NONE_FIELDS if BY_NAME[f].json == "boolean")


def _shown(value: Any) -> str:
    """A slot value as a message quotes it: short, and with its JSON type."""
    if isinstance(value, bool):
        return f"{str(value).lower()} (a bool)"
    if isinstance(value, int):
        return (
            f"{value} (outside the 64-bit integer range)"
            if not (_I64_MIN <= value <= _I64_MAX)
            else f"{value}"
        )
    if isinstance(value, float):
        if value.is_integer() and abs(value) >= 2.0**63:  # a JSON integer beyond int64
            return f"{value:.6g} (outside the 64-bit integer range)"
        return (
            f"{value!r} (a number with a fraction)"
            if not value.is_integer()
            else (f"{value!r} (a float)")
        )
    if isinstance(value, str):
        text = value if len(value) <= 40 else value[:37] + "..."
        return f"{json.dumps(text)} (a string)"
    if value is None:
        return "null"
    if isinstance(value, list):
        return f"a list of {len(value)} items"
    if isinstance(value, dict):
        return "an object"
    return type(value).__name__


class _Bad(Exception):
    """One invalid slot value: (row index, field, value shown, expected)."""

    def __init__(self, row: int, field: str, shown: str, expected: str) -> None:
        super().__init__(row, field, shown, expected)
        self.row, self.field, self.shown, self.expected = row, field, shown, expected


def _is_int(v: Any) -> bool:
    return type(v) is int and _I64_MIN <= v <= _I64_MAX


def _first(values: Sequence[Any], ok: Any) -> int:
    for i, v in enumerate(values):
        if not ok(v):
            return i
    return -1


def _int_column(values: list[Any], field: str) -> np.ndarray:
    arr = np.asarray(values) if values else np.zeros(0, dtype=np.int64)
    if arr.dtype != np.int64 or arr.ndim != 1:
        i = _first(values, _is_int)
        if i < 0:  # pragma: no cover - numpy and the check agree on every value
            i = 0
        raise _Bad(i, field, _shown(values[i]), "an integer (int64)")
    return arr


def _bool_column(values: list[Any], field: str) -> np.ndarray:
    arr = np.asarray(values)
    if arr.dtype != np.bool_ or arr.ndim != 1:
        i = _first(values, lambda v: type(v) is bool)
        raise _Bad(max(i, 0), field, _shown(values[max(i, 0)]), "a JSON bool (true or false)")
    return arr


def _real(v: Any) -> bool:
    return type(v) is float or _is_int(v)


def _table(values: list[Any], field: str, K: int, ok: Any, expected: str) -> np.ndarray:
    """A (B, K) column: each row a list of K numbers of the kind ``ok`` accepts."""
    fine = set(map(type, values)) == {list} and set(map(len, values)) == {K}
    for i, row in enumerate(() if fine else values):
        if type(row) is not list or len(row) != K:
            raise _Bad(i, field, _shown(row), f"a list of {K} numbers (one per arm)")
    arr = np.asarray(values)
    if (
        arr.dtype.kind not in ("i", "f")
        or arr.shape != (len(values), K)
        or (expected.startswith("integers") and arr.dtype != np.int64)
    ):
        for i, row in enumerate(values):
            j = _first(row, ok)
            if j >= 0:
                raise _Bad(i, f"{field}[{j + 1}]", _shown(row[j]), expected)
        raise _Bad(0, field, "not a table of numbers", expected)  # pragma: no cover
    return arr


def decode_messages(
    payloads: Sequence[bytes | memoryview], K: int, n_states: int | None, *, where: str
) -> SlotBlock:
    """The SlotBlock of consecutive slot messages (JSON bytes), validated strictly.

    Every field must have its JSON type (an integer is never a bool or a float, a bool is
    never a number or a string), integers must fit int64, x in 1..n_states, arm in 1..K,
    aoi and oracle_aoi >= 1, pulls >= 0, mu_hat in [0, 1], candidates distinct arms in
    1..K, exactly the fields of the schema. The first violation is one
    :class:`LogError` naming ``where``, the slot, the field, the value and what was
    expected.
    """
    if not payloads:
        return empty_block(K)
    joined = b"[" + b",".join(payloads) + b"]"
    try:
        rows = orjson.loads(joined)
    except orjson.JSONDecodeError:
        raise _json_error(payloads, where) from None
    B = len(rows)
    first = rows[0] if type(rows[0]) is dict else {}
    names = list(first)
    missing = [f for f in REQUIRED if f not in first]
    if type(rows[0]) is dict and missing:  # a required field lacking in the log
        raise LogError(
            f"{where}: {_slot_of(first, 0)} lacks {', '.join(missing)}, a required "
            f"field of the slot log (expected at least the fields {', '.join(REQUIRED)})"
        )
    # C-level checks first (map/set); the Python loop below runs only to name a bad row.
    # Every message of a chunk has the keys of its first; a field a block holds as None
    # when absent may come and go (a plug-in that gave scores from some slot on), a column
    # of FIELDS may not (a log holds it from its first slot or never).
    fine = set(map(type, rows)) == {dict} and set(map(len, rows)) == {len(names)}
    cols: dict[str, list[Any]] = {}
    if fine:
        try:
            cols = {f: [r[f] for r in rows] for f in names}
        except KeyError:
            fine = False
    if not fine:
        expect = set(names)
        for i, r in enumerate(rows):
            if type(r) is not dict:
                raise LogError(f"{where}: message {i + 1} is {_shown(r)}, expected a JSON object")
            lacking = [f for f in names if f not in r and f not in NONE_FIELDS]
            extra = sorted(k for k in r if k not in expect and k not in NONE_FIELDS)[:3]
            if lacking or extra:
                what = f"lacks {', '.join(lacking)}" if lacking else f"has extra keys {extra}"
                raise LogError(f"{where}: {_slot_of(r, i)} {what}; expected exactly the fields "
                               f"{', '.join(names)}")  # fmt: skip
        names += [f for f in NONE_FIELDS if f not in expect and any(f in r for r in rows)]
        cols = {f: [r.get(f) for r in rows] for f in names}
    unknown = [f for f in names if f not in BY_NAME]
    try:
        out = _columns(cols, B, K, n_states)
        # a bool hidden in a number column: numpy reads [1, true] as int64, so count them
        # (every known column now holds numbers, nulls or bools only; keys are fixed)
        bools = B * sum(f in cols for f in ("success", "override"))
        bools += sum(v is not None for f in _NONE_FLAGS for v in cols.get(f, ()))
        bools += sum(_count_bools(v) for f in unknown for v in cols[f])
        if joined.count(b"true") + joined.count(b"false") != bools:
            for f in (*_INT_FIELDS, "estimator", "mu_hat", "pulls", "candidates"):
                for i, v in enumerate(cols.get(f, ())):
                    items = v if type(v) is list else [v]
                    if any(type(a) is bool for a in items):
                        raise _Bad(i, f, _shown(next(a for a in items if type(a) is bool)),
                                   "a number, not a bool")  # fmt: skip
        optional = {f: _optional(f, cols[f], out["candidates"]) for f in names
                    if f in NONE_FIELDS}  # fmt: skip
    except _Bad as bad:
        raise LogError(
            f"{where}: {_slot_of(rows[bad.row], bad.row)}: {bad.field} is {bad.shown}, "
            f"expected {bad.expected}"
        ) from None
    kept = {f: _unknown(cols[f]) for f in unknown}
    absent = tuple(f for f in FIELDS if f not in cols)
    return SlotBlock(**{f: out[f] for f in FIELDS}, **optional, extra=kept, absent=absent)


def _count_bools(v: Any) -> int:
    if type(v) is bool:
        return 1
    if type(v) is list:
        return sum(_count_bools(a) for a in v)
    if type(v) is dict:
        return sum(_count_bools(a) for a in v.values())
    return 0


def _unknown(values: list[Any]) -> np.ndarray:
    """A field this corraoi does not know (a newer one wrote it), kept as it reads."""
    try:
        arr = np.asarray(values)
    except ValueError:  # ragged lists
        arr = np.empty(len(values), dtype=object)
        arr[:] = values
    return arr


_NUMBER = {float, int}


def _optional(f: str, values: list[Any], cand: np.ndarray) -> np.ndarray:
    """An optional field's column (``cand``: the slots' candidate sets); a slot that lacks
    it (None: a chunk where it came or went) gets NaN, or False."""
    decl = BY_NAME[f]
    B, K = cand.shape
    if decl.json == "boolean":
        arr = np.asarray([False if v is None else v for v in values])
        if arr.dtype != np.bool_ or arr.ndim != 1:
            i = _first(values, lambda v: v is None or type(v) is bool)
            raise _Bad(max(i, 0), f, _shown(values[max(i, 0)]), "a JSON bool (true or false)")
        return arr
    if decl.json == "float32":
        vals = [np.nan if v is None else v for v in values]
        if not set(map(type, vals)) <= _NUMBER:
            i = _first(vals, lambda v: type(v) in _NUMBER)
            raise _Bad(i, f, _shown(vals[i]), "a number")
        return _infinite(np.asarray(vals, dtype=np.float64).astype(np.float32))
    # "candidate scores": per slot [] or one number per candidate, in the candidates' order
    rows = [[] if v is None else v for v in values]
    counts = cand.sum(axis=1)
    lengths = np.fromiter(map(len, rows), dtype=np.int64, count=B) if set(
        map(type, rows)) == {list} else None  # fmt: skip
    if lengths is None or ((lengths != 0) & (lengths != counts)).any():
        for i, row in enumerate(rows):
            if type(row) is not list or len(row) not in (0, counts[i]):
                raise _Bad(i, f, _shown(row), f"a list of {counts[i]} numbers (one per "
                           "candidate) or []")  # fmt: skip
    flat = list(chain.from_iterable(rows))
    if not set(map(type, flat)) <= _NUMBER:
        for i, row in enumerate(rows):
            j = _first(row, lambda a: type(a) in _NUMBER)
            if j >= 0:
                raise _Bad(i, f"{f}[{j + 1}]", _shown(row[j]), "a number")
    out = np.full((B, K), np.nan, dtype=np.float32)
    assert lengths is not None
    scored = lengths > 0
    out[cand & scored[:, None]] = _infinite(np.asarray(flat, dtype=np.float64).astype(np.float32))
    return out


def _infinite(arr: np.ndarray) -> np.ndarray:
    """+-FLOAT32_MAX, how the log writes +-infinity, back to +-infinity."""
    arr[arr >= FLOAT32_MAX] = np.inf
    arr[arr <= -FLOAT32_MAX] = -np.inf
    return arr


def _columns(
    cols: dict[str, list[Any]], B: int, K: int, n_states: int | None
) -> dict[str, np.ndarray]:
    """The columns of FIELDS, checked; one the log lacks (not in ``cols``) is
    :func:`~corraoi.engine.block.absent_column`'s fill."""
    out: dict[str, np.ndarray] = {f: absent_column(f, B, K) for f in FIELDS if f not in cols}
    if n_states is None and "x" in cols:
        raise _Bad(0, "x", _shown(cols["x"][0]), "no hidden state (the run has no instance)")
    for f in _INT_FIELDS:
        if f in cols:
            out[f] = _int_column(cols[f], f)
    for f in ("success", "override"):
        if f in cols:
            out[f] = _bool_column(cols[f], f)
    if "estimator" in cols:
        est = np.asarray(cols["estimator"])
        if est.dtype.kind not in ("i", "f") or est.ndim != 1:
            i = _first(cols["estimator"], _real)
            raise _Bad(max(i, 0), "estimator", _shown(cols["estimator"][max(i, 0)]), "a number")
        out["estimator"] = est.astype(np.float64, copy=False)
    if "mu_hat" in cols:
        mu = _table(cols["mu_hat"], "mu_hat", K, _real, "a number in [0, 1]")
        out["mu_hat"] = mu.astype(np.float64, copy=False)
    if "pulls" in cols:
        out["pulls"] = _table(cols["pulls"], "pulls", K, _is_int, "integers >= 0")
    for f, lo, hi in (("x", 1, n_states), ("arm", 1, K), ("aoi", 1, None),
                      ("oracle_aoi", 1, None), ("t", 1, None)):  # fmt: skip
        if f not in cols:
            continue
        col = out[f]
        bad = (col < lo) | (col > hi) if hi is not None else col < lo
        if bad.any():
            i = int(np.argmax(bad))
            want = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
            raise _Bad(i, f, str(int(col[i])), f"an integer {want}")
    bounds: tuple[tuple[str, np.ndarray, float, float | None], ...] = (
        ("mu_hat", out["mu_hat"], 0.0, 1.0),
        ("pulls", out["pulls"], 0, None),
    )
    for f, arr, low, high in bounds:
        if f not in cols:
            continue
        bad = (arr < low) | (arr > high) if high is not None else arr < low
        if bad.any():
            i, j = divmod(int(np.argmax(bad)), K)
            want = f"in [{low:g}, {high:g}]" if high is not None else f">= {low:g}"
            raise _Bad(i, f"{f}[{j + 1}]", repr(arr[i, j].item()), f"a value {want}")
    if "candidates" in cols:
        out["candidates"] = _candidates(cols["candidates"], B, K)
    if "x" in cols:
        out["x"] = out["x"] - 1
    out["arm"] = out["arm"] - 1
    return out


def _candidates(cand: list[Any], B: int, K: int) -> np.ndarray:
    lengths = (
        np.fromiter(map(len, cand), dtype=np.int64, count=B)
        if set(map(type, cand)) == {list}
        else None
    )
    if lengths is None or lengths.min() < 1 or lengths.max() > K:
        for i, c in enumerate(cand):
            if type(c) is not list or not 1 <= len(c) <= K:
                raise _Bad(i, "candidates", _shown(c), f"a list of 1..{K} distinct arms")
    assert lengths is not None
    flat = np.asarray(list(chain.from_iterable(cand)))
    if flat.dtype != np.int64:
        for i, c in enumerate(cand):
            j = _first(c, _is_int)
            if j >= 0:
                raise _Bad(i, f"candidates[{j + 1}]", _shown(c[j]), f"an arm in 1..{K}")
    bad = (flat < 1) | (flat > K)
    if bad.any():
        k = int(np.argmax(bad))
        i = int(np.searchsorted(np.cumsum(lengths), k, side="right"))
        raise _Bad(i, "candidates", str(int(flat[k])), f"arms in 1..{K}")
    mask = np.zeros((B, K), dtype=bool)
    mask[np.repeat(np.arange(B), lengths), flat - 1] = True
    dup = mask.sum(axis=1) != lengths
    if dup.any():
        i = int(np.argmax(dup))
        raise _Bad(i, "candidates", str(cand[i]), "distinct arms")
    return mask


def _slot_of(row: Any, i: int) -> str:
    """ "slot 17" when the message's t is a usable integer, else "message 3 of the chunk"."""
    t = row.get("t") if isinstance(row, dict) else None
    if _is_int(t):
        return f"slot {t}"
    return f"message {i + 1} of the chunk"


def _json_error(payloads: Sequence[bytes | memoryview], where: str) -> LogError:
    """Name the first message that is not valid JSON (or holds an unreadable number)."""
    for i, p in enumerate(payloads):
        try:
            orjson.loads(bytes(p))
        except orjson.JSONDecodeError as exc:
            text = str(exc)
            if "infinity" in text or "number" in text:
                text = f"a number outside the 64-bit range ({text})"
            return LogError(f"{where}: message {i + 1} of the chunk is not valid JSON: {text}")
    return LogError(f"{where}: the slot messages do not form valid JSON")


# ----------------------------------------------------------------------- run metadata


def check_agrees(p: Path, md: dict[str, str], config: RunConfig) -> None:
    """The flat fields of the run metadata must say what its ``config`` says: MCAP has no
    checksum over metadata, so a flipped digit in either shows up as a disagreement."""
    facts = {
        "seed": str(config.seed),
        "horizon": str(config.horizon),
        "arms": str(config.K),
        "states": str(config.n_states),
        "policy": config.policy.name,
        "instance": config.instance_name,
    }
    for key, value in facts.items():
        if key in md and md[key] != value:
            raise LogError(
                f"{p}: damaged run metadata: {key} is {md[key]!r} in its own field but "
                f"{value!r} in the configuration; expected both to agree"
            )


def not_a_run_log(p: Path, library: str, sweep: bool = False) -> LogError:
    """The error for an MCAP file that is not a slot log (``sweep``: it is a sweep log)."""
    if sweep:
        return LogError(
            f"{p}: a corraoi sweep log (aggregated curves), not the log of one run; "
            "draw it with `corraoi figure`"
        )
    who = f" (written by {library!r})" if library else ""
    return LogError(f"{p}: an MCAP file but not a corraoi log{who}: no {RUN_METADATA} metadata")


def check_run_metadata(p: Path, md: dict[str, str], library: str) -> None:
    """The ``corraoi.run`` record names this format, holds a config, and a version we read."""
    if md.get("format") != SLOT_FORMAT_NAME or "config" not in md:
        raise not_a_run_log(p, library)
    try:
        version = int(md.get("format_version", ""))
    except ValueError:
        raise LogError(
            f"{p}: format_version {md.get('format_version')!r} is not an integer"
        ) from None
    if version > SLOT_FORMAT_VERSION:
        raise LogError(
            f"{p}: written in log format version {version}, newer than the version "
            f"{SLOT_FORMAT_VERSION} this corraoi reads; upgrade corraoi to read it"
        )
    if version < 1:
        raise LogError(f"{p}: unknown log format version {version}")


__all__ = [
    "MESSAGE_KEYS",
    "check_agrees",
    "check_run_metadata",
    "decode_messages",
    "empty_block",
    "not_a_run_log",
]
