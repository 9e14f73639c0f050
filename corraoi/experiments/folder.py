"""The sweep folder's format: what ``corraoi sweep -o DIR`` keeps for resumes and appends
(docs/log-format.md, section 5), read and written in one place.

* ``manifest.json``: the grid and the sweep's status (:func:`read_manifest`,
  :func:`write_manifest`; :func:`merge_grids` extends an old grid by a new one);
* ``parts/<cell>-<first run>-<end run>.npz``: one :class:`ChunkResult` per finished chunk,
  with :class:`DeviceAggregates` when a device ran it (the GPU backend);
* :class:`CellRuns`: a cell's parts joined in run order, what summaries and logs are made of;
* :func:`group_dirs`: where each (instance, horizon) group's logs and figures go.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from corraoi._version import __version__
from corraoi.errors import ConfigError, DamagedPart
from corraoi.files.guard import MANIFEST_FORMAT
from corraoi.files.partial import PartialFile
from corraoi.stats import Moments

from .grid import Cell, Chunk, Grid

MANIFEST = "manifest.json"
PARTS = "parts"
MANIFEST_VERSION = 1
#: What a group folder holds (written from the parts when the sweep finishes).
GROUP_FILES = ("sweep.mcap", "sweep.rrd", "summary.json", "summary.md", "figure.png")


@dataclass(frozen=True)
class Words:
    """How a message names the caller's options: the command line's (``--resume``) or
    Python's (``resume=True``). The experiments' refusals take one and say its words."""

    resume: str = "--resume"
    force: str = "--force"
    kept_code: str = "--kept-code"
    allow_changed_code: str = "--allow-changed-code"
    chunk: str = "--chunk"
    backend: str = "--backend"
    #: which run of a sweep to record, whose cells, which policies (each followed by a value)
    run: str = "--run "
    cell: str = "--cell "
    policy: str = "--policy "


#: The command line's words, and Python's (``corraoi.sweep``, ``Sweep.record``).
CLI_WORDS = Words()
PYTHON_WORDS = Words("resume=True", "force=True", "kept_code=True", "allow_changed_code=True",
                     "chunk=", "backend=", "which=", "cell=", "policy=")  # fmt: skip


@dataclass
class DeviceAggregates:
    """What a device returns for a chunk instead of every run's checkpoints (the GPU backend):
    moments over the runs at every checkpoint ``t``, and those of the run-by-run regret
    difference against ``baseline`` (computed on the device)."""

    t: np.ndarray  # (S,) every checkpoint slot
    regret: Moments
    estimator: Moments
    pulls_sum: np.ndarray  # (S, K) int64
    paired: Moments | None = None
    baseline: str | None = None

    def merge(self, other: DeviceAggregates) -> DeviceAggregates:
        paired = None
        if self.paired is not None and other.paired is not None and (
            self.baseline == other.baseline
        ):
            paired = self.paired.merge(other.paired)
        return DeviceAggregates(self.t, self.regret.merge(other.regret),
                                self.estimator.merge(other.estimator),
                                self.pulls_sum + other.pulls_sum, paired,
                                self.baseline if paired is not None else None)  # fmt: skip

    def arrays(self) -> dict[str, Any]:
        out: dict[str, Any] = {"agg_t": self.t, "agg_n": self.regret.n}
        for name, m in (("regret", self.regret), ("estimator", self.estimator),
                        ("paired", self.paired)):  # fmt: skip
            if m is not None:
                out[f"agg_{name}_mean"] = m.mean
                out[f"agg_{name}_m2"] = m.m2
        out["agg_pulls_sum"] = self.pulls_sum
        if self.baseline is not None:
            out["agg_baseline"] = np.array(self.baseline)
        return out

    @classmethod
    def from_arrays(cls, z: Any) -> DeviceAggregates | None:
        if "agg_t" not in z:
            return None
        n = int(z["agg_n"])

        def moments(name: str) -> Moments | None:
            if f"agg_{name}_mean" not in z:
                return None
            return Moments(n, z[f"agg_{name}_mean"], z[f"agg_{name}_m2"])

        regret, estimator = moments("regret"), moments("estimator")
        if regret is None or estimator is None:
            raise KeyError("agg_regret_mean")
        return cls(z["agg_t"], regret, estimator, z["agg_pulls_sum"], moments("paired"),
                   str(z["agg_baseline"]) if "agg_baseline" in z else None)  # fmt: skip


@dataclass
class ChunkResult:
    """The per-run values of one chunk at every checkpoint (what a part file holds).

    A chunk run on a device (``agg`` set) holds every run's values at the horizon only
    (``t`` = [T]) and the aggregates over its runs at every checkpoint.
    """

    chunk: Chunk
    t: np.ndarray  # (S,) checkpoint slots
    regret: np.ndarray  # (n, S) float64
    estimator: np.ndarray  # (n, S) float64
    best_pulls: np.ndarray  # (n, S) int64 pulls of the best arm
    pulls_sum: np.ndarray  # (S, K) int64 pulls per arm summed over the chunk's runs
    wall_s: float
    agg: DeviceAggregates | None = None
    #: a cell of several sources: each run's regret per source (n, S, M) and its collisions
    #: summed over its sources (n, S) (``regret`` is their sum); None for one source
    regret_by_source: np.ndarray | None = None
    collisions: np.ndarray | None = None

    def save(self, path: Path) -> None:
        """Write through the ``.partial`` protocol: a part exists only when complete."""
        extra = self.agg.arrays() if self.agg is not None else {}
        if self.regret_by_source is not None and self.collisions is not None:
            extra = {**extra, "regret_by_source": self.regret_by_source,
                     "collisions": self.collisions}  # fmt: skip
        with PartialFile(path, overwrite=True, what="part file", sweep=True) as target:
            np.savez(
                target.file, cell=np.array(self.chunk.cell), start=self.chunk.start,
                stop=self.chunk.stop, t=self.t, regret=self.regret, estimator=self.estimator,
                best_pulls=self.best_pulls, pulls_sum=self.pulls_sum, wall_s=self.wall_s,
                **extra,
            )  # fmt: skip

    @classmethod
    def load(cls, path: Path) -> ChunkResult:
        """Read and check a part file; :class:`DamagedPart` (one line, with the path) for a
        file that is not a whole part of the chunk its name says: truncated, zeroed, not a
        zip, arrays missing or of the wrong shape, or another chunk's part under this name."""
        try:
            with np.load(path) as z:
                part = cls(
                    chunk=Chunk(str(z["cell"]), int(z["start"]), int(z["stop"])),
                    t=z["t"], regret=z["regret"], estimator=z["estimator"],
                    best_pulls=z["best_pulls"], pulls_sum=z["pulls_sum"],
                    wall_s=float(z["wall_s"]), agg=DeviceAggregates.from_arrays(z),
                    regret_by_source=z["regret_by_source"] if "regret_by_source" in z else None,
                    collisions=z["collisions"] if "collisions" in z else None,
                )  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - zip, zlib, pickle, numpy: all "damaged"
            detail = " ".join(str(exc).split())[:200] or type(exc).__name__
            raise DamagedPart(path, f"{type(exc).__name__}: {detail}") from None
        part.check(path)
        return part

    def check(self, path: Path) -> None:
        """DamagedPart unless the arrays agree with each other and with the file's name."""
        c = self.chunk
        if path.stem != c.name:
            raise DamagedPart(path, f"it holds chunk {c.name}, not the chunk its name says")
        n, S = c.stop - c.start, self.t.shape[0] if self.t.ndim == 1 else -1
        if n < 1 or S < 1 or np.any(np.diff(self.t) <= 0) or self.t[0] < 1:
            raise DamagedPart(path, "its checkpoints or run range are not valid")
        for name in ("regret", "estimator", "best_pulls"):
            if getattr(self, name).shape != (n, S):
                raise DamagedPart(path, f"{name} has shape {getattr(self, name).shape}, "
                                        f"expected ({n}, {S})")  # fmt: skip
        if (self.regret_by_source is None) != (self.collisions is None) or (
            self.regret_by_source is not None and self.collisions is not None and (
                self.regret_by_source.ndim != 3 or self.regret_by_source.shape[:2] != (n, S)
                or self.collisions.shape != (n, S))
        ):
            raise DamagedPart(path, "its per-source regret or collisions do not match its runs")
        if self.pulls_sum.ndim != 2 or self.pulls_sum.shape[0] != S:
            raise DamagedPart(path, f"pulls_sum has shape {self.pulls_sum.shape}")
        if not (np.all(np.isfinite(self.regret)) and np.all(np.isfinite(self.estimator))):
            raise DamagedPart(path, "it holds values that are not finite")

    @classmethod
    def from_device(cls, chunk: Chunk, run: Any, baseline: str | None) -> ChunkResult:
        """The part of a chunk run on a device (:class:`corraoi.gpu.runner.DeviceRun`)."""
        agg = DeviceAggregates(run.t, run.regret, run.estimator, run.pulls_sum, run.paired,
                               baseline if run.paired is not None else None)  # fmt: skip
        return cls(chunk=chunk, t=run.t[-1:], regret=run.regret_final[:, None],
                   estimator=run.estimator_final[:, None],
                   best_pulls=run.best_pulls_final[:, None], pulls_sum=run.pulls_sum[-1:],
                   wall_s=run.wall_s, agg=agg)  # fmt: skip


def group_dirs(grid: Grid, out: Path) -> dict[tuple[str, int], Path]:
    """Where each (instance, horizon) group's logs and figures go."""
    groups = list(grid.groups())
    if len(groups) == 1:
        return {groups[0]: out}
    horizons = {h for _, h in groups}
    out_dirs: dict[tuple[str, int], Path] = {}
    for name, h in groups:
        base = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-") or "instance"
        out_dirs[(name, h)] = out / (base if len(horizons) == 1 else f"{base}-T{h}")
    return out_dirs


def read_manifest(out: Path) -> Grid | None:
    """The grid of a sweep folder (None when it has no manifest)."""
    path = out / MANIFEST
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as exc:
        why = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise ConfigError(f"{path}: unreadable manifest ({why})") from None
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
        raise ConfigError(f"{path}: not a corraoi sweep manifest")
    version = data.get("format_version")
    if type(version) is not int or version < 1:
        raise ConfigError(f"{path}: manifest format_version {_shown(version)}: expected a whole "
                          f"number from 1 to {MANIFEST_VERSION} (a damaged manifest)")
    if version > MANIFEST_VERSION:
        raise ConfigError(f"{path}: manifest version {version}: upgrade corraoi")
    grid = data.get("grid")
    if not isinstance(grid, dict):
        raise ConfigError(f"{path}: not a corraoi grid (no 'grid' object)")
    return Grid.from_dict(grid, where=str(path))


def _shown(value: Any) -> str:
    """A value from a file, shown in one short line."""
    text = json.dumps(value)
    return text[:40] + ("..." if len(text) > 40 else "")


def write_manifest(out: Path, grid: Grid, status: str,
                   provenance: dict[str, Any] | None = None) -> None:  # fmt: skip
    data = {
        "format": MANIFEST_FORMAT,
        "format_version": MANIFEST_VERSION,
        "corraoi_version": __version__,
        "status": status,
        "grid": grid.to_dict(),
        "groups": {str(p.relative_to(out)) or ".": {"instance": name, "horizon": h}
                   for (name, h), p in group_dirs(grid, out).items()},  # fmt: skip
        **({"provenance": provenance} if provenance is not None else {}),
    }
    write_text(out / MANIFEST, json.dumps(data, indent=1, sort_keys=True) + "\n", "manifest")


def write_text(path: Path, text: str, what: str = "file") -> None:
    """Write ``path`` through the ``.partial`` protocol
    (:class:`~corraoi.files.partial.PartialFile`)."""
    PartialFile.write_bytes(path, text.encode(), overwrite=True, what=what, sweep=True)


def merge_grids(old: Grid, new: Grid, where: Path, words: Words = CLI_WORDS) -> Grid:
    """The grid of an existing folder extended by ``new`` (more runs, cells): an append."""
    if old.seed != new.seed:
        raise ConfigError(f"{where}: holds a sweep with seed {old.seed}; {words.resume} needs the "
                          f"same seed (got {new.seed})")  # fmt: skip
    if old.chunk != new.chunk and new.chunk:
        raise ConfigError(f"{where}: holds a sweep in chunks of {old.chunk or old.runs} runs; "
                          f"{words.resume} keeps them (got {words.chunk}"
                          f"{'' if words.chunk.endswith('=') else ' '}{new.chunk})")  # fmt: skip
    if old.checkpoints != new.checkpoints:
        raise ConfigError(f"{where}: holds a sweep with {old.checkpoints} checkpoints; "
                          f"{words.resume} keeps them")  # fmt: skip
    if old.backend != new.backend:  # other random streams: the runs would not pair
        sep = "" if words.backend.endswith("=") else " "
        raise ConfigError(f"{where}: holds a sweep run with {words.backend}{sep}{old.backend}; "
                          f"{words.resume} it with {words.backend}{sep}{old.backend} (got "
                          f"{new.backend})")  # fmt: skip
    cells = list(old.cells)
    keys = {c.key for c in cells}
    cells += [c for c in new.cells if c.key not in keys]
    return Grid(tuple(cells), runs=max(old.runs, new.runs), seed=old.seed, chunk=old.chunk,
                checkpoints=old.checkpoints, baseline=new.baseline or old.baseline,
                backend=old.backend)  # fmt: skip


def read_parts(
    out: Path,
    grid: Grid | None = None,
    on_damaged: Callable[[DamagedPart], None] | None = None,
) -> dict[str, list[ChunkResult]]:
    """The finished chunks of a folder by cell key (each run range once, sorted).

    Every part is checked (:meth:`ChunkResult.load`); with ``grid``, also against the
    folder's grid (a cell it has, runs within its range, its checkpoints). A damaged part
    raises :class:`DamagedPart`, or with ``on_damaged`` is reported there and left out, so
    that its chunk runs again (``--resume``): never counted, never a traceback.
    """
    found: dict[str, list[ChunkResult]] = {}
    folder = out / PARTS
    if not folder.is_dir():
        return found
    cells = {c.key: c for c in grid.cells} if grid is not None else None
    for f in sorted(folder.glob("*.npz")):
        try:
            part = ChunkResult.load(f)
            if cells is not None and grid is not None:
                _check_against(part, f, cells, grid)
            taken = found.get(part.chunk.cell, [])
            if any(p.chunk.start < part.chunk.stop and part.chunk.start < p.chunk.stop
                   for p in taken):  # fmt: skip
                raise DamagedPart(f, "its runs overlap another part's")
        except DamagedPart as exc:
            if on_damaged is None:
                raise
            on_damaged(exc)
            continue
        found.setdefault(part.chunk.cell, []).append(part)
    for parts in found.values():
        parts.sort(key=lambda p: p.chunk.start)
    return found


def _check_against(part: ChunkResult, path: Path, cells: dict[str, Cell], grid: Grid) -> None:
    cell = cells.get(part.chunk.cell)
    if cell is None:
        raise DamagedPart(path, "its cell is not in this folder's manifest")
    if part.chunk.stop > grid.runs:
        raise DamagedPart(path, f"its runs end at {part.chunk.stop}, the sweep has {grid.runs}")
    if part.agg is None and int(part.t[-1]) != int(cell.horizon):
        raise DamagedPart(path, f"its last checkpoint is {int(part.t[-1])}, the horizon is "
                                f"{cell.horizon}")  # fmt: skip
    M = part.regret_by_source.shape[2] if part.regret_by_source is not None else 1
    if M != cell.sources:
        raise DamagedPart(path, f"it holds runs of {M} source(s), the cell {cell.sources}")
    if part.pulls_sum.shape[1] != cell.instance.K:
        raise DamagedPart(path, f"it has {part.pulls_sum.shape[1]} arms, the instance "
                                f"{cell.instance.K}")  # fmt: skip


def covered(parts: Sequence[ChunkResult]) -> list[tuple[int, int]]:
    return [(p.chunk.start, p.chunk.stop) for p in parts]


@dataclass
class CellRuns:
    """All runs of a cell (its chunks joined in run order)."""

    cell: Cell
    label: str
    t: np.ndarray
    regret: np.ndarray
    estimator: np.ndarray
    best_pulls: np.ndarray
    pulls_sum: np.ndarray
    wall_s: float
    agg: DeviceAggregates | None = None
    regret_by_source: np.ndarray | None = None  # (R, S, M): several sources only
    collisions: np.ndarray | None = None  # (R, S)

    @classmethod
    def join(cls, cell: Cell, label: str, parts: Sequence[ChunkResult], runs: int) -> CellRuns:
        parts = [p for p in parts if p.chunk.start < runs]
        starts = [p.chunk.start for p in parts]
        stops = [p.chunk.stop for p in parts]
        if not parts or starts[0] != 0 or stops[-1] < runs or any(
            a != b for a, b in zip(stops[:-1], starts[1:], strict=False)
        ):
            raise ConfigError(f"cell {label}: runs 0..{runs - 1} are not all done")
        agg = None
        if parts[0].agg is not None:
            if any(p.agg is None for p in parts) or stops[-1] != runs:
                raise ConfigError(f"cell {label}: its parts mix backends or run counts; "
                                  "start the sweep over with --force")  # fmt: skip
            agg = parts[0].agg
            for p in parts[1:]:
                assert p.agg is not None
                agg = agg.merge(p.agg)
        return cls(
            cell=cell, label=label, t=parts[0].t,
            regret=np.concatenate([p.regret for p in parts])[:runs],
            estimator=np.concatenate([p.estimator for p in parts])[:runs],
            best_pulls=np.concatenate([p.best_pulls for p in parts])[:runs],
            pulls_sum=np.sum([p.pulls_sum for p in parts], axis=0),
            wall_s=float(sum(p.wall_s for p in parts)), agg=agg,
            regret_by_source=_joined(parts, "regret_by_source", runs),
            collisions=_joined(parts, "collisions", runs),
        )  # fmt: skip

    @property
    def checkpoints(self) -> np.ndarray:
        """Every checkpoint slot of the cell's curves (``t`` holds only T for a device's runs)."""
        return self.agg.t if self.agg is not None else self.t

    def points(self) -> list[Any]:
        """The sweep log's points: mean and 95% CI over runs at each checkpoint."""
        from corraoi.stats import sweep_points

        if self.agg is not None:
            a = self.agg
            t, n, pulls, regret, estimator = a.t, a.regret.n, a.pulls_sum, a.regret, a.estimator
        else:
            t, n, pulls = self.t, self.regret.shape[0], self.pulls_sum
            regret, estimator = Moments.of(self.regret), Moments.of(self.estimator)
        # a source-slot per source and slot: the shares of M sources sum to 1 too
        share = pulls / (n * self.cell.sources * t.astype(np.float64))[:, None]
        hits = Moments.of(self.collisions.astype(np.float64)) if (
            self.collisions is not None and self.agg is None) else None  # fmt: skip
        return sweep_points(self.label, t, regret, estimator, share, hits)

    def paired_curve(self, base: CellRuns) -> dict[str, list[Any]] | None:
        """Mean and 95% CI of regret(this) - regret(base), run by run, at each checkpoint:
        from the runs' values, or from the moments a device computed against ``base``."""
        if self.agg is not None:
            if self.agg.paired is None or self.agg.baseline != base.cell.policy.name:
                return None
            t, m = self.agg.t, self.agg.paired
        else:
            if base.regret.shape != self.regret.shape:
                return None
            t, m = self.t, Moments.of(self.regret - base.regret)
        h = m.ci95()
        return {"t": [int(v) for v in t], "mean": [float(v) for v in m.mean],
                "ci95": [float(v) if np.isfinite(v) else None for v in h]}  # fmt: skip

    def result(self, best_arm: int) -> Any:
        from .montecarlo import PolicyResult

        n = self.regret.shape[0]
        return PolicyResult(
            policy=self.cell.policy, regret=self.regret[:, -1], estimator=self.estimator[:, -1],
            pulls=None, best_arm=best_arm, wall_s=self.wall_s, label=self.label,
            best_pulls=self.best_pulls[:, -1] / self.cell.sources,
            pulls_mean=self.pulls_sum[-1] / n, horizon=int(self.t[-1]),
            regret_by_source=(self.regret_by_source[:, -1] if self.regret_by_source is not None
                              else None),
            collisions=self.collisions[:, -1] if self.collisions is not None else None,
        )  # fmt: skip


def _joined(parts: Sequence[ChunkResult], name: str, runs: int) -> np.ndarray | None:
    """The parts' ``name`` arrays (per-source values) joined in run order, or None."""
    arrays = [getattr(p, name) for p in parts]
    if any(a is None for a in arrays):
        return None
    return np.concatenate(arrays)[:runs]
