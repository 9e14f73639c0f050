"""The slot-log format: names, the JSON Schema, the metadata, and the block encoder/decoder.

One MCAP message per slot on :data:`TOPIC`, JSON encoded. Arms and states are numbered
from 1 in the log (``SlotBlock`` arrays are 0-based: the encoder adds 1, the decoder
subtracts it). ``docs/log-format.md`` is the human description; this module is the code.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import orjson
from mcap.writer import IndexType

from corraoi.block import ARM_FIELDS, FIELDS, SCALAR_FIELDS, RunConfig, SlotBlock
from corraoi.theory import analyse

from .errors import LogError

#: Name of the format, stored under ``format`` in the run metadata.
FORMAT_NAME = "corraoi.slot-log"
#: The newest version of the format this code reads and writes (see docs/log-format.md):
#: a run is written as version 1 (built-in policy, i.i.d. channel) or 2 (a plug-in policy or a
#: Markov/trace channel), ``RunConfig.format_version``.
FORMAT_VERSION = 2
TOPIC = "/corraoi/slot"
SCHEMA_NAME = "corraoi.SlotEvent"
MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"
#: Metadata record written when the file is opened: the run configuration.
RUN_METADATA = "corraoi.run"
#: Metadata record written when the file is finished: how the run ended.
END_METADATA = "corraoi.end"
#: Metadata record that marks a sweep log (recorder.sweep_log), not a run log.
SWEEP_METADATA = "corraoi.sweep"
#: log_time = publish_time = t * NS_PER_SLOT: one slot shows as one second in MCAP tools.
NS_PER_SLOT = 1_000_000_000
#: The largest slot number whose log_time fits MCAP's unsigned 64-bit nanoseconds.
MAX_SLOT = (2**64 - 1) // NS_PER_SLOT
#: A chunk is closed (and flushed to the OS) after every slot t with t % FLUSH_EVERY == 0.
FLUSH_EVERY = 1000
#: Message keys in the order the encoder writes them.
MESSAGE_KEYS = FIELDS
#: The summary indexes every MCAP file we write carries: chunk, message and metadata
#: indexes. Not the attachment index: we write no attachment, and the mcap writer would
#: otherwise end every file with an empty attachment-index summary group.
MCAP_INDEX_TYPES = IndexType.CHUNK | IndexType.MESSAGE | IndexType.METADATA

_NUMPY = orjson.OPT_SERIALIZE_NUMPY


def library_name(version: str) -> str:
    """The MCAP header's ``library`` field."""
    return f"corraoi/{version}"


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
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"urn:corraoi:slot-event:v{FORMAT_VERSION}",
        "title": SCHEMA_NAME,
        "description": f"One slot of a corraoi run ({FORMAT_NAME} version {FORMAT_VERSION}); "
        "arms and states are numbered from 1.",
        "type": "object",
        "properties": properties,
        "required": list(MESSAGE_KEYS),
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
    }


def end_metadata(
    *, slots: int, horizon: int, last: SlotBlock | None, error: str | None = None
) -> dict[str, str]:
    """The ``corraoi.end`` metadata record written by a writer that finished its file
    (``error``: the run stopped on that error, status ``failed``)."""
    status = "complete" if slots >= horizon else "interrupted"
    out = {"status": "failed" if error is not None else status, "slots": str(slots)}
    if error is not None:
        out["error"] = error
    if last is not None and len(last):
        out["regret"] = str(int(last.regret[-1]))
        out["estimator"] = repr(float(last.estimator[-1]))
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

    def __init__(self, K: int) -> None:
        self.K = int(K)
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
        columns: list[list[bytes]] = [
            _items(b.t),
            _items(b.x + 1),
            _items(b.arm + 1),
            _BOOLS[np.asarray(b.success, dtype=np.intp)].tolist(),
            _items(b.aoi),
            _items(b.oracle_aoi),
            _items(b.regret),
            _items(b.estimator),
            _BOOLS[np.asarray(b.override, dtype=np.intp)].tolist(),
            _rows(b.mu_hat, n),
            _rows(b.pulls, n),
            self._candidates(b.candidates),
        ]
        step = 2 * len(_KEYS) + 1
        parts: list[bytes] = [b"}\n"] * (step * n)  # every message ends with "}\n"
        for i, (key, column) in enumerate(zip(_KEYS, columns, strict=True)):
            parts[2 * i :: step] = [key] * n
            parts[2 * i + 1 :: step] = column
        return b"".join(parts)[:-1].split(b"\n")


#: The text before each value of a message; ``encode`` ends each with "}\n" and splits at
#: the newlines (orjson escapes any newline inside a JSON string).
_KEYS = (
    b'{"t":',
    b',"x":',
    b',"arm":',
    b',"success":',
    b',"aoi":',
    b',"oracle_aoi":',
    b',"regret":',
    b',"estimator":',
    b',"override":',
    b',"mu_hat":[',
    b'],"pulls":[',
    b'],"candidates":',
)
_BOOLS = np.array([b"false", b"true"], dtype=object)


def _items(column: np.ndarray) -> list[bytes]:
    """JSON text of each element of a 1-D numeric array."""
    return orjson.dumps(np.ascontiguousarray(column), option=_NUMPY)[1:-1].split(b",")


def _rows(table: np.ndarray, n: int) -> list[bytes]:
    """JSON text of each row of a 2-D numeric array, without the brackets."""
    if table.shape[1] == 0:
        return [b""] * n
    return orjson.dumps(np.ascontiguousarray(table), option=_NUMPY)[2:-2].split(b"],[")


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


def decode_messages(
    payloads: Sequence[bytes | memoryview], K: int, n_states: int, *, where: str
) -> SlotBlock:
    """The SlotBlock of consecutive slot messages (JSON bytes), checked against the format."""
    if not payloads:
        return empty_block(K)
    try:
        rows = orjson.loads(b"[" + b",".join(payloads) + b"]")
    except orjson.JSONDecodeError as exc:
        raise LogError(f"{where}: a slot message is not valid JSON ({exc})") from None
    try:
        cols: dict[str, Any] = {f: [r[f] for r in rows] for f in FIELDS}
    except (KeyError, TypeError) as exc:
        raise LogError(f"{where}: a slot message lacks the field {exc}") from None
    B = len(rows)
    try:
        out: dict[str, np.ndarray] = {}
        for f in ("t", "x", "arm", "aoi", "oracle_aoi", "regret"):
            out[f] = np.asarray(cols[f], dtype=np.int64).reshape(B)
        out["x"] -= 1
        out["arm"] -= 1
        for f in ("success", "override"):
            out[f] = np.asarray(cols[f], dtype=bool).reshape(B)
        out["estimator"] = np.asarray(cols["estimator"], dtype=np.float64).reshape(B)
        out["mu_hat"] = np.asarray(cols["mu_hat"], dtype=np.float64).reshape(B, K)
        out["pulls"] = np.asarray(cols["pulls"], dtype=np.int64).reshape(B, K)
        cand = cols["candidates"]
        lengths = np.fromiter((len(c) for c in cand), dtype=np.int64, count=B)
        flat = np.fromiter((a for c in cand for a in c), dtype=np.int64, count=int(lengths.sum()))
    except (ValueError, TypeError) as exc:
        raise LogError(
            f"{where}: a slot message has a field of the wrong type or size ({exc})"
        ) from None
    if flat.size and (flat.min() < 1 or flat.max() > K):
        raise LogError(f"{where}: a candidate arm is outside 1..{K}")
    mask = np.zeros((B, K), dtype=bool)
    mask[np.repeat(np.arange(B), lengths), flat - 1] = True
    out["candidates"] = mask
    for f, top in (("x", n_states), ("arm", K)):
        col = out[f]
        if col.min() < 0 or col.max() >= top:
            raise LogError(f"{where}: field {f} is outside 1..{top}")
    return SlotBlock(**{f: out[f] for f in FIELDS})


__all__ = [
    "ARM_FIELDS",
    "BlockEncoder",
    "END_METADATA",
    "FLUSH_EVERY",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_SLOT",
    "MCAP_INDEX_TYPES",
    "NS_PER_SLOT",
    "RUN_METADATA",
    "SCALAR_FIELDS",
    "SCHEMA_NAME",
    "TOPIC",
    "decode_messages",
    "empty_block",
    "end_metadata",
    "run_metadata",
    "slot_schema",
]
