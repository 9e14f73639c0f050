"""The sweep log: the aggregated curves of a sweep, streamed to MCAP as the sweep runs.

One JSON message per (policy, checkpoint slot) on :data:`SWEEP_TOPIC` (schema
:data:`SWEEP_SCHEMA_NAME`), in log-time order: at each checkpoint slot, every policy in the
grid's order (MCAP checkers, ``mcap``'s and ``rerun mcap check``, want log times that never
go back). The configuration of the sweep (instance, policies,
runs, horizon, seed, checkpoints, version) is stored in the metadata record
:data:`SWEEP_METADATA`, so a figure can be redrawn from the file alone.
``docs/log-format.md`` (section 3) is the human description; this module is the code.

The writer is byte-reproducible: no wall clock anywhere (log_time = publish_time =
``t * NS_PER_SLOT``, sequence = 1-based index of the message in the file). It writes
``<path>.partial`` and renames it to ``path`` only when closed normally. The reader
(:func:`read_sweep`, :class:`SweepLog`) lives in :mod:`corraoi.recorder.sweeplog.read` and is
re-exported here.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np
import orjson
from mcap.writer import CompressionType, Writer

from corraoi._version import __version__
from corraoi.errors import WriteError
from corraoi.files.partial import PartialFile, reason
from corraoi.recorder.sink import Sink

# Colours live in corraoi.recorder.style (one place for every view); re-exported for old imports.
# The sweep log's names (corraoi.recorder.vocab)
from corraoi.recorder.vocab import (
    MESSAGE_ENCODING,
    NS_PER_SLOT,
    PLUGIN_MEDIA_TYPE,
    PROVENANCE_METADATA,
    SCHEMA_ENCODING,
    SWEEP_END_METADATA,
    SWEEP_FLUSH_EVERY,
    SWEEP_FORMAT_NAME,
    SWEEP_FORMAT_VERSION,
    SWEEP_MESSAGE_KEYS,
    SWEEP_METADATA,
    SWEEP_OPTIONAL_KEYS,
    SWEEP_SCHEMA_NAME,
    SWEEP_TOPIC,
    library_name,
    mcap_index_types,
)

from .read import sweep_arms

if TYPE_CHECKING:
    from corraoi.provenance import Provenance
    from corraoi.stats import SweepPoint


# ---------------------------------------------------------------------------- format


def sweep_schema(K: int, *, sources: bool = False) -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of one :data:`SWEEP_SCHEMA_NAME` message for K arms;
    ``sources``: a sweep with a cell of several sources, whose messages may hold the
    collisions (:data:`SWEEP_SOURCES_KEYS`; a sweep of single sources declares none)."""
    half_width = {"type": "number", "minimum": 0}
    extra = {
        "collisions_mean": {
            "type": "number", "minimum": 0,
            "description": "a cell of several sources: mean over runs of the collisions in "
            "slots 1..t, summed over the sources",
        },
        "collisions_ci95": {
            **half_width,
            "description": "half-width of the 95% confidence interval of collisions_mean; "
            "absent with a single run",
        },
    } if sources else {}  # fmt: skip
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "$id": f"urn:corraoi:sweep-point:v{SWEEP_FORMAT_VERSION}",
        "title": SWEEP_SCHEMA_NAME,
        "description": f"Aggregates over the runs of one policy at one checkpoint slot "
        f"({SWEEP_FORMAT_NAME} version {SWEEP_FORMAT_VERSION}); arms are numbered from 1.",
        "type": "object",
        "properties": {
            "policy": {"type": "string", "minLength": 1, "description": "policy name"},
            "t": {"type": "integer", "minimum": 1, "description": "checkpoint slot, 1..horizon"},
            "regret_mean": {
                "type": "number",
                "description": "mean over runs of the pathwise AoI regret "
                "sum_{s<=t} (aoi_s - oracle_aoi_s), in slots",
            },
            "regret_ci95": {
                **half_width,
                "description": "half-width of the 95% Student t confidence interval of "
                "regret_mean, in slots; absent with a single run",
            },
            "estimator_mean": {
                "type": "number",
                "description": "mean over runs of the paper's estimator "
                "sum_{s<=t} aoi_s - t / mu*, in slots",
            },
            "estimator_ci95": {
                **half_width,
                "description": "half-width of the 95% confidence interval of estimator_mean, "
                "in slots; absent with a single run",
            },
            "pull_share": {
                "type": "array",
                "description": f"mean over runs of pulls_k / t for arms k = 1..{K} (in arm "
                "order; sums to 1)",
                "items": {"type": "number", "minimum": 0, "maximum": 1},
                "minItems": K,
                "maxItems": K,
            },
            **extra,
        },
        "required": [k for k in SWEEP_MESSAGE_KEYS if k not in SWEEP_OPTIONAL_KEYS],
        "additionalProperties": False,
    }


def sweep_metadata(
    config: dict[str, Any], *, flush_every: int = SWEEP_FLUSH_EVERY
) -> dict[str, str]:
    """The :data:`SWEEP_METADATA` record: flat strings, plus the full config as JSON."""
    inst = config.get("instance") or {}
    policies = [p["name"] if isinstance(p, dict) else str(p) for p in config.get("policies", [])]
    return {
        "format": SWEEP_FORMAT_NAME,
        "format_version": str(SWEEP_FORMAT_VERSION),
        "corraoi_version": str(config.get("version", __version__)),
        "instance": str(inst.get("name", "")),
        "arms": str(sweep_arms(config)),
        "policies": json.dumps(policies),
        "runs": str(config.get("runs", "")),
        "horizon": str(config.get("horizon", "")),
        "seed": str(config.get("seed", "")),
        "checkpoints": str(len(config.get("checkpoints", []))),
        "numbering": "arms from 1 (pull_share is in arm order)",
        "log_time": f"t * {NS_PER_SLOT} ns",
        "flush_every": str(flush_every),
        "config": json.dumps(config, sort_keys=True),
    }


# ---------------------------------------------------------------------------- writer


class SweepMcapSink(Sink["SweepPoint"]):
    """Streams :class:`~corraoi.stats.SweepPoint` rows of a sweep into an MCAP
    file.

    ``with SweepMcapSink(path, config) as sink: sink.write(point)``. The file is written as
    ``<path>.partial`` and renamed to ``path`` by :meth:`close`; leaving the ``with`` block
    through an exception (or calling :meth:`abort`) finishes the file but leaves it under
    its ``.partial`` name with ``status = interrupted``. Closing twice is safe.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        config: dict[str, Any],
        *,
        overwrite: bool = True,
        flush_every: int = SWEEP_FLUSH_EVERY,
        fsync: bool = True,
        provenance: Provenance | None = None,
    ) -> None:
        if flush_every < 1:
            raise ValueError(f"flush_every must be >= 1, got {flush_every}")
        self.path = Path(path)
        self.config = config
        self.K = sweep_arms(config)
        horizon = int(config.get("horizon", 0) or 0)
        if horizon * NS_PER_SLOT >= 2**64:
            raise ValueError(f"horizon {horizon} is too long for an MCAP sweep log")
        self.flush_every = int(flush_every)
        self._overwrite = overwrite
        self._fsync = fsync
        self._count = 0
        self._pending = 0
        self._last_t: dict[str, int] = {}
        self._time = 0  # the last message's log time: they never go back
        self._closed = False
        metadata = sweep_metadata(config, flush_every=self.flush_every)
        sources = provenance.sources if provenance is not None else ()
        self._out = PartialFile(self.path, overwrite=overwrite, what="sweep log", sweep=True)
        self._stream: BinaryIO = self._out.create().file
        try:
            index = mcap_index_types(bool(sources))
            self._writer = Writer(self._stream, compression=CompressionType.ZSTD,
                                  index_types=index)  # fmt: skip
            library = library_name(str(config.get("version", __version__)))
            self._writer.start(profile="", library=library)
            self._writer.add_metadata(SWEEP_METADATA, metadata)
            if provenance is not None:  # what made the numbers, each plug-in's source too
                self._writer.add_metadata(PROVENANCE_METADATA, provenance.metadata())
            for src in sources:
                self._writer.add_attachment(0, 0, src.name, PLUGIN_MEDIA_TYPE, src.data)
            schema_id = self._writer.register_schema(
                name=SWEEP_SCHEMA_NAME,
                encoding=SCHEMA_ENCODING,
                data=json.dumps(sweep_schema(self.K, sources=bool(config.get("sources"))),
                                indent=1).encode(),  # fmt: skip
            )
            self._channel = self._writer.register_channel(
                topic=SWEEP_TOPIC,
                message_encoding=MESSAGE_ENCODING,
                schema_id=schema_id,
                metadata={"format_version": str(SWEEP_FORMAT_VERSION)},
            )
            self._writer.flush()
        except OSError as exc:
            self._out.leave()
            raise WriteError(f"{self.part}: cannot write the sweep log: {reason(exc)}") from None

    @property
    def part(self) -> Path:
        """Where the file lives until it is closed."""
        return self._out.partial

    @property
    def count(self) -> int:
        """Messages written so far."""
        return self._count

    def encode(self, point: SweepPoint) -> bytes:
        """The JSON message of ``point`` (checked: finite means, K shares, increasing t)."""
        if not isinstance(point.policy, str) or not point.policy:
            raise ValueError(
                f"sweep point: policy must be a non-empty string, got {point.policy!r}"
            )
        t = int(point.t)
        if t < 1 or t * NS_PER_SLOT >= 2**64:
            raise ValueError(f"sweep point {point.policy}: t out of range, got {point.t}")
        last = self._last_t.get(point.policy, 0)
        if t <= last:
            raise ValueError(
                f"sweep point {point.policy}: t must increase, got t={t} after t={last}"
            )
        if t * NS_PER_SLOT < self._time:
            raise ValueError(f"sweep point {point.policy}: t={t} after a point at "
                             f"t={self._time // NS_PER_SLOT} (points come in slot order)")
        for name in ("regret_mean", "estimator_mean"):
            if not math.isfinite(getattr(point, name)):
                raise ValueError(f"sweep point {point.policy} t={t}: {name} is not finite")
        share = np.asarray(point.pull_share, dtype=np.float64).reshape(-1)
        if share.size != self.K:
            raise ValueError(
                f"sweep point {point.policy} t={t}: pull_share has {share.size} entries, "
                f"the instance has {self.K} arms"
            )
        message = {
            "policy": point.policy,
            "t": t,
            "regret_mean": float(point.regret_mean),
            "regret_ci95": _opt(point.regret_ci95),
            "estimator_mean": float(point.estimator_mean),
            "estimator_ci95": _opt(point.estimator_ci95),
            "pull_share": share.tolist(),
            "collisions_mean": _opt(point.collisions_mean),
            "collisions_ci95": _opt(point.collisions_ci95),
        }
        # an undefined half-width is an absent key (version 1 wrote null)
        return orjson.dumps({k: v for k, v in message.items() if v is not None})

    def write(self, point: SweepPoint) -> None:
        """Append one point (in slot order: log times never go back); flushes a chunk every
        ``flush_every`` points."""
        if self._closed:
            raise ValueError(f"{self.path}: the sweep log is closed")
        data = self.encode(point)
        try:
            self._count += 1
            log_time = self._time = int(point.t) * NS_PER_SLOT
            self._writer.add_message(
                self._channel,
                log_time=log_time,
                data=data,
                publish_time=log_time,
                sequence=self._count,
            )
            self._last_t[point.policy] = int(point.t)
            self._pending += 1
            if self._pending >= self.flush_every:
                self._flush()
        except OSError as exc:
            raise WriteError(f"{self.part}: cannot write the sweep log: {reason(exc)}") from None

    def _flush(self) -> None:
        if self._pending:
            self._writer.flush()
            self._pending = 0

    def _finish(self, status: str) -> None:
        self._closed = True
        try:
            self._writer.add_metadata(
                SWEEP_END_METADATA,
                {
                    "status": status,
                    "messages": str(self._count),
                    "policies": json.dumps(list(self._last_t)),
                },
            )
            self._writer.finish()
            self._stream.flush()
            if self._fsync:
                os.fsync(self._stream.fileno())
        except OSError as exc:
            self._out.leave()
            raise WriteError(f"{self.part}: cannot finish the sweep log: {reason(exc)}") from None

    def close(self) -> None:
        """Finish the file and rename it into place (while its lock is held). Safe to call
        twice."""
        if self._closed:
            return
        self._finish("complete")
        self._out.publish(sync=False)  # synced by _finish

    def abort(self) -> None:
        """Finish the file as interrupted and leave it at ``<path>.partial``."""
        if self._closed:
            return
        try:
            self._finish("interrupted")
        finally:
            self._out.leave()


def _opt(v: float | None) -> float | None:
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


__all__ = [
    "SweepMcapSink",
    "sweep_metadata",
    "sweep_schema",
]
