"""Per-run sweep results, ``results.parquet``: the writer and the reader side by side.

One row per instance x policy x params x run x checkpoint (``docs/log-format.md``,
section "Per-run results"). :class:`ResultsWriter` is fed by the sweep's checkpoint hook
and writes a row group per policy (or per :data:`ROWS_PER_GROUP` rows) to
``results.parquet.partial``, renamed when the sweep finishes: memory stays bounded by one
row group whatever the number of runs. :func:`read_results` reads a single file or a
dataset directory partitioned by instance (``results.parquet/instance=I1/part-0.parquet``).

pyarrow (and pandas for the reader) are the optional extra ``analysis``.
"""

from __future__ import annotations

import json
import os
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from corraoi._version import __version__
from corraoi.errors import ResultsError
from corraoi.files.partial import PartialFile, partial_path
from corraoi.recorder.vocab import SWEEP_METADATA

if TYPE_CHECKING:
    import pandas as pd
    import pyarrow as pa

    from corraoi.provenance import Provenance


#: File name inside a sweep folder.
RESULTS_FILE = "results.parquet"
#: Name of the format, in the Parquet key-value metadata under ``format``.
FORMAT_NAME = "corraoi.results"
#: Version this code writes and the newest it reads.
FORMAT_VERSION = 1
#: Rows buffered before a row group is written (a policy change also writes one).
ROWS_PER_GROUP = 262_144
#: The columns, in order, with their Arrow types (by name).
COLUMNS: tuple[tuple[str, str], ...] = (
    ("instance", "string"),
    ("policy", "string"),
    ("params", "string"),
    ("horizon", "int64"),
    ("run", "int64"),
    ("seed", "int64"),
    ("t", "int64"),
    ("regret", "float64"),
    ("estimator", "float64"),
    ("best_arm_pulls", "int64"),
)
#: The columns a sweep with a cell of several sources adds after :data:`COLUMNS` (a sweep of
#: single sources writes none of them: its files as before): the cell's number of sources,
#: the run's collisions up to t summed over its sources, and its regret per source (source
#: 1 first; ``regret`` is their sum). A cell of one source: 1, 0 and [regret].
SOURCE_COLUMNS: tuple[tuple[str, str], ...] = (
    ("sources", "int64"),
    ("collisions", "int64"),
    ("regret_by_source", "list<float64>"),
)


def results_schema(metadata: dict[str, str] | None = None, *,
                   sources: bool = False) -> pa.Schema:  # fmt: skip
    """The Arrow schema of ``results.parquet`` (with ``metadata`` as key-value metadata);
    ``sources``: with the :data:`SOURCE_COLUMNS` of a sweep of several sources."""
    import pyarrow as pa

    types = {"string": pa.string(), "int64": pa.int64(), "float64": pa.float64(),
             "list<float64>": pa.list_(pa.float64())}  # fmt: skip
    columns = COLUMNS + (SOURCE_COLUMNS if sources else ())
    return pa.schema([(n, types[t]) for n, t in columns], metadata=metadata)


def params_json(params: dict[str, float]) -> str:
    """The ``params`` column: the policy's parameters as JSON with sorted keys."""
    return json.dumps({k: float(v) for k, v in params.items()}, sort_keys=True)


def results_metadata(config: dict[str, Any]) -> dict[str, str]:
    """The key-value metadata: format, version, corraoi version, the sweep configuration."""
    return {
        "format": FORMAT_NAME,
        "format_version": str(FORMAT_VERSION),
        "corraoi_version": str(config.get("version", __version__)),
        "numbering": "run from 0 (seed = master seed + run); t is the checkpoint slot",
        "sweep_config": json.dumps(config, sort_keys=True),
    }


def write_dataset(
    path: str | os.PathLike[str], grid: Any, parts: dict[str, list[Any]], provenance: Provenance
) -> Path:
    """Compact a grid's finished chunks into ``path`` (``results.parquet``), a dataset
    partitioned by instance: ``instance=<name>/part-0.parquet``, rows in grid order (cell,
    checkpoint, run), with ``provenance`` (what made the rows) in its metadata. Written to
    ``<path>.partial`` and swapped in when complete."""
    from urllib.parse import quote

    import pyarrow as pa
    import pyarrow.parquet as pq

    out = PartialFile(path, overwrite=True, what="results", folder=True, sweep=True)
    many = any(cell.sources > 1 for cell in grid.cells)
    full = results_schema(sources=many)
    metadata = results_metadata({**grid.to_dict(), "version": __version__})
    metadata["provenance"] = json.dumps(provenance.to_dict(), sort_keys=True)
    schema = pa.schema([f for f in full if f.name != "instance"], metadata=metadata)
    by_instance: dict[str, list[Any]] = {}
    for cell in grid.cells:
        by_instance.setdefault(cell.instance.name, []).append(cell)
    with out:  # published when whole; on an error discarded (a failed write: one line)
        for name, cells in by_instance.items():
            folder = out.partial / f"instance={quote(name, safe='')}"
            folder.mkdir(parents=True)
            with pq.ParquetWriter(str(folder / "part-0.parquet"), schema,
                                  compression="zstd") as writer:  # fmt: skip
                for cell in cells:
                    chunks = [p for p in parts.get(cell.key, []) if p.chunk.start < grid.runs]
                    regret = np.concatenate([p.regret for p in chunks])[: grid.runs]
                    estimator = np.concatenate([p.estimator for p in chunks])[: grid.runs]
                    best = np.concatenate([p.best_pulls for p in chunks])[: grid.runs]
                    R, S = regret.shape
                    t = np.asarray(chunks[0].t, dtype=np.int64)
                    runs = np.tile(np.arange(R, dtype=np.int64), S)
                    n = R * S
                    cols = [
                        pa.array([cell.policy.name] * n, pa.string()),
                        pa.array([params_json(cell.policy.params)] * n, pa.string()),
                        pa.array(np.full(n, cell.horizon, dtype=np.int64)),
                        pa.array(runs),
                        pa.array(runs + grid.seed),
                        pa.array(np.repeat(t, R)),
                        pa.array(regret.T.reshape(-1)),
                        pa.array(estimator.T.reshape(-1)),
                        pa.array(best.T.reshape(-1).astype(np.int64)),
                    ]
                    if many:
                        cols += _source_columns(chunks, grid.runs, regret, n)
                    writer.write_table(pa.Table.from_arrays(cols, schema=schema))
    return out.path


def _source_columns(chunks: list[Any], runs: int, regret: np.ndarray, n: int) -> list[Any]:
    """The :data:`SOURCE_COLUMNS` of one cell's rows (checkpoint-major, as the others)."""
    import pyarrow as pa

    R, S = regret.shape
    if chunks[0].regret_by_source is None:  # one source
        M, by = 1, regret[:, :, None]
        hits = np.zeros((R, S), dtype=np.int64)
    else:
        by = np.concatenate([p.regret_by_source for p in chunks])[:runs]
        hits = np.concatenate([p.collisions for p in chunks])[:runs].astype(np.int64)
        M = by.shape[2]
    flat = by.transpose(1, 0, 2).reshape(-1)  # (S, R, M): a row's sources together
    offsets = np.arange(0, n * M + 1, M, dtype=np.int32)
    return [pa.array(np.full(n, M, dtype=np.int64)), pa.array(hits.T.reshape(-1)),
            pa.ListArray.from_arrays(pa.array(offsets), pa.array(flat))]  # fmt: skip


# ---------------------------------------------------------------------------- reading


def _files(p: Path) -> list[Path]:
    if p.is_dir():
        return sorted(f for f in p.rglob("*.parquet") if f.is_file())
    return [p]


def read_metadata(path: str | os.PathLike[str]) -> dict[str, str]:
    """The key-value metadata of a results file (of its first part for a dataset)."""
    import pyarrow.parquet as pq

    p = Path(path)
    if not p.exists():
        part = partial_path(p)
        hint = f" ({part} exists: the sweep did not finish)" if part.exists() else ""
        raise ResultsError(f"{p}: no such results file{hint}")
    files = _files(p)
    if not files:
        raise ResultsError(f"{p}: a directory without .parquet files (expected results)")
    try:
        raw = pq.read_schema(files[0]).metadata or {}
    except (OSError, ValueError) as exc:
        raise ResultsError(f"{files[0]}: not a readable Parquet file ({exc})") from None
    md = {k.decode(): v.decode() for k, v in raw.items()}
    if md.get("format") != FORMAT_NAME:
        raise ResultsError(
            f"{files[0]}: a Parquet file but not corraoi's per-run results "
            f"(no format {FORMAT_NAME!r} in its metadata)"
        )
    version = md.get("format_version", "")
    if not version.isdigit() or int(version) > FORMAT_VERSION:
        raise ResultsError(
            f"{files[0]}: results format version {version!r}; this corraoi reads up to "
            f"{FORMAT_VERSION}: upgrade corraoi"
        )
    return md


def read_results_table(path: str | os.PathLike[str]) -> pa.Table:
    """The results as one Arrow table with the documented columns and types.

    ``path`` is ``results.parquet`` (a file) or a dataset directory partitioned by
    instance (``instance=I1/part-*.parquet``); the partition key becomes the ``instance``
    column.
    """
    import pyarrow as pa
    import pyarrow.dataset as ds

    p = Path(path)
    read_metadata(p)
    try:
        if p.is_dir():
            dataset = ds.dataset(str(p), format="parquet", partitioning="hive")
        else:
            dataset = ds.dataset(str(p), format="parquet")
        table = dataset.to_table()
    except (OSError, ValueError, pa.ArrowException) as exc:
        raise ResultsError(f"{p}: cannot read the results ({exc})") from None
    names = [n for n, _ in COLUMNS]
    missing = [n for n in names if n not in table.column_names]
    if missing:
        raise ResultsError(f"{p}: the results lack the column(s) {', '.join(missing)}")
    many = all(n in table.column_names for n, _ in SOURCE_COLUMNS)  # several sources
    if many:
        names += [n for n, _ in SOURCE_COLUMNS]
    schema = results_schema(sources=many)
    cols = [table.column(n).cast(schema.field(n).type) for n in names]
    return pa.Table.from_arrays(cols, schema=schema)


def read_results(path: str | os.PathLike[str]) -> pd.DataFrame:
    """``results.parquet`` (a file or a partitioned dataset) as a pandas DataFrame."""
    frame: pd.DataFrame = read_results_table(path).to_pandas()
    return frame


# ---------------------------------------------------------------------------- sweeps


def is_sweep_path(p: Path) -> bool:
    """Whether ``p`` is a sweep folder, its results, or a sweep log (not a slot log)."""
    if p.suffix == ".parquet":  # results.parquet: a file, or a partitioned folder
        return True
    if p.is_dir():
        return any((p / f).exists() for f in (RESULTS_FILE, "sweep.mcap", "summary.json"))
    return p.is_file() and _first_metadata(p) == SWEEP_METADATA


def _first_metadata(p: Path) -> str | None:
    """The name of the first metadata record of an MCAP file (None: none, or not MCAP)."""
    from mcap.records import Metadata

    from corraoi.recorder.walk import Walker

    try:
        with open(p, "rb") as f:
            for _, record in Walker(f, p).records(read_chunks=False):
                if isinstance(record, Metadata):
                    return str(record.name)
    except Exception:  # noqa: BLE001 - not MCAP or damaged: the slot-log reader says why
        return None
    return None


class SweepData:
    """A sweep folder, loaded: ``.runs`` (per-run results), ``.summary``, ``.curves``."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        p = Path(path)
        # a partitioned results.parquet is a directory too: its parent is the sweep folder
        self.folder = p.parent if (p.is_file() or p.suffix == ".parquet") else p
        self.results_path = p if p.suffix == ".parquet" else self.folder / RESULTS_FILE
        self.log_path = p if p.suffix == ".mcap" else self.folder / "sweep.mcap"
        #: (instance, horizon) of a group folder inside a grid's folder: its rows only
        self.group: tuple[str, int] | None = None
        if not self.results_path.exists():
            self._find_grid_results()

    def _find_grid_results(self) -> None:
        """A group folder of a grid (``DIR/I1``): the results are the grid's, filtered."""
        manifest = self.folder.parent / "manifest.json"
        if not manifest.is_file():
            return
        try:
            groups = json.loads(manifest.read_text(encoding="utf-8")).get("groups", {})
        except (OSError, ValueError, RecursionError, AttributeError):
            return
        if not isinstance(groups, dict):
            return
        entry = groups.get(self.folder.name)
        if isinstance(entry, dict) and "instance" in entry:
            self.results_path = self.folder.parent / RESULTS_FILE
            self.group = (str(entry["instance"]), int(entry["horizon"]))

    def __repr__(self) -> str:
        return f"SweepData({str(self.folder)!r})"

    @cached_property
    def runs(self) -> pd.DataFrame:
        """One row per policy x run x checkpoint (columns in ``docs/log-format.md``)."""
        if not self.results_path.exists() and not partial_path(self.results_path).exists():
            raise ResultsError(
                f"{self.results_path}: no per-run results in {self.folder} (written by "
                "`corraoi sweep -o DIR` with the analysis extra installed)"
            )
        frame = read_results(self.results_path)
        if self.group is not None:
            name, horizon = self.group
            keep = (frame["instance"] == name) & (frame["horizon"] == horizon)
            frame = frame[keep].reset_index(drop=True)
        return frame

    @cached_property
    def summary(self) -> dict[str, Any] | None:
        """``summary.json`` (None when the folder has none)."""
        f = self.folder / "summary.json"
        if not f.exists():
            return None
        try:
            out: dict[str, Any] = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError) as exc:
            why = " ".join(str(exc).split())[:120] or type(exc).__name__
            raise ResultsError(f"{f}: cannot read the summary ({why})") from None
        return out

    @cached_property
    def config(self) -> dict[str, Any]:
        """The sweep configuration (from the sweep log, else the results' metadata: a grid)."""
        from .read import read_sweep

        if self.log_path.exists():
            return read_sweep(self.log_path).config
        out: dict[str, Any] = json.loads(read_metadata(self.results_path)["sweep_config"])
        return out

    @cached_property
    def curves(self) -> pd.DataFrame:
        """The sweep log's aggregated curves: policy, t, means, CI half-widths, shares."""
        import pandas as pd

        from .read import read_sweep

        log = read_sweep(self.log_path)
        parts = []
        for name in log.policies:
            c = log.curves[name]
            part = pd.DataFrame(
                {
                    "policy": pd.Series([name] * len(c), dtype="string"),
                    "t": c.t,
                    "regret_mean": c.regret_mean,
                    "regret_ci95": c.regret_ci95,
                    "estimator_mean": c.estimator_mean,
                    "estimator_ci95": c.estimator_ci95,
                }
            )
            for k in range(c.pull_share.shape[1]):
                part[f"pull_share_{k + 1}"] = c.pull_share[:, k]
            if c.collisions_mean is not None:  # a cell of several sources
                part["collisions_mean"] = c.collisions_mean
                part["collisions_ci95"] = c.collisions_ci95
            parts.append(part)
        return pd.concat(parts, ignore_index=True) if parts else pd.DataFrame()


__all__ = [
    "COLUMNS",
    "FORMAT_NAME",
    "SOURCE_COLUMNS",
    "FORMAT_VERSION",
    "RESULTS_FILE",
    "SweepData",
    "is_sweep_path",
    "params_json",
    "read_metadata",
    "read_results",
    "read_results_table",
    "results_metadata",
    "results_schema",
]
