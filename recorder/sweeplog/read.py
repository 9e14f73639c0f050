"""The sweep log read back: a sweep's curves, its configuration and how it ended.

:func:`read_sweep` reads a sweep log written by :class:`corraoi.recorder.sweeplog.log.SweepMcapSink`
(also a ``.partial`` file, or one cut short: every complete chunk) into a
:class:`SweepLog` of :class:`SweepCurve` per policy. The records are walked by
:mod:`corraoi.recorder.walk`; the names come from :mod:`corraoi.recorder.vocab`.
``docs/log-format.md`` (section 3) describes the format.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import orjson
from mcap.records import Channel, Header, Message, Metadata, Schema

from corraoi.errors import LogError, SweepLogError
from corraoi.files.partial import PARTIAL_SUFFIX, partial_path, reason
from corraoi.recorder.vocab import MAGIC, RUN_METADATA, SWEEP_METADATA
from corraoi.recorder.vocab import SLOT_SCHEMA_NAME as _SLOT_SCHEMA
from corraoi.recorder.vocab import SWEEP_END_METADATA as END_METADATA
from corraoi.recorder.vocab import SWEEP_FORMAT_VERSION as FORMAT_VERSION
from corraoi.recorder.vocab import SWEEP_OPTIONAL_KEYS as OPTIONAL_KEYS
from corraoi.recorder.vocab import SWEEP_SCHEMA_NAME as SCHEMA_NAME
from corraoi.recorder.vocab import SWEEP_TOPIC as TOPIC
from corraoi.recorder.walk import Walker


def sweep_arms(config: dict[str, Any]) -> int:
    """K, the number of arms of a sweep configuration (its ``instance.Y`` has K rows)."""
    try:
        K = len(config["instance"]["Y"])
    except (KeyError, TypeError) as exc:
        raise ValueError(
            f"sweep config needs instance.Y (the K x n table), missing {exc}"
        ) from None
    if K < 1:
        raise ValueError("sweep config: instance.Y has no arms")
    return K


@dataclass(frozen=True, eq=False)
class SweepCurve:
    """One policy's curve: arrays over its checkpoints (NaN where a half-width is null)."""

    policy: str
    t: np.ndarray  # (n,) int64
    regret_mean: np.ndarray  # (n,) float64
    regret_ci95: np.ndarray
    estimator_mean: np.ndarray
    estimator_ci95: np.ndarray
    pull_share: np.ndarray  # (n, K), arm order (arm k + 1 in column k)
    #: a cell of several sources: mean collisions up to t (summed over the sources) and the
    #: half-width (NaN where undefined); None for a curve of one source
    collisions_mean: np.ndarray | None = None
    collisions_ci95: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(eq=False)
class SweepLog:
    """A sweep log read back: its config, its policies in order, and their curves."""

    path: Path
    config: dict[str, Any]
    policies: list[str]
    curves: dict[str, SweepCurve]
    library: str = ""
    status: str = "complete"  # complete | interrupted | truncated
    messages: int = 0
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def notable(self) -> dict[str, Any] | None:
        """The runs worth watching (corraoi.experiments.notable), None in logs from before they
        were named."""
        value = self.config.get("notable")
        return value if isinstance(value, dict) else None

    @property
    def complete(self) -> bool:
        return self.status == "complete"

    @property
    def instance_name(self) -> str:
        inst = self.config.get("instance") or {}
        return str(inst.get("name", "?"))

    @property
    def runs(self) -> int | None:
        v = self.config.get("runs")
        return int(v) if v is not None else None

    @property
    def horizon(self) -> int | None:
        v = self.config.get("horizon")
        return int(v) if v is not None else None

    @property
    def K(self) -> int:
        return sweep_arms(self.config)


def _check_file(path: Path) -> None:
    if path.is_dir():
        hint = ""
        if (path / "sweep.mcap").is_file():
            hint = f" (did you mean {path / 'sweep.mcap'}?)"
        raise SweepLogError(f"{path}: is a directory, not a sweep log{hint}")
    if not path.exists():
        part = partial_path(path)
        hint = f" ({part} exists: the sweep did not finish)" if part.is_file() else ""
        raise SweepLogError(f"{path}: no such sweep log{hint}")
    try:
        with open(path, "rb") as f:
            magic = f.read(len(MAGIC))
    except OSError as exc:
        raise SweepLogError(f"{path}: cannot read the sweep log: {reason(exc)}") from None
    if magic != MAGIC:
        raise SweepLogError(f"{path}: not an MCAP file (expected a sweep log, sweep.mcap)")


def read_sweep(path: str | os.PathLike[str]) -> SweepLog:
    """Read a sweep log (also a ``.partial`` file or one cut short: every complete chunk)."""
    p = Path(path)
    _check_file(p)
    schemas: dict[int, Schema] = {}
    channel_id: int | None = None
    payloads: list[bytes] = []
    meta: dict[str, str] | None = None
    end: dict[str, str] | None = None
    library = ""
    truncated = damaged = False
    others: set[str] = set()  # names of other schemas and metadata records
    try:
        with open(p, "rb") as f:
            walker = Walker(f, p)
            for record in walker.mcap_records():
                if isinstance(record, Message):
                    if record.channel_id == channel_id:
                        payloads.append(record.data)
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    sch = schemas.get(record.schema_id)
                    if (
                        record.topic == TOPIC
                        and sch is not None
                        and sch.name == SCHEMA_NAME
                        and channel_id is None
                    ):
                        channel_id = record.id
                    elif sch is not None:
                        others.add(sch.name)
                elif isinstance(record, Metadata):
                    if record.name == SWEEP_METADATA and meta is None:
                        meta = dict(record.metadata)
                    elif record.name == END_METADATA:
                        end = dict(record.metadata)
                    else:
                        others.add(record.name)
                elif isinstance(record, Header):
                    library = record.library
            truncated = walker.truncated
    except OSError as exc:
        raise SweepLogError(f"{p}: cannot read the sweep log: {reason(exc)}") from None
    except LogError:  # damage (a bad CRC, sizes that do not add up): keep what came before
        truncated = damaged = True
    if channel_id is None or meta is None:
        # a slot log shows its schema in its first chunk; damage there stops the walk
        # before it, and then its run metadata says what it is
        if _SLOT_SCHEMA in others or (damaged and RUN_METADATA in others):
            raise SweepLogError(
                f"{p}: a per-slot run log, not a sweep log (figures read the sweep.mcap "
                "written by `corraoi sweep -o DIR`)"
            )
        what = "is cut short before its header" if truncated else "is not a corraoi sweep log"
        raise SweepLogError(f"{p}: {what} (no {SCHEMA_NAME} channel {TOPIC} with its metadata)")
    return _build(p, meta, end, payloads, library=library, truncated=truncated)


def _build(
    p: Path,
    meta: dict[str, str],
    end: dict[str, str] | None,
    payloads: list[bytes],
    *,
    library: str,
    truncated: bool,
) -> SweepLog:
    version = meta.get("format_version", "")
    if not version.isdigit():
        raise SweepLogError(f"{p}: the sweep metadata has no valid format_version ({version!r})")
    if int(version) > FORMAT_VERSION:
        raise SweepLogError(
            f"{p}: written by a newer corraoi (sweep log format version {version}; this one "
            f"reads up to {FORMAT_VERSION}): upgrade corraoi"
        )
    try:
        config = json.loads(meta["config"])
        K = sweep_arms(config)
    except (KeyError, ValueError, TypeError, AttributeError, RecursionError) as exc:
        raise SweepLogError(f"{p}: the sweep metadata holds no valid config ({exc})") from None
    try:
        rows = orjson.loads(b"[" + b",".join(payloads) + b"]")
    except orjson.JSONDecodeError as exc:
        raise SweepLogError(f"{p}: a sweep message is not valid JSON ({exc})") from None
    grouped: dict[str, list[dict[str, Any]]] = {}
    for i, row in enumerate(rows):
        if not isinstance(row, dict) or not isinstance(row.get("policy"), str):
            raise SweepLogError(f"{p}: sweep message {i + 1} has no policy name")
        grouped.setdefault(row["policy"], []).append(row)
    curves = {name: _curve(p, name, group, K) for name, group in grouped.items()}
    if truncated:
        status = "truncated"
    elif end is None:
        status = "interrupted"
    else:
        status = end.get("status", "interrupted")
    if p.name.endswith(PARTIAL_SUFFIX) and status == "complete":
        status = "interrupted"
    return SweepLog(
        path=p,
        config=config,
        policies=list(grouped),
        curves=curves,
        library=library,
        status=status,
        messages=len(rows),
        metadata=meta,
    )


def _curve(p: Path, name: str, rows: list[dict[str, Any]], K: int) -> SweepCurve:
    def column(key: str) -> np.ndarray:
        # an absent key (version 2) or null (version 1) is an undefined half-width
        if key in OPTIONAL_KEYS:
            values = [r.get(key) for r in rows]
        else:
            values = [r[key] for r in rows]
        return np.array([np.nan if v is None else v for v in values], dtype=np.float64)

    many = any("collisions_mean" in r for r in rows)  # a cell of several sources
    try:
        t = np.array([r["t"] for r in rows], dtype=np.int64)
        curve = SweepCurve(
            policy=name,
            t=t,
            regret_mean=column("regret_mean"),
            regret_ci95=column("regret_ci95"),
            estimator_mean=column("estimator_mean"),
            estimator_ci95=column("estimator_ci95"),
            pull_share=np.array([r["pull_share"] for r in rows], dtype=np.float64).reshape(
                len(rows), K
            ),
            collisions_mean=column("collisions_mean") if many else None,
            collisions_ci95=column("collisions_ci95") if many else None,
        )
    except KeyError as exc:
        raise SweepLogError(f"{p}: a sweep message of {name} lacks the field {exc}") from None
    except (TypeError, ValueError) as exc:
        raise SweepLogError(
            f"{p}: a sweep message of {name} has a field of the wrong type or size ({exc})"
        ) from None
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise SweepLogError(f"{p}: the checkpoints of {name} are not in increasing order")
    return curve


__all__ = [
    "SweepCurve",
    "SweepLog",
    "read_sweep",
    "sweep_arms",
]
