"""A slot log as a table: pandas DataFrames and Arrow record batches, numbered from 1.

:class:`RunData` is what ``corraoi.load("run.mcap")`` returns. It reads the log with the
one reader (:func:`recorder.slotlog.reader.open_log`) and turns each SlotBlock into an Arrow
record batch whose columns are the log's fields exactly as the file holds them: arms and
states numbered from 1, per-arm arrays spread into wide columns. pandas and pyarrow are
the optional extra ``analysis``; they are imported when a table is built.

Columns (``docs/analysis.md`` documents them): ``t, x, arm`` (int64), ``success`` (bool),
``aoi, oracle_aoi, regret`` (int64), ``estimator`` (float64), ``mu_hat_1..K`` (float64),
``pulls_1..K`` (int64), ``cand_1..K`` (bool), ``override`` (bool).
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator, Mapping
from functools import cached_property
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from corraoi.engine.block import SlotBlock
from corraoi.errors import UsageError

from .reader import RunLog, open_log

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

#: Slots per record batch of :meth:`RunData.to_arrow` (one chunk of the log is 1000).
BATCH_SLOTS = 65_536


def slot_columns(K: int, absent: tuple[str, ...] = ()) -> list[tuple[str, str]]:
    """(name, dtype) of every column of the slots table of a run with K arms, in order;
    those of its log's ``absent`` fields (``RunConfig.absent``) left out."""
    cols = [
        ("t", "int64"),
        ("x", "int64"),
        ("arm", "int64"),
        ("success", "bool"),
        ("aoi", "int64"),
        ("oracle_aoi", "int64"),
        ("regret", "int64"),
        ("estimator", "float64"),
    ]
    cols += [(f"mu_hat_{k}", "float64") for k in range(1, K + 1)]
    cols += [(f"pulls_{k}", "int64") for k in range(1, K + 1)]
    cols += [(f"cand_{k}", "bool") for k in range(1, K + 1)]
    cols.append(("override", "bool"))
    return [c for c in cols if _field_of(c[0]) not in absent] if absent else cols


def _field_of(column: str) -> str:
    """The slot record's field a column of the table shows (``mu_hat_2``: ``mu_hat``)."""
    head, _, tail = column.rpartition("_")
    if not tail.isdigit():
        return column
    return "candidates" if head == "cand" else head


def arrow_schema(K: int, absent: tuple[str, ...] = ()) -> pa.Schema:
    pa = _pyarrow()
    types = {"int64": pa.int64(), "float64": pa.float64(), "bool": pa.bool_()}
    return pa.schema([(name, types[dtype]) for name, dtype in slot_columns(K, absent)])


def block_columns(block: SlotBlock) -> dict[str, np.ndarray]:
    """The columns of a SlotBlock as the file numbers them (arms and states from 1)."""
    K = block.mu_hat.shape[1]
    out: dict[str, np.ndarray] = {
        "t": block.t.astype(np.int64, copy=False),
        "x": block.x.astype(np.int64) + 1,
        "arm": block.arm.astype(np.int64) + 1,
        "success": block.success.astype(bool, copy=False),
        "aoi": block.aoi.astype(np.int64, copy=False),
        "oracle_aoi": block.oracle_aoi.astype(np.int64, copy=False),
        "regret": block.regret.astype(np.int64, copy=False),
        "estimator": block.estimator.astype(np.float64, copy=False),
    }
    for k in range(K):
        out[f"mu_hat_{k + 1}"] = np.ascontiguousarray(block.mu_hat[:, k], dtype=np.float64)
    for k in range(K):
        out[f"pulls_{k + 1}"] = np.ascontiguousarray(block.pulls[:, k], dtype=np.int64)
    for k in range(K):
        out[f"cand_{k + 1}"] = np.ascontiguousarray(block.candidates[:, k], dtype=bool)
    out["override"] = block.override.astype(bool, copy=False)
    return out


def block_batch(block: SlotBlock, absent: tuple[str, ...] = ()) -> pa.RecordBatch:
    """One Arrow record batch of the block's slots (columns of :func:`slot_columns`, those
    of the ``absent`` fields left out)."""
    pa = _pyarrow()
    K = block.mu_hat.shape[1]
    cols = block_columns(block)
    arrays = [pa.array(cols[name]) for name, _ in slot_columns(K, absent)]
    return pa.RecordBatch.from_arrays(arrays, schema=arrow_schema(K, absent))


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

    def __repr__(self) -> str:
        where = f", slots {self.window[0]}..{self.window[1]}" if self.window else ""
        return f"RunData({str(self.path)!r}, {self.log.label}{where}, {self.log.status})"

    @property
    def K(self) -> int:
        return self.log.config.instance.K

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
                "instance": cfg.instance.name,
                "arms": cfg.instance.K,
                "states": cfg.instance.n_states,
                "best_arm": int(md["best_arm"]) if "best_arm" in md else None,
                "mu": json.loads(md["mu"]) if "mu" in md else None,
                "corraoi_version": cfg.version,
                "format_version": self.log.format_version,
                "status": self.log.status,
                "slots": self.log.n_slots,
                "run_config": cfg.to_dict(),
            }
        )

    def blocks(self, block: int = BATCH_SLOTS) -> Iterator[SlotBlock]:
        """The SlotBlocks of the loaded slots (the window, or every slot)."""
        if self.window is None:
            yield from self.log.blocks(block)
        else:
            yield from self.log.window(*self.window)

    def to_arrow(self, *, batch: int = BATCH_SLOTS) -> Iterator[pa.RecordBatch]:
        """Arrow record batches of the slots, streamed: memory bounded by one batch."""
        _pyarrow()
        absent = self.log.config.absent
        for b in self.blocks(batch):
            yield block_batch(b, absent)

    def arrow_schema(self) -> pa.Schema:
        return arrow_schema(self.K, self.log.config.absent)

    @cached_property
    def slots(self) -> pd.DataFrame:
        """One row per slot; dtypes as documented (``docs/analysis.md``)."""
        _pandas()
        pyarrow = _pyarrow()
        table = pyarrow.Table.from_batches(list(self.to_arrow()), schema=self.arrow_schema())
        frame: pd.DataFrame = table.to_pandas()
        return frame


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
]
