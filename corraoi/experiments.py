"""Experiments as library functions: sweeps of grids (in this process or on Dask) into a
resumable folder, and the paper's reproduction. The CLI commands call these.

A sweep folder holds (docs/scaling.md, docs/log-format.md; its manifest and parts are read
and written by :mod:`corraoi.sweep_folder`):

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
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import chunks
from .chunks import chunk_task, prepare_kernels
from .errors import ConfigError
from .grid import Chunk, Grid
from .sweep_folder import (
    GROUP_FILES,
    MANIFEST,
    PARTS,
    CellRuns,
    ChunkResult,
    DamagedPart,
    covered,
    group_dirs,
    merge_grids,
    read_manifest,
    read_parts,
    write_manifest,
)

#: Why a GPU sweep and a Dask client do not go together.
GPU_NOT_ON_CLUSTER = ("--backend gpu runs in this process, on its GPU; leave out --scheduler "
                      "(or use --backend cpu on the cluster)")  # fmt: skip


# ---------------------------------------------------------------------------- one run


@dataclass
class RecordOutcome:
    """What :func:`record_run` wrote: the log (final name, or ``.partial`` when the run
    stopped on an error), the Rerun recording if any, the slots, and a viewer's problem."""

    mcap: Path
    rrd: Path | None
    slots: int
    viewer_problem: str | None = None


def record_run(
    config: Any,
    mcap: str | os.PathLike[str],
    *,
    rrd: str | os.PathLike[str] | None = None,
    viewer_url: str | None = None,
    overwrite: bool = False,
    on_block: Callable[[Any], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    rerun: Any = None,
) -> RecordOutcome:
    """Simulate one run (a ``RunConfig``) and stream every slot to the MCAP log ``mcap`` and,
    with ``rrd`` or ``viewer_url``, to a Rerun recording (what ``corraoi record`` does for
    each policy). ``should_stop()`` is asked after every block: the files are then finished
    with the slots so far (status interrupted). A failed run (a plug-in's bad arm) leaves its
    log at the ``.partial`` name, marked failed, and raises. Ctrl-C finishes both files.
    ``rerun``, a :class:`recorder.rerun_worker.RerunWorker`, writes the Rerun recording in
    its process (the same file), else it is written in this one."""
    from recorder.errors import ViewerError, WriteError
    from recorder.mcap_sink import McapSink

    problem: str | None = None
    rrd_error: WriteError | None = None
    slots = 0
    rrd_path: Path | None = None
    with McapSink(mcap, config, overwrite=overwrite) as log:
        output: Any = None
        sink: Any = None  # in this process: the RerunSink in front of ``output``
        if rrd is not None or viewer_url is not None:
            where = None if rrd is None else Path(rrd)
            if rerun is not None:
                output = rerun.open(config, rrd_path=where, viewer_url=viewer_url,
                                    overwrite=overwrite)  # fmt: skip
            else:
                from recorder.rerun_sink import RerunSink, RrdOutput

                output = RrdOutput(config, rrd_path=where, viewer_url=viewer_url,
                                   overwrite=overwrite)  # fmt: skip
                sink = RerunSink(output.recording, config.label, config)
        try:
            for block in slots_of(config):
                log.write(block)
                if sink is not None:
                    sink.write(block)
                elif output is not None:
                    output.write(block)
                slots = int(block.t[-1])
                if on_block is not None:
                    on_block(block)
                if should_stop is not None and should_stop():
                    break
        except BaseException as exc:
            if output is not None:
                if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                    try:
                        if sink is not None:
                            sink.close()  # send the slots it still holds (up to a batch)
                        output.close()
                    except (ViewerError, WriteError):
                        pass
                else:
                    try:  # the run's own error is the one to report, not the abort's
                        output.abort(discard=slots == 0)
                    except (ViewerError, WriteError):
                        pass
            raise
        if output is not None:
            if sink is not None:
                sink.close()
            try:
                rrd_path = output.close()
            except ViewerError as exc:
                rrd_path = output.path
                problem = str(exc)
            except WriteError as exc:  # the MCAP log is still finished properly
                rrd_error = exc
    if rrd_error is not None:
        if log.finished:
            raise WriteError(f"{rrd_error} (the MCAP log {log.path} is complete)")
        raise rrd_error
    return RecordOutcome(log.path if log.finished else log.partial_path, rrd_path, slots, problem)


def slots_of(config: Any) -> Any:
    """The slot blocks of one run: the CPU engine's, or for a run of a GPU sweep
    (``config.streams``) the GPU kernel's own, captured slot by slot."""
    if config.streams == "cpu":
        from .engine import simulate_run

        return simulate_run(config.instance, config.policy, config.seed, config.horizon,
                            channel=config.channel)  # fmt: skip
    from .gpu.device import device_of
    from .gpu.runner import capture_run

    device = device_of("emulate" if config.streams == "gpu-emulated" else "cuda")
    return capture_run(config.instance, config.policy, seed=config.seed,
                       horizon=config.horizon, channel=config.channel, device=device)  # fmt: skip


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


# ---------------------------------------------------------------------------- the folder


# ---------------------------------------------------------------------------- executing


def _execute(
    tasks: list[tuple[Chunk, dict[str, Any]]],
    *,
    client: Any,
    on_done: Callable[[ChunkResult], None],
    on_slots: Callable[[int], None] | None,
) -> None:
    if client is None:
        for _, task in tasks:
            on_done(chunks.run_chunk(task, on_slots=on_slots))
        return
    from .cluster import run_on_cluster

    run_on_cluster(client, tasks, on_done=on_done)


# ---------------------------------------------------------------------------- summaries


def group_summary(
    grid: Grid, cells: Sequence[CellRuns], *, workers: int, wall_s: float
) -> dict[str, Any]:
    """The summary (``--json``, summary.json) of one (instance, horizon) group."""
    from .summary import sweep_summary
    from .theory import analyse

    inst, horizon = cells[0].cell.instance, cells[0].cell.horizon
    best = analyse(inst).best_arm
    results = [c.result(best) for c in cells]
    summary = sweep_summary(inst, results, runs=grid.runs, horizon=horizon, seed=grid.seed,
                            workers=workers)  # fmt: skip
    summary["wall_s"] = round(wall_s, 4)
    summary["notable"] = group_notable(grid, cells)
    if grid.backend != "cpu":
        summary["backend"] = grid.backend
    if grid.baseline is not None:
        from .paired import paired_against

        base = [c for c in cells if c.cell.policy.name == grid.baseline]
        if base:
            summary["baseline"] = base[0].label
            for name, entry in paired_against(results, base[0].label).items():
                summary["policies"][name].update(entry)
            for c in cells:
                curve = c.paired_curve(base[0]) if c is not base[0] else None
                if curve is not None:
                    summary["policies"][c.label]["paired_diff_curve"] = curve
    return summary


def group_notable(grid: Grid, cells: Sequence[CellRuns]) -> dict[str, Any]:
    """The group's notable runs (:mod:`corraoi.notable`) from the per-run finals."""
    from .notable import notable_runs

    base = [c.label for c in cells if c.cell.policy.name == grid.baseline]
    return notable_runs([c.label for c in cells], [c.regret[:, -1] for c in cells],
                        [c.cell.channel.to_dict() for c in cells], seed=grid.seed,
                        baseline=base[0] if base else None)  # fmt: skip


def group_config(grid: Grid, cells: Sequence[CellRuns]) -> dict[str, Any]:
    """The sweep log's configuration of a group (``sweep_config`` with cell labels)."""
    from recorder.style import spec_color, variant_colors

    from .sweep import sweep_config

    c0 = cells[0].cell
    config = sweep_config(c0.instance, [c.cell.policy for c in cells], runs=grid.runs,
                          horizon=c0.horizon, seed=grid.seed,
                          checkpoints=[int(t) for t in cells[0].checkpoints],
                          channel=c0.channel)  # fmt: skip
    # every view draws a policy in its own colour; the parameter values of one policy in
    # shades of it
    same: dict[str, list[CellRuns]] = {}
    for c in cells:
        same.setdefault(c.cell.policy.name, []).append(c)
    shade = {
        id(c): rgb
        for group in same.values()
        for c, rgb in zip(group, variant_colors(spec_color(group[0].cell.policy), len(group)),
                          strict=True)  # fmt: skip
    }
    for entry, c in zip(config["policies"], cells, strict=True):
        entry["name"] = c.label
        if c.cell.policy.color is not None or len(same[c.cell.policy.name]) > 1:
            entry["color"] = list(shade[id(c)])
    return config


# ---------------------------------------------------------------------------- the sweep


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
) -> SweepOutcome:
    """Run ``grid``; with ``out``, into a resumable folder (module docstring).

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
    """
    from contextlib import ExitStack
    from dataclasses import replace

    if backend is not None and backend != grid.backend:
        grid = replace(grid, backend=backend)
    if grid.backend != "cpu":
        from .gpu import choose_backend

        grid = choose_backend(grid, warn=warn)
        if grid.backend == "gpu" and client is not None:
            raise ConfigError(GPU_NOT_ON_CLUSTER)
    folder = Path(out) if out is not None else None
    with ExitStack() as stack:
        if folder is not None:
            from recorder.paths import folder_lock

            _check_parent(folder)
            folder.mkdir(parents=True, exist_ok=True)
            stack.enter_context(folder_lock(folder, "sweep folder"))
        return _sweep(grid, folder, client=client, resume=resume, force=force, workers=workers,
                      threads_per_worker=threads_per_worker, on_chunk=on_chunk,
                      on_slots=on_slots, warn=warn)  # fmt: skip


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
) -> SweepOutcome:
    from .engine import set_workers

    start = time.perf_counter()
    used = set_workers(workers) if client is None else int(threads_per_worker or 1)
    parts: dict[str, list[ChunkResult]] = {}
    if folder is not None:
        grid = _prepare_folder(folder, grid, resume=resume, force=force)

        def damaged(exc: DamagedPart) -> None:
            aside = exc.path.with_name(exc.path.name + ".damaged")
            os.replace(exc.path, aside)  # kept for a look, never read again
            if warn is not None:
                warn(f"{exc}; its runs are run again (the file is now {aside.name})")

        parts = read_parts(folder, grid, on_damaged=damaged)
    tasks: list[tuple[Chunk, dict[str, Any]]] = []
    skipped = 0
    threads = threads_per_worker if client is not None else None
    by_key = {cell.key: cell for cell in grid.cells}
    for cell in grid.cells:
        done = parts.get(cell.key, [])
        skipped += len(done)
        for chunk in grid.chunks(cell, covered=covered(done)):
            task = chunk_task(grid, cell, chunk, threads=threads) if grid.backend == "cpu" else {}
            tasks.append((chunk, task))
    total = len(tasks)
    finished = 0
    if grid.backend == "gpu":
        todo = [(by_key[ch.cell], ch) for ch, _ in tasks]

    def on_done(result: ChunkResult) -> None:
        nonlocal finished
        if folder is not None:
            result.save(folder / PARTS / f"{result.chunk.name}.npz")
        parts.setdefault(result.chunk.cell, []).append(result)
        finished += 1
        if on_chunk is not None:
            on_chunk(finished, total)

    if grid.backend == "gpu":
        from .gpu.runner import execute

        execute(grid, todo, on_done=on_done, on_slots=on_slots)
    else:
        if client is None and tasks:
            prepare_kernels([by_key[ch.cell] for ch, _ in tasks])
        _execute(tasks, client=client, on_done=on_done,
                 on_slots=on_slots if client is None else None)  # fmt: skip
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
        summaries.append(group_summary(grid, joined, workers=used, wall_s=wall))
    if folder is not None:
        _write_results(folder, grid, parts, labels, warn=warn)
        for (key, joined), summary in zip(joined_groups, summaries, strict=True):
            _write_group(dirs[key], grid, joined, summary, warn=warn)
        write_manifest(folder, grid, "complete")
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


def _prepare_folder(folder: Path, grid: Grid, *, resume: bool, force: bool) -> Grid:
    old = read_manifest(folder) if folder.is_dir() else None
    legacy = folder.is_dir() and old is None and any(
        (folder / f).exists() for f in (*GROUP_FILES, "results.parquet")
    )
    if resume:
        if old is None:
            raise ConfigError(f"{folder}: no sweep to resume (no {MANIFEST}); drop --resume")
        grid = merge_grids(old, grid, folder)
    elif old is not None or legacy:
        if not force:
            raise ConfigError(
                f"{folder}: already holds a sweep; use --resume to continue or extend it, "
                "or --force to start over"
            )
        _clear(folder, old)
    folder.mkdir(parents=True, exist_ok=True)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError(f"{folder}: directory is not writable")
    (folder / PARTS).mkdir(exist_ok=True)
    write_manifest(folder, grid, "running")
    return grid


def _clear(folder: Path, old: Grid | None) -> None:
    """Remove an earlier sweep's files (only with --force); a file another process is
    writing right now is never touched (nothing is removed then)."""
    from recorder.errors import OutputError
    from recorder.paths import lock_holder

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


def _write_results(
    folder: Path,
    grid: Grid,
    parts: dict[str, list[ChunkResult]],
    labels: dict[str, str],
    *,
    warn: Callable[[str], None] | None,
) -> None:
    """results.parquet, compacted from the parts: one partition per instance."""
    try:
        import pyarrow.parquet  # noqa: F401
    except ImportError:
        if warn is not None:
            warn('results.parquet not written: install the analysis extra, '
                 'pip install "corraoi[analysis]"')  # fmt: skip
        return
    from recorder.results import write_dataset

    write_dataset(folder / "results.parquet", grid, parts)


def _write_group(
    folder: Path,
    grid: Grid,
    cells: Sequence[CellRuns],
    summary: dict[str, Any],
    *,
    warn: Callable[[str], None] | None,
) -> None:
    from recorder.sweep_log import SweepMcapSink
    from recorder.sweep_rerun import open_sweep_recording

    from .summary import summary_markdown

    folder.mkdir(parents=True, exist_ok=True)
    config = group_config(grid, cells)
    config["notable"] = summary["notable"]  # read back by SweepLog.notable
    with (
        SweepMcapSink(folder / "sweep.mcap", config) as log,
        open_sweep_recording(folder / "sweep.rrd", config) as rec,
    ):
        for c in cells:
            for point in c.points():
                log.write(point)
                rec.write(point)
        for c in cells:  # the runs worth watching, over the mean (CPU: every checkpoint)
            if c.agg is not None or c.regret.shape[1] < 2:
                continue
            for kind, e in summary["notable"]["cells"].get(c.label, {}).items():
                rec.mark(c.label, kind, e["run"], e["seed"], c.t, c.regret[e["run"]])
    write_text(folder / "summary.json", json.dumps(summary, indent=2) + "\n")
    write_text(folder / "summary.md", summary_markdown(summary))
    from recorder.sweep_log import read_sweep
    from viewer.figure import FigureUnavailable, draw_figure

    try:
        draw_figure(read_sweep(folder / "sweep.mcap"), folder / "figure.png")
    except FigureUnavailable as exc:
        if warn is not None:
            warn(f"{folder / 'figure.png'} not written: {exc}")


def write_text(path: Path, text: str) -> None:
    """Write ``path`` atomically: ``.partial`` first, renamed when complete."""
    tmp = path.with_name(path.name + ".partial")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
