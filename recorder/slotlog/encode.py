"""The slot log written: its JSON Schema, its metadata records and the block encoder.

One MCAP message per slot on the slot topic (:data:`recorder.vocab.SLOT_TOPIC`), JSON
encoded, arms and states numbered from 1 (``SlotBlock`` arrays are 0-based: the encoder
adds 1). The reading side, the strict decoder, is :mod:`recorder.slotlog.decode`, which re-exports
these names; ``docs/log-format.md`` is the human description.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import orjson

from corraoi.model.theory import analyse
from recorder.vocab import NS_PER_SLOT
from recorder.vocab import SLOT_FLUSH_EVERY as FLUSH_EVERY
from recorder.vocab import SLOT_FORMAT_NAME as FORMAT_NAME
from recorder.vocab import SLOT_SCHEMA_NAME as SCHEMA_NAME

if TYPE_CHECKING:  # types only: corraoi.engine.block's import circle stays out of this module
    from corraoi.engine.block import RunConfig, SlotBlock

_NUMPY = orjson.OPT_SERIALIZE_NUMPY


def slot_schema(config: RunConfig) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of one slot message of this run."""
    K, n = config.instance.K, config.instance.n_states

    def integer(desc: str, minimum: int | None = None, maximum: int | None = None) -> dict:
        out: dict[str, Any] = {"type": "integer", "description": desc}
        if minimum is not None:
            out["minimum"] = minimum
        if maximum is not None:
            out["maximum"] = maximum
        return out

    def per_arm(item: dict[str, Any], desc: str) -> dict[str, Any]:
        return {
            "type": "array",
            "description": desc,
            "items": item,
            "minItems": K,
            "maxItems": K,
        }

    properties: dict[str, Any] = {
        "t": integer("slot number, 1..horizon", 1),
        "x": integer(f"hidden state X_t, numbered 1..{n}", 1, n),
        "arm": integer(f"channel (arm) played at slot t, numbered 1..{K}", 1, K),
        "success": {"type": "boolean", "description": "r_t = Y[arm, x] = 1"},
        "aoi": integer("age of information after slot t, in slots (aoi_0 = 1)", 1),
        "oracle_aoi": integer("age of the oracle that plays the best arm on the same X path", 1),
        "regret": integer("pathwise AoI regret sum_{s<=t} (aoi_s - oracle_aoi_s), in slots"),
        "estimator": {
            "type": "number",
            "description": "the paper's estimator sum_{s<=t} aoi_s - t / mu*, in slots",
        },
        "override": {
            "type": "boolean",
            "description": "the AoI-aware rule chose the arm (argmax mu_hat); false otherwise",
        },
        "mu_hat": per_arm(
            {"type": "number", "minimum": 0, "maximum": 1},
            "empirical mean reward of arms 1..K after the slot's update (0 if never pulled)",
        ),
        "pulls": per_arm(
            {"type": "integer", "minimum": 0}, "pulls of arms 1..K after the slot's update"
        ),
        "candidates": {
            "type": "array",
            "description": "arms (1..K, ascending) the arm was chosen from: A_t + {k_emp} for "
            "the correlated policies, every arm otherwise",
            "items": {"type": "integer", "minimum": 1, "maximum": K},
            "minItems": 1,
            "maxItems": K,
            "uniqueItems": True,
        },
    }
    for name in config.absent:  # a column the log leaves out is not in its messages
        del properties[name]
    version = config.format_version  # the run's own: the schema says what its metadata says
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"urn:corraoi:slot-event:v{version}",
        "title": SCHEMA_NAME,
        "description": f"One slot of a corraoi run ({FORMAT_NAME} version {version}); "
        "arms and states are numbered from 1.",
        "type": "object",
        "properties": properties,
        # the message keys in the order the encoder writes them: corraoi.engine.block.FIELDS
        "required": list(properties),
        "additionalProperties": False,
    }


def schema_bytes(config: RunConfig) -> bytes:
    return json.dumps(slot_schema(config), indent=1).encode()


def run_metadata(config: RunConfig, *, flush_every: int = FLUSH_EVERY) -> dict[str, str]:
    """The ``corraoi.run`` metadata record: flat strings, plus the full config as JSON."""
    inst = config.instance
    theory = analyse(inst)
    return {
        "format": FORMAT_NAME,
        "format_version": str(config.format_version),
        "corraoi_version": config.version,
        "label": config.label,
        "instance": inst.name,
        "policy": config.policy.name,
        "params": json.dumps(config.policy.params, sort_keys=True),
        "seed": str(config.seed),
        "horizon": str(config.horizon),
        "arms": str(inst.K),
        "states": str(inst.n_states),
        "p": json.dumps([float(v) for v in inst.p]),
        "Y": json.dumps(inst.Y.astype(int).tolist()),
        "mu": json.dumps([float(v) for v in theory.mu]),
        "best_arm": str(theory.best_arm + 1),
        "mu_star": repr(float(theory.mu_star)),
        "competitive_arms": json.dumps([a + 1 for a in theory.competitive]),
        "numbering": "arms and states from 1",
        "log_time": f"t * {NS_PER_SLOT} ns",
        "flush_every": str(flush_every),
        "config": json.dumps(config.to_dict(), sort_keys=True),
        **({"absent": json.dumps(list(config.absent))} if config.absent else {}),
    }


def end_metadata(
    *,
    slots: int,
    horizon: int,
    last: SlotBlock | None,
    error: str | None = None,
    absent: tuple[str, ...] = (),
) -> dict[str, str]:
    """The ``corraoi.end`` metadata record written by a writer that finished its file
    (``error``: the run stopped on that error, status ``failed``; ``absent``: the run's
    columns the log does not hold, left out here too)."""
    status = "complete" if slots >= horizon else "interrupted"
    out = {"status": "failed" if error is not None else status, "slots": str(slots)}
    if error is not None:
        out["error"] = error
    if last is not None and len(last):
        if "regret" not in absent:
            out["regret"] = str(int(last.regret[-1]))
        if "estimator" not in absent:
            out["estimator"] = repr(float(last.estimator[-1]))
        if "pulls" not in absent:
            out["pulls"] = json.dumps([int(v) for v in last.pulls[-1]])
    return out


class BlockEncoder:
    """Encodes a SlotBlock into one JSON message per slot, a column at a time.

    Numbers are formatted by orjson a whole column at a time (shortest round-trip text, so
    the decoder gets back the same float64 values); the messages are then put together by
    one ``bytes.join`` over the columns interleaved with the constant key texts, and split
    at a separator no JSON text of ours contains (a newline). That is about twice as fast
    as formatting each slot with ``bytes %`` (benchmarks/bench_record.py).
    """

    def __init__(self, K: int, absent: tuple[str, ...] = ()) -> None:
        self.K = int(K)
        #: the message's fields, in log order: all but the absent ones
        self._fields = [f for f in _COLUMNS if f not in absent]
        self._keys = _keys(self._fields)
        self._weights = (1 << np.arange(self.K, dtype=np.int64)) if self.K <= 62 else None
        self._sets: dict[int, bytes] = {}

    def _candidates(self, mask: np.ndarray) -> list[bytes]:
        if self._weights is None:  # too many arms for a bit code: one row at a time
            return [orjson.dumps(np.flatnonzero(row) + 1, option=_NUMPY) for row in mask]
        codes, inverse = np.unique(mask.astype(np.int64) @ self._weights, return_inverse=True)
        sets = self._sets
        texts = np.empty(len(codes), dtype=object)
        for i, code in enumerate(codes.tolist()):
            text = sets.get(code)
            if text is None:
                text = orjson.dumps([k + 1 for k in range(self.K) if code >> k & 1])
                sets[code] = text
            texts[i] = text
        return texts[inverse].tolist()

    def encode(self, b: SlotBlock) -> list[bytes]:
        n = len(b)
        if n == 0:
            return []
        columns = [_COLUMNS[f](self, b, n) for f in self._fields]
        keys, last = self._keys[:-1], self._keys[-1]
        step = 2 * len(keys) + 1
        parts: list[bytes] = [last] * (step * n)  # every message ends with "}\n"
        for i, (key, column) in enumerate(zip(keys, columns, strict=True)):
            parts[2 * i :: step] = [key] * n
            parts[2 * i + 1 :: step] = column
        return b"".join(parts)[:-1].split(b"\n")


_BOOLS = np.array([b"false", b"true"], dtype=object)

#: Each field's JSON texts for a block, in the order ``encode`` writes them
#: (corraoi.engine.block.FIELDS's; tests/test_logger.py checks that the two agree).
_COLUMNS: dict[str, Callable[[BlockEncoder, SlotBlock, int], list[bytes]]] = {
    "t": lambda e, b, n: _items(b.t),
    "x": lambda e, b, n: _items(b.x + 1),
    "arm": lambda e, b, n: _items(b.arm + 1),
    "success": lambda e, b, n: _BOOLS[np.asarray(b.success, dtype=np.intp)].tolist(),
    "aoi": lambda e, b, n: _items(b.aoi),
    "oracle_aoi": lambda e, b, n: _items(b.oracle_aoi),
    "regret": lambda e, b, n: _items(b.regret),
    "estimator": lambda e, b, n: _items(b.estimator),
    "override": lambda e, b, n: _BOOLS[np.asarray(b.override, dtype=np.intp)].tolist(),
    "mu_hat": lambda e, b, n: _rows(b.mu_hat, n),
    "pulls": lambda e, b, n: _rows(b.pulls, n),
    "candidates": lambda e, b, n: e._candidates(b.candidates),
}
_ROWS = ("mu_hat", "pulls")  # written without their brackets (_rows)


def _keys(fields: list[str]) -> list[bytes]:
    """The text before each value of a message of ``fields``; ``encode`` ends each message
    with "}\n" and splits at the newlines (orjson escapes any newline inside a JSON
    string). A table's brackets are part of the texts around its rows."""
    out = []
    before = b"{"
    for f in fields:
        text = before + b'"' + f.encode() + b'":'
        if f in _ROWS:
            text += b"["
        out.append(text)
        before = b"]," if f in _ROWS else b","
    out.append(b"]}\n" if fields[-1] in _ROWS else b"}\n")
    return out


def _items(column: np.ndarray) -> list[bytes]:
    """JSON text of each element of a 1-D numeric array."""
    return orjson.dumps(np.ascontiguousarray(column), option=_NUMPY)[1:-1].split(b",")


def _rows(table: np.ndarray, n: int) -> list[bytes]:
    """JSON text of each row of a 2-D numeric array, without the brackets."""
    if table.shape[1] == 0:
        return [b""] * n
    return orjson.dumps(np.ascontiguousarray(table), option=_NUMPY)[2:-2].split(b"],[")


__all__ = ["BlockEncoder", "end_metadata", "run_metadata", "schema_bytes", "slot_schema"]
