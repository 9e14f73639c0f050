"""A slot log as a table: pandas DataFrames and Arrow record batches, numbered from 1.

:class:`RunData` is what ``corraoi.load("run.mcap")`` returns. It reads the log with the
one reader (:func:`corraoi.recorder.slotlog.reader.open_log`) and turns each SlotBlock into an Arrow
record batch whose columns are the log's fields exactly as the file holds them: arms and
states numbered from 1, per-arm arrays spread into wide columns. pandas and pyarrow are
the optional extra ``analysis``; they are imported when a table is built.

Columns (``docs/analysis.md`` documents them): one per field of the slot record
(:mod:`corraoi.engine.slot_record`) that the log holds, in its order, a per-arm field
spread over one column per arm (``mu_hat_1..K``, ``pulls_1..K``, ``cand_1..K``,
``score_1..K``); then any field a newer corraoi wrote, as read.

A run of several sources is tidy: one row per slot and source (slot by slot, the sources
of a slot in order), a ``source`` column numbered from 1 after ``t``, the slot's shared
fields (``t``, ``x``) repeated on each of its rows.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Mapping, Sequence
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from corraoi.engine.block import FIELDS, SlotBlock, SourcesBlock, absent_column, absent_fill
from corraoi.engine.slot_record import BY_NAME, SLOT_RECORD, record_for
from corraoi.errors import UsageError

from .reader import RunLog, open_log

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

#: Slots per record batch of :meth:`RunData.to_arrow` (one chunk of the log is 1000).
BATCH_SLOTS = 65_536


#: Every field a single source's run may hold (not ``collided``, a field of several sources):
#: the default fields of :func:`slot_columns`.
SINGLE_SOURCE = tuple(f.name for f in record_for(1))
#: The column of the table of a run of several sources that numbers the source (from 1).
SOURCE_COLUMN = ("source", "int64")


def slot_columns(
    K: int,
    fields: Sequence[str] = SINGLE_SOURCE,
    extra: Mapping[str, np.ndarray] | None = None,
    *,
    sources: bool = False,
) -> list[tuple[str, str]]:
    """(name, dtype) of every column of the slots table of a run with K arms that logs
    ``fields`` (by default every field a single source's run may hold), in order: one per field, or
    one per arm numbered from 1 (``mu_hat_1 .. mu_hat_K``); then the columns of the fields
    a newer corraoi wrote (``extra``: a block's, as read). ``sources``: the table of a run
    of several sources, with :data:`SOURCE_COLUMN` after ``t`` (pass its fields: those of
    ``record_for(M)``, ``collided`` among them)."""
    cols = [c for f in SLOT_RECORD if f.name in fields for c in f.table_columns(K)]
    if sources:
        cols.insert(1 if cols and cols[0][0] == "t" else 0, SOURCE_COLUMN)
    for name, value in (extra or {}).items():
        if value.ndim == 2:
            cols += [(f"{name}_{k}", str(value.dtype)) for k in range(1, value.shape[1] + 1)]
        else:
            cols.append((name, str(value.dtype)))
    return cols


def arrow_schema(
    K: int,
    fields: Sequence[str] = SINGLE_SOURCE,
    extra: Mapping[str, np.ndarray] | None = None,
    *,
    sources: bool = False,
) -> pa.Schema:
    pa = _pyarrow()
    columns = slot_columns(K, fields, extra, sources=sources)
    return pa.schema([(name, _arrow_type(pa, dtype)) for name, dtype in columns])


def _arrow_type(pa: Any, dtype: str) -> Any:
    if dtype == "object":  # an unknown field of mixed values: kept as text
        return pa.string()
    return pa.from_numpy_dtype(np.dtype(dtype))


def block_columns(block: SlotBlock) -> dict[str, np.ndarray]:
    """The columns of a SlotBlock as the file numbers them (arms and states from 1)."""
    out: dict[str, np.ndarray] = {}
    for name in block.fields():
        f = BY_NAME[name]
        value = block.column(name)
        if f.one_based:
            value = value.astype(np.int64) + 1
        if f.per_arm:
            for (col, dtype), k in zip(f.table_columns(value.shape[1]), range(value.shape[1]),
                                       strict=True):  # fmt: skip
                out[col] = np.ascontiguousarray(value[:, k], dtype=dtype)
        else:
            out[name] = np.ascontiguousarray(value, dtype=f.dtype)
    for name, value in block.extra.items():
        if value.dtype == object:
            value = np.array([None if v is None else str(v) for v in value], dtype=object)
        if value.ndim == 2:
            for k in range(value.shape[1]):
                out[f"{name}_{k + 1}"] = value[:, k]
        else:
            out[name] = value
    return out


def block_batch(block: SlotBlock) -> pa.RecordBatch:
    """One Arrow record batch of the block's slots (columns of :func:`slot_columns`)."""
    pa = _pyarrow()
    K = block.mu_hat.shape[1]
    schema = arrow_schema(K, block.fields(), block.extra)
    cols = block_columns(block)
    arrays = [pa.array(cols[name], type=schema.field(name).type) for name in schema.names]
    return pa.RecordBatch.from_arrays(arrays, schema=schema)


def sources_batch(block: SourcesBlock) -> pa.RecordBatch:
    """One Arrow record batch of a run of several sources: one row per slot and source,
    slot by slot, with the ``source`` column (numbered from 1)."""
    pa = _pyarrow()
    first = block.sources[0]
    schema = arrow_schema(first.mu_hat.shape[1], first.fields(), first.extra, sources=True)
    n, M = len(block), block.M
    each = [block_columns(s) for s in block.sources]
    cols = {name: np.stack([c[name] for c in each], axis=1).reshape(n * M) for name in each[0]}
    cols[SOURCE_COLUMN[0]] = np.tile(np.arange(1, M + 1, dtype=np.int64), n)
    arrays = [pa.array(cols[name], type=schema.field(name).type) for name in schema.names]
    return pa.RecordBatch.from_arrays(arrays, schema=schema)


class RunData:
    """One recorded run, loaded: ``.slots`` (DataFrame), ``.config``, ``.to_arrow()``.

    ``slots=(first, last)`` restricts every table to the slots ``first..last`` (inclusive,
    1-based t); chunks of the log outside that window are not decompressed.
    """

    def __init__(
        self, path: str | os.PathLike[str] | RunLog, *, slots: tuple[int, int] | None = None
    ) -> None:
        self.log: RunLog = path if isinstance(path, RunLog) else open_log(path)
        self.path: Path = self.log.path
        if slots is not None:
            try:
                first, last = (int(v) for v in slots)
            except (TypeError, ValueError):
                raise UsageError(
                    f"{self.path}: slots must be a pair (first, last) of slot numbers, "
                    f"got {slots!r}"
                ) from None
            if first < 1 or last < first:
                raise UsageError(
                    f"{self.path}: slots=({first}, {last}) is not a window of slot numbers "
                    "(expected 1 <= first <= last)"
                )
            slots = (first, last)
        self.window = slots
        #: the fields of the tables (the declared ones, the unknown ones), from the first block
        self._fields: tuple[tuple[str, ...], Mapping[str, np.ndarray]] | None = None

    def __repr__(self) -> str:
        where = f", slots {self.window[0]}..{self.window[1]}" if self.window else ""
        return f"RunData({str(self.path)!r}, {self.log.label}{where}, {self.log.status})"

    @property
    def K(self) -> int:
        return self.log.config.K

    @cached_property
    def config(self) -> Mapping[str, Any]:
        """The run's settings: policy, params, seed, horizon, instance, and more."""
        md = self.log.metadata
        cfg = self.log.config
        return MappingProxyType(
            {
                "label": cfg.label,
                "policy": cfg.policy.name,
                "params": dict(cfg.policy.params),
                "seed": cfg.seed,
                "horizon": cfg.horizon,
                "instance": cfg.instance_name,
                "arms": cfg.K,
                "states": cfg.n_states,
                "best_arm": int(md["best_arm"]) if "best_arm" in md else None,
                "mu": json.loads(md["mu"]) if "mu" in md else None,
                "corraoi_version": cfg.version,
                "format_version": self.log.format_version,
                "status": self.log.status,
                "slots": self.log.n_slots,
                "run_config": cfg.to_dict(),
            }
        )

    def blocks(self, block: int = BATCH_SLOTS) -> Iterator[Any]:
        """The SlotBlocks of the loaded slots (the window, or every slot); SourcesBlocks for
        a run of several sources."""
        if self.window is None:
            yield from self.log.blocks(block)
        else:
            yield from self.log.window(*self.window)

    def to_arrow(self, *, batch: int = BATCH_SLOTS) -> Iterator[pa.RecordBatch]:
        """Arrow record batches of the slots, streamed: memory bounded by one batch. Every
        batch has the columns of the first (:meth:`arrow_schema`): a field a later block
        lacks is filled (NaN, or False)."""
        _pyarrow()
        for b in self.blocks(batch):
            parts = b.sources if isinstance(b, SourcesBlock) else (b,)
            if self._fields is None:
                self._fields = (parts[0].fields(), parts[0].extra)
            fields, extra = self._fields
            parts = tuple(p if p.fields() == fields and list(p.extra) == list(extra)
                          else _conform(p, fields, extra) for p in parts)  # fmt: skip
            yield sources_batch(SourcesBlock(parts)) if len(parts) > 1 else block_batch(parts[0])

    def arrow_schema(self) -> pa.Schema:
        """The columns of the tables: those of the fields the log holds (its first block's;
        the required ones of an empty log)."""
        if self._fields is None:
            first = next(iter(self.blocks(1)), None)
            if isinstance(first, SourcesBlock):
                first = first.sources[0]
            self._fields = (first.fields(), first.extra) if first is not None else (FIELDS, {})
        return arrow_schema(self.K, *self._fields, sources=self.log.sources > 1)

    @cached_property
    def slots(self) -> pd.DataFrame:
        """One row per slot; dtypes as documented (``docs/analysis.md``)."""
        _pandas()
        pyarrow = _pyarrow()
        batches = list(self.to_arrow())
        table = pyarrow.Table.from_batches(batches, schema=self.arrow_schema())
        frame: pd.DataFrame = table.to_pandas()
        return frame


def _conform(b: SlotBlock, fields: Sequence[str], extra: Mapping[str, np.ndarray]) -> SlotBlock:
    """``b`` with exactly the fields of the table (absent ones filled)."""
    parts: dict[str, Any] = {f: absent_fill(b, f) for f in fields}
    parts["extra"] = {k: absent_fill(b, k) for k in extra}
    parts["absent"] = tuple(f for f in FIELDS if f not in fields)
    for f in parts["absent"]:
        parts[f] = absent_column(f, len(b), b.mu_hat.shape[1])
    return SlotBlock(**parts)


def _pyarrow() -> Any:
    try:
        import pyarrow
    except ImportError:
        raise _missing("pyarrow") from None
    return pyarrow


def _pandas() -> Any:
    try:
        import pandas
    except ImportError:
        raise _missing("pandas") from None
    return pandas


def _missing(what: str) -> Exception:
    from corraoi.errors import MissingExtraError

    return MissingExtraError(
        f"{what} is not installed: tables of logs need the analysis extra, "
        'pip install "corraoi[analysis]"'
    )


__all__ = [
    "BATCH_SLOTS",
    "RunData",
    "arrow_schema",
    "block_batch",
    "block_columns",
    "slot_columns",
    "sources_batch",
    "SINGLE_SOURCE",
    "SOURCE_COLUMN",
]
