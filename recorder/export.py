"""Export a slot log or a sweep's per-run results to CSV or Parquet, streamed and atomic.

The table written is exactly what ``corraoi.load`` gives: ``.slots`` of a slot log (one
row per slot, arms and states from 1) or ``.runs`` of a sweep (``results.parquet``). The
format comes from the output's extension; the file is written as ``<out>.partial`` and
renamed when complete.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import TYPE_CHECKING

from corraoi.errors import UsageError
from corraoi.files.partial import PartialFile

from .sink import made_again

if TYPE_CHECKING:
    import pyarrow as pa

#: Output formats by extension.
FORMATS = {".csv": "csv", ".parquet": "parquet"}


@dataclass(frozen=True)
class Exported:
    path: Path
    kind: str  # "slots" or "runs"
    rows: int
    format: str


def export_format(out: Path) -> str:
    """The format named by ``out``'s extension, or a UsageError listing the known ones."""
    fmt = FORMATS.get(out.suffix.lower())
    if fmt is None:
        raise UsageError(
            f"{out}: unknown export format {out.suffix or '(no extension)'!r}, expected a "
            f"file name ending in {' or '.join(FORMATS)}"
        )
    return fmt


def export(
    source: str | os.PathLike[str], out: str | os.PathLike[str], *, overwrite: bool = False
) -> Exported:
    """Write the table of ``source`` (slot log, sweep folder or sweep log) to ``out``."""
    from corraoi.extras import require

    out_p = Path(out)
    fmt = export_format(out_p)
    require("analysis", "corraoi export", ("pyarrow",))
    from corraoi.recorder.slotlog.frames import RunData
    from corraoi.recorder.sweeplog.results import SweepData, is_sweep_path, read_results_table

    src = Path(source)
    # a .partial a killed export left is made again from the source: never in the way
    target = PartialFile(out_p, overwrite=overwrite, what=f"{fmt} export", replaceable=made_again)
    if is_sweep_path(src):
        sweep = SweepData(src)
        table = read_results_table(sweep.results_path)
        if fmt == "csv":  # CSV has no lists: regret_by_source is regret_by_source_1 .. _M
            table = _lists_as_columns(table)
        rows = _write(target, fmt, table.schema, table.to_batches())
        return Exported(out_p, "runs", rows, fmt)
    run = RunData(src)
    batches = run.to_arrow()
    first = next(batches, None)  # its columns: the fields the log holds
    rows = _write(target, fmt, run.arrow_schema(), chain([first] if first else [], batches))
    return Exported(out_p, "slots", rows, fmt)


def _write(
    target: PartialFile, fmt: str, schema: pa.Schema, batches: Iterable[pa.RecordBatch]
) -> int:
    import pyarrow.csv as pcsv
    import pyarrow.parquet as pq

    rows = 0
    with target:  # published when whole; on an error discarded (a failed write: one line)
        writer: pq.ParquetWriter | pcsv.CSVWriter
        if fmt == "parquet":
            writer = pq.ParquetWriter(str(target.partial), schema, compression="zstd")
        else:
            writer = pcsv.CSVWriter(str(target.partial), schema)
        try:
            for batch in _nonempty(batches):
                writer.write_batch(batch)
                rows += batch.num_rows
        finally:
            writer.close()
    return rows


def _lists_as_columns(table: pa.Table) -> pa.Table:
    """``table`` with each list column (a sweep of several sources' ``regret_by_source``)
    as one column per position, ``<name>_1 .. <name>_M`` (numbered from 1, as ``mu_hat_1``
    is; M the longest list; empty where a row's list is shorter: a cell of fewer sources)."""
    import numpy as np
    import pyarrow as pa

    for i, field in reversed(list(enumerate(table.schema))):
        if not pa.types.is_list(field.type):
            continue
        col = table.column(i).combine_chunks()
        starts = col.offsets.to_numpy()[:-1]
        lengths = col.value_lengths().fill_null(0).to_numpy(zero_copy_only=False)
        values = col.values.to_numpy(zero_copy_only=False)  # offsets index it as they are
        table = table.remove_column(i)
        for m in range(int(lengths.max(initial=0))):
            held = lengths > m
            out = np.zeros(len(col), dtype=values.dtype)
            out[held] = values[starts[held] + m]
            named = pa.field(f"{field.name}_{m + 1}", field.type.value_type)
            table = table.add_column(i + m, named, pa.array(out, mask=~held))
    return table


def _nonempty(batches: Iterable[pa.RecordBatch]) -> Iterator[pa.RecordBatch]:
    for b in batches:
        if b.num_rows:
            yield b


__all__ = ["Exported", "FORMATS", "export", "export_format"]
