"""Experiments as library functions: sweeps of grids (in this process or on Dask) into a
resumable folder, and the paper's reproduction. The CLI commands call these.

A sweep folder holds (docs/scaling.md, docs/log-format.md; its manifest and parts are read
and written by :mod:`corraoi.experiments.folder`):

* ``manifest.json``: the grid (cells, runs, seeds, chunking) and its status;
* ``parts/<cell>-<first run>-<end run>.npz``: one part per finished chunk of runs, written
  atomically as the chunk finishes (what ``--resume`` and appends build on);
* ``results.parquet/instance=<name>/part-0.parquet``: the per-run results, compacted from the
  parts when every chunk is done (the ``analysis`` extra);
* per (instance, horizon) group -- in the folder itself when the grid has one group, else in
  a sub-folder named after the instance (and ``-T<horizon>`` with several horizons): the
  sweep log ``sweep.mcap``, ``sweep.rrd``, ``summary.json``, ``summary.md``, ``figure.png``,
  all written from the parts after all cells finish, so their order and bytes do not depend
  on which worker finished first.

Run i of a cell uses seed ``seed + i``: the numbers do not depend on the scheduler, the number
of workers, the chunking of the runs, or on the order chunks finish in.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from corraoi.errors import ConfigError, DamagedPart, WriteError

from . import backends
from .folder import (
    CLI_WORDS,
    GROUP_FILES,
    MANIFEST,
    PARTS,
    CellRuns,
    ChunkResult,
    Words,
    covered,
    group_dirs,
    merge_grids,
    read_manifest,
    read_parts,
    write_manifest,
    write_text,
)
from .grid import Cell, Chunk, Grid
from .kept_code import check_code, keep_sources, kept_copy, read_manifest_dict
from .summary import group_summary, summary_markdown


def reproduce(
    out: str | os.PathLike[str],
    *,
    runs: int = 200,
    horizon: int = 10_000,
    seed: int = 0,
    force: bool = False,
    workers: int | None = None,
    on_slots: Callable[[int], None] | None = None,
    warn: Callable[[str], None] | None = None,
    backend: str = "cpu",
) -> SweepOutcome:
    """The paper's simulations: I1 and I2, the twelve policies, into ``out`` (a grid sweep
    with one folder per instance; ``corraoi reproduce`` adds ``out/summary.md``);
    ``backend`` as for :func:`sweep`."""
    grid = paper_grid(runs=runs, horizon=horizon, seed=seed, backend=backend)
    return sweep(grid, out=out, force=force, workers=workers, on_slots=on_slots, warn=warn)


def paper_grid(
    *, runs: int = 200, horizon: int = 10_000, seed: int = 0, backend: str = "cpu"
) -> Grid:
    """The grid of the paper's simulations (I1 and I2, the twelve policies)."""
    from .grid import build_grid

    return build_grid(instances=list(PAPER_INSTANCES), policies=["all"], horizons=[horizon],
                      runs=runs, seed=seed, backend=backend)  # fmt: skip


#: The paper's simulation settings (section "Simulations"; 200 runs as its published code).
PAPER_INSTANCES = ("I1", "I2")

#: ``corraoi reproduce decentralized``: our experiment after Prasad, Jain and Moharir,
#: "Decentralized Age-of-Information Bandits" (arXiv 2009.12961), whose body could not be
#: read (docs/decentralized.md): the seed paper's I1 (K = 4), M = 1..4 sources, the
#: decentralized rules (rhoRand, MCTopM) and the centralized baseline over UCB, CUCB, TS and
#: CTS, T = 10,000.
DECENTRALIZED_INSTANCE = "I1"
DECENTRALIZED_RULES = ("rhorand", "mctopm", "centralized")
DECENTRALIZED_BASES = ("ucb", "cucb", "ts", "cts")
DECENTRALIZED_SOURCES = (1, 2, 3, 4)
DECENTRALIZED_RUNS = 50


def decentralized_grid(*, runs: int = DECENTRALIZED_RUNS, horizon: int = 10_000,
                       seed: int = 0, backend: str = "cpu") -> Grid:  # fmt: skip
    """The grid of ``corraoi reproduce decentralized`` (:data:`DECENTRALIZED_INSTANCE`, the
    rules x bases, M in :data:`DECENTRALIZED_SOURCES`; one group: one folder)."""
    from .grid import build_grid

    policies = [f"{r}-{b}" for r in DECENTRALIZED_RULES for b in DECENTRALIZED_BASES]
    return build_grid(instances=[DECENTRALIZED_INSTANCE], policies=policies,
                      horizons=[horizon], runs=runs, seed=seed, backend=backend,
                      sources=list(DECENTRALIZED_SOURCES))  # fmt: skip


def regret_by_sources(summary: dict[str, Any], grid: Grid) -> dict[str, dict[int, Any]]:
    """Per policy, the number of sources -> (mean regret at T, its 95% half-width), from a
    group's ``summary`` (its labels are ``grid``'s): what the figure of regret against M
    draws."""
    labels = grid.labels()
    out: dict[str, dict[int, Any]] = {}
    for cell in grid.cells:
        entry = summary["policies"][labels[cell.key]]
        out.setdefault(cell.policy.name, {})[cell.sources] = (entry["regret_mean"],
                                                              entry["regret_ci95"])  # fmt: skip
    return out


# ---------------------------------------------------------------------------- the folder


# ---------------------------------------------------------------------------- the sweep


class SweepOutputs(Protocol):
    """What writes a finished sweep folder's files in the upper layers' formats: the folder's
    ``results.parquet`` from the parts, then each (instance, horizon) group's files, then
    ``finish``."""

    def write_results(self, folder: Path, grid: Grid, parts: dict[str, list[ChunkResult]],
                      labels: dict[str, str], *,
                      warn: Callable[[str], None] | None) -> None: ...  # fmt: skip

    def write_group(self, folder: Path, grid: Grid, cells: Sequence[CellRuns],
                    summary: dict[str, Any], *,
                    warn: Callable[[str], None] | None) -> None: ...  # fmt: skip

    def finish(self, *, warn: Callable[[str], None] | None) -> None:
        """Every file complete (outputs written meanwhile by other processes waited for),
        before the manifest says the folder is. A WriteError here is an output that could
        not be made (a figure): the sweep marks the folder complete, then raises it."""


@dataclass
class SweepOutcome:
    grid: Grid
    summaries: list[dict[str, Any]]
    folders: list[Path]
    chunks_run: int
    chunks_skipped: int


def sweep(
    grid: Grid,
    *,
    out: str | os.PathLike[str] | None = None,
    client: Any = None,
    resume: bool = False,
    force: bool = False,
    workers: int | None = None,
    threads_per_worker: int | None = None,
    on_chunk: Callable[[int, int], None] | None = None,
    on_slots: Callable[[int], None] | None = None,
    warn: Callable[[str], None] | None = None,
    backend: str | None = None,
    outputs: SweepOutputs | None = None,
    words: Words = CLI_WORDS,
) -> SweepOutcome:
    """Run ``grid``; with ``out``, into a resumable folder (module docstring).

    ``outputs`` writes the folder's files beyond its parts, manifest and summaries
    (:class:`SweepOutputs`: the sweep logs, recordings, ``results.parquet`` and figures are
    ``corraoi.face.outputs.FolderOutputs``, which ``corraoi.sweep`` and ``corraoi sweep``
    hand in); without, the folder holds the parts, the manifest and the summaries.

    ``backend``: "cpu", "gpu" or "auto" (docs/gpu.md), else the grid's own (``cpu`` unless
    set). "gpu" runs every cell on the GPU (:class:`corraoi.gpu.GpuUnavailable` says why
    when it cannot); "auto" takes the GPU when it can run every cell, else the CPU with a
    notice through ``warn``.

    ``client``: a ``dask.distributed.Client`` (chunks run on its workers), else this
    process (the engine's own threads, ``workers`` of them). ``resume``: continue or extend
    the sweep in ``out`` (finished chunks are skipped; new runs, policies or parameter
    values are appended). ``on_chunk(done, total)`` after each chunk; ``on_slots(n)`` as the
    in-process engine advances. Returns the summaries, one per (instance, horizon) group.
    A folder is locked while the sweep writes it: a second sweep into it is refused at once.
    A complete folder that holds ``grid`` already (:func:`saved_outcome`) is read, not run.
    ``words``: how refusals name the options (the command line's, or Python's).
    """
    from contextlib import ExitStack

    grid = backends.settle(grid, backend, client=client, warn=warn)
    folder = Path(out) if out is not None else None
    if folder is not None and not force:
        saved = saved_outcome(folder, grid, resume=resume, words=words)
        if saved is not None:
            return saved
    with ExitStack() as stack:
        if folder is not None:
            from corraoi.files.locks import folder_lock

            _check_parent(folder)
            folder.mkdir(parents=True, exist_ok=True)
            stack.enter_context(folder_lock(folder, "sweep folder"))
        return _sweep(grid, folder, client=client, resume=resume, force=force, workers=workers,
                      threads_per_worker=threads_per_worker, on_chunk=on_chunk,
                      on_slots=on_slots, warn=warn, outputs=outputs, words=words)  # fmt: skip


def saved_outcome(folder: Path, grid: Grid, *, resume: bool = False,
                  words: Words = CLI_WORDS) -> SweepOutcome | None:  # fmt: skip
    """The outcome of the complete sweep folder ``folder`` when it holds ``grid`` already,
    read from its files (nothing runs): the same cells with the same code (each plug-in's
    sha256), runs, seed, checkpoints, baseline and backend, made by this corraoi's engine
    sources. With ``resume``, a folder whose grid takes in ``grid`` (nothing to add) too; a
    plug-in whose code changed is refused then (:class:`~corraoi.errors.CodeChanged`).
    None otherwise: the sweep runs (or is refused) as ever."""
    from corraoi.provenance import versions

    if not (folder / MANIFEST).is_file():
        return None
    data = read_manifest_dict(folder)
    try:
        old = read_manifest(folder)
    except ConfigError:
        return None
    prov = data.get("provenance")
    made_by = prov.get("versions", {}) if isinstance(prov, dict) else {}
    if old is None or data.get("status") != "complete" or not isinstance(made_by, dict) or (
        made_by.get("kernel_sources") != versions()["kernel_sources"]
    ):
        return None
    asked = Grid(grid.cells, runs=grid.runs, seed=grid.seed, chunk=grid.chunk or old.chunk,
                 checkpoints=grid.checkpoints, baseline=grid.baseline,
                 backend=grid.backend)  # fmt: skip
    if resume:
        check_code([c.policy for c in old.cells], folder, data, words=words)
        try:
            asked = merge_grids(old, asked, folder, words)
        except ConfigError:
            return None
    if asked.to_dict() != old.to_dict():
        return None
    dirs = group_dirs(old, folder)
    if not _intact(folder, old, dirs.values()):
        return None
    summaries = []
    for key in old.groups():
        try:
            summary = json.loads((dirs[key] / "summary.json").read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError):
            return None
        if not isinstance(summary, dict):
            return None
        summaries.append(summary)
    chunks = sum(len(old.chunks(c)) for c in old.cells)
    return SweepOutcome(old, summaries, [dirs[k] for k in old.groups()], 0, chunks)


def _intact(folder: Path, grid: Grid, groups: Iterable[Path]) -> bool:
    """Whether a complete folder still holds every file it wrote (by name and kind, none
    read): each group's files, ``results.parquet``, a part for every run of every cell, and
    nothing half-written (``.partial``). Otherwise a sweep into it writes what is missing."""
    if any(folder.rglob("*.partial")) or not (folder / "results.parquet").is_dir():
        return False
    for d in groups:
        for name in GROUP_FILES:
            path = d / name
            if path.is_symlink() or not path.is_file():
                return False
    made: dict[str, list[tuple[int, int]]] = {}
    for f in (folder / PARTS).glob("*.npz"):
        key, _, rest = f.stem.partition("-")
        start, _, stop = rest.partition("-")
        if start.isdigit() and stop.isdigit() and f.is_file() and not f.is_symlink():
            made.setdefault(key, []).append((int(start), int(stop)))
    return all(not grid.chunks(c, covered=made.get(c.key, [])) for c in grid.cells)


def _sweep(
    grid: Grid,
    folder: Path | None,
    *,
    client: Any,
    resume: bool,
    force: bool,
    workers: int | None,
    threads_per_worker: int | None,
    on_chunk: Callable[[int, int], None] | None,
    on_slots: Callable[[int], None] | None,
    warn: Callable[[str], None] | None,
    outputs: SweepOutputs | None,
    words: Words = CLI_WORDS,
) -> SweepOutcome:
    start = time.perf_counter()
    runner = backends.choose(grid, client=client, workers=workers,
                             threads_per_worker=threads_per_worker)  # fmt: skip
    parts: dict[str, list[ChunkResult]] = {}
    if folder is not None:
        grid = _prepare_folder(folder, grid, resume=resume, force=force, words=words)

        def damaged(exc: DamagedPart) -> None:
            aside = exc.path.with_name(exc.path.name + ".damaged")
            os.replace(exc.path, aside)  # kept for a look, never read again
            if warn is not None:
                warn(f"{exc}; its runs are run again (the file is now {aside.name})")

        parts = read_parts(folder, grid, on_damaged=damaged)
    todo: list[tuple[Cell, Chunk]] = []
    skipped = 0
    for cell in grid.cells:
        done = parts.get(cell.key, [])
        skipped += len(done)
        todo += [(cell, chunk) for chunk in grid.chunks(cell, covered=covered(done))]
    total = len(todo)
    finished = 0

    def on_done(result: ChunkResult) -> None:
        nonlocal finished
        if folder is not None:
            result.save(folder / PARTS / f"{result.chunk.name}.npz")
        parts.setdefault(result.chunk.cell, []).append(result)
        finished += 1
        if on_chunk is not None:
            on_chunk(finished, total)

    runner.run(grid, todo, on_done=on_done, on_slots=on_slots)
    for p in parts.values():
        p.sort(key=lambda r: r.chunk.start)
    labels = grid.labels()
    dirs = group_dirs(grid, folder) if folder is not None else {}
    summaries: list[dict[str, Any]] = []
    wall = time.perf_counter() - start
    joined_groups = []
    for key, cells in grid.groups().items():
        joined = [CellRuns.join(c, labels[c.key], parts.get(c.key, []), grid.runs) for c in cells]
        joined_groups.append((key, joined))
        summaries.append(group_summary(grid, joined, workers=runner.workers, wall_s=wall))
    if folder is not None:
        if outputs is not None:
            outputs.write_results(folder, grid, parts, labels, warn=warn)
        for (key, joined), summary in zip(joined_groups, summaries, strict=True):
            dirs[key].mkdir(parents=True, exist_ok=True)
            if outputs is not None:
                outputs.write_group(dirs[key], grid, joined, summary, warn=warn)
            write_text(dirs[key] / "summary.json", json.dumps(summary, indent=2) + "\n")
            write_text(dirs[key] / "summary.md", summary_markdown(summary))
        unfinished: WriteError | None = None
        if outputs is not None:
            try:
                outputs.finish(warn=warn)
            except WriteError as exc:  # a figure not drawn: the results are complete
                unfinished = exc
        prov = folder_provenance(grid)
        keep_sources(folder, prov)
        write_manifest(folder, grid, "complete", provenance_entry(folder, prov))
        if unfinished is not None:
            raise unfinished
    return SweepOutcome(grid, summaries, [dirs[k] for k, _ in joined_groups] if dirs else [],
                        total, skipped)  # fmt: skip


def _check_parent(folder: Path) -> None:
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder}: exists and is not a directory (expected a folder for -o)")
    probe = folder
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise ConfigError(f"{folder}: cannot create the folder ({probe} is not a directory)")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise ConfigError(f"{folder}: cannot create the folder ({probe} is not writable)")


def _prepare_folder(folder: Path, grid: Grid, *, resume: bool, force: bool,
                    words: Words = CLI_WORDS) -> Grid:  # fmt: skip
    old = read_manifest(folder) if folder.is_dir() else None
    legacy = folder.is_dir() and old is None and any(
        (folder / f).exists() for f in (*GROUP_FILES, "results.parquet")
    )
    if resume:
        if old is None:
            raise ConfigError(f"{folder}: no sweep to resume (no {MANIFEST}); drop "
                              f"{words.resume}")  # fmt: skip
        # the code that will run is the code the sweep ran, or one line says which is not
        manifest = read_manifest_dict(folder)
        check_code([c.policy for c in old.cells], folder, manifest, words=words)
        _check_engine(folder, manifest, words)
        grid = merge_grids(old, grid, folder, words)
    elif old is not None or legacy:
        if not force:
            raise ConfigError(
                f"{folder}: already holds a sweep; use {words.resume} to continue or extend it, "
                f"or {words.force} to start over"
            )
        _clear(folder, old)
    folder.mkdir(parents=True, exist_ok=True)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"{folder}: directory is not writable")
    prov = folder_provenance(grid)  # plug-ins loaded, versions asked: before any file
    write_manifest(folder, grid, "running", provenance_entry(folder, prov))  # first: resumable
    keep_sources(folder, prov)
    (folder / PARTS).mkdir(exist_ok=True)
    from corraoi.files.locks import lock_holder

    for stale in (folder / PARTS).glob("*.partial"):  # parts a killed sweep left half-written
        if stale.is_file() and lock_holder(stale) is None:
            stale.unlink(missing_ok=True)
    return grid


def _check_engine(folder: Path, manifest: dict[str, Any], words: Words) -> None:
    """A sweep made by other engine sources (an older corraoi) is not continued: its runs
    and the new ones would come from different code. A folder from before the hash was
    recorded is continued as ever."""
    from corraoi.provenance import short, versions

    prov = manifest.get("provenance")
    made_by = prov.get("versions") if isinstance(prov, dict) else None
    then = made_by.get("kernel_sources") if isinstance(made_by, dict) else None
    now = versions()["kernel_sources"]
    if isinstance(then, str) and then != now:
        raise ConfigError(f"{folder}: its runs were made by other engine sources ({short(then)}, "
                          f"this corraoi's are {short(now)}: another corraoi); new runs would "
                          f"not be comparable: drop {words.resume} and use {words.force} to "
                          "start the sweep over")  # fmt: skip


def folder_provenance(grid: Grid) -> Any:
    """What made a sweep's numbers: the versions, the backend and each plug-in's source."""
    from corraoi.provenance import Provenance

    from .backends import sweep_backend

    return Provenance.of([c.policy for c in grid.cells], backend=sweep_backend(grid.backend))


def provenance_entry(folder: Path, prov: Any) -> dict[str, Any]:
    """The manifest's ``provenance``: :func:`folder_provenance` with where the folder keeps
    the copy of each plug-in's source (corraoi.experiments.kept_code)."""
    return {**prov.to_dict(), "plugins": [{**s.to_dict(), "copy": kept_copy(s)}
                                          for s in prov.sources]}  # fmt: skip


def _clear(folder: Path, old: Grid | None) -> None:
    """Remove an earlier sweep's files (only with --force); a file another process is
    writing right now is never touched (nothing is removed then)."""
    from corraoi.errors import OutputError
    from corraoi.files.locks import lock_holder

    for f in sorted(folder.rglob("*")):
        holder = lock_holder(f) if f.is_file() else None
        if holder is not None:
            who = f"process {holder}" if holder else "another process"
            raise OutputError(
                f"{f}: is being written by {who} right now; not touched (wait for it, stop it, "
                "or give another output folder)"
            )
    targets = [folder / PARTS, folder / "results.parquet", folder / "results.parquet.partial",
               folder / MANIFEST]  # fmt: skip
    targets += [folder / f for name in GROUP_FILES for f in (name, f"{name}.partial")]
    if old is not None:  # the group folders of a grid of several groups
        targets += [d for d in group_dirs(old, folder).values() if d != folder]
    for t in targets:
        if t.is_dir():
            shutil.rmtree(t)
        else:
            t.unlink(missing_ok=True)
