"""Experiments as library functions: sweeps of grids (in this process or on Dask) into a
resumable folder, and the paper's reproduction. The CLI commands call these.

A sweep folder holds (docs/scaling.md, docs/log-format.md):

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
import re
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._version import __version__
from .errors import ConfigError
from .grid import Cell, Chunk, Grid
from .instance import Instance
from .stats import Moments

MANIFEST = "manifest.json"
PARTS = "parts"
MANIFEST_FORMAT = "corraoi.sweep-folder"
MANIFEST_VERSION = 1
#: Why a GPU sweep and a Dask client do not go together.
GPU_NOT_ON_CLUSTER = ("--backend gpu runs in this process, on its GPU; leave out --scheduler "
                      "(or use --backend cpu on the cluster)")  # fmt: skip
#: What a group folder holds (written from the parts when the sweep finishes).
GROUP_FILES = ("sweep.mcap", "sweep.rrd", "summary.json", "summary.md", "figure.png")


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

    def save(self, path: Path) -> None:
        """Write atomically (``.partial`` then rename): a part exists only when complete."""
        tmp = path.with_name(path.name + ".partial")
        extra = self.agg.arrays() if self.agg is not None else {}
        with open(tmp, "wb") as f:
            np.savez(
                f, cell=np.array(self.chunk.cell), start=self.chunk.start, stop=self.chunk.stop,
                t=self.t, regret=self.regret, estimator=self.estimator,
                best_pulls=self.best_pulls, pulls_sum=self.pulls_sum, wall_s=self.wall_s,
                **extra,
            )  # fmt: skip
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: Path) -> ChunkResult:
        try:
            with np.load(path) as z:
                return cls(
                    chunk=Chunk(str(z["cell"]), int(z["start"]), int(z["stop"])),
                    t=z["t"], regret=z["regret"], estimator=z["estimator"],
                    best_pulls=z["best_pulls"], pulls_sum=z["pulls_sum"],
                    wall_s=float(z["wall_s"]), agg=DeviceAggregates.from_arrays(z),
                )  # fmt: skip
        except (OSError, ValueError, KeyError) as exc:
            raise ConfigError(
                f"{path}: a damaged part file ({exc}); delete it and --resume"
            ) from None

    @classmethod
    def from_device(cls, chunk: Chunk, run: Any, baseline: str | None) -> ChunkResult:
        """The part of a chunk run on a device (:class:`corraoi.gpu.runner.DeviceRun`)."""
        agg = DeviceAggregates(run.t, run.regret, run.estimator, run.pulls_sum, run.paired,
                               baseline if run.paired is not None else None)  # fmt: skip
        return cls(chunk=chunk, t=run.t[-1:], regret=run.regret_final[:, None],
                   estimator=run.estimator_final[:, None],
                   best_pulls=run.best_pulls_final[:, None], pulls_sum=run.pulls_sum[-1:],
                   wall_s=run.wall_s, agg=agg)  # fmt: skip


def checkpoints_of(grid: Grid, horizon: int) -> list[int]:
    from .sweep import default_checkpoints

    return [c for c in default_checkpoints(horizon, grid.checkpoints) if 0 < c <= horizon]


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
) -> RecordOutcome:
    """Simulate one run (a ``RunConfig``) and stream every slot to the MCAP log ``mcap`` and,
    with ``rrd`` or ``viewer_url``, to a Rerun recording (what ``corraoi record`` does for
    each policy). ``should_stop()`` is asked after every block: the files are then finished
    with the slots so far (status interrupted). A failed run (a plug-in's bad arm) leaves its
    log at the ``.partial`` name, marked failed, and raises. Ctrl-C finishes both files."""
    from recorder.errors import ViewerError, WriteError
    from recorder.mcap_sink import McapSink

    from .engine import simulate_run

    problem: str | None = None
    rrd_error: WriteError | None = None
    slots = 0
    rrd_path: Path | None = None
    with McapSink(mcap, config, overwrite=overwrite) as log:
        output = sink = None
        if rrd is not None or viewer_url is not None:
            from recorder.rerun_sink import RerunSink, RrdOutput

            output = RrdOutput(config, rrd_path=None if rrd is None else Path(rrd),
                               viewer_url=viewer_url, overwrite=overwrite)  # fmt: skip
            sink = RerunSink(output.recording, config.label, config)
        try:
            for block in simulate_run(config.instance, config.policy, config.seed,
                                      config.horizon, channel=config.channel):  # fmt: skip
                log.write(block)
                if sink is not None:
                    sink.write(block)
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
                    output.abort(discard=slots == 0)
            raise
        if output is not None:
            assert sink is not None
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


# ---------------------------------------------------------------------------- one chunk


def chunk_task(
    grid: Grid, cell: Cell, chunk: Chunk, *, threads: int | None = None
) -> dict[str, Any]:
    """Everything a worker needs to run ``chunk``, as plain data: the cell (instance, policy,
    channel with its trace), the seeds, the checkpoints, and a file plug-in's source."""
    task: dict[str, Any] = {
        "version": __version__,
        "cell": cell.to_dict(),
        "key": cell.key,
        "start": chunk.start,
        "stop": chunk.stop,
        "seed": grid.seed,
        "checkpoints": checkpoints_of(grid, cell.horizon),
        "threads": threads,
    }
    if cell.channel.kind == "trace" and cell.channel.trace is not None:
        task["trace"] = [int(v) for v in cell.channel.trace]
    qual = cell.policy.qualname
    if qual.startswith("file:"):
        path = qual[len("file:") :].rpartition(":")[0]
        task["plugin_source"] = {"path": path, "source": Path(path).read_text(encoding="utf-8")}
    return task


def run_chunk(task: dict[str, Any], on_slots: Callable[[int], None] | None = None) -> ChunkResult:
    """Run one chunk from its :func:`chunk_task` data (in this process or on a worker)."""
    from .block import RunConfig
    from .channels import Channel
    from .engine import set_workers
    from .sweep import run_policy
    from .theory import analyse

    if task.get("version") != __version__:
        raise ConfigError(
            f"this worker runs corraoi {__version__}, the client {task.get('version')}: "
            "install the same version on both"
        )
    if task.get("plugin_source"):
        from .policies.registry import install_plugin_source

        install_plugin_source(task["plugin_source"]["path"], task["plugin_source"]["source"])
    if task.get("threads"):
        set_workers(int(task["threads"]))
    cfg = RunConfig.from_dict({**task["cell"], "seed": 0})
    channel = cfg.channel
    if "trace" in task and channel is not None:
        states = np.asarray(task["trace"], dtype=np.int64)
        channel = Channel("trace", source=channel.source, trace=states, digest=channel.digest)
    inst: Instance = cfg.instance
    best = analyse(inst).best_arm
    stops = [int(c) for c in task["checkpoints"]]
    S, K = len(stops), inst.K
    n = int(task["stop"]) - int(task["start"])
    regret = np.empty((n, S))
    estimator = np.empty((n, S))
    best_pulls = np.empty((n, S), dtype=np.int64)
    pulls_sum = np.empty((S, K), dtype=np.int64)
    index = {t: i for i, t in enumerate(stops)}

    def keep(policy: Any, snap: Any) -> None:
        i = index[snap.t]
        regret[:, i] = snap.regret
        estimator[:, i] = snap.estimator
        best_pulls[:, i] = snap.pulls[:, best]
        pulls_sum[i] = snap.pulls.sum(axis=0)

    start = time.perf_counter()
    seed0 = int(task["seed"]) + int(task["start"])
    run_policy(inst, cfg.policy, seeds=range(seed0, seed0 + n), horizon=cfg.horizon,
               checkpoints=stops, on_checkpoint=keep, on_slots=on_slots,
               channel=channel)  # fmt: skip
    return ChunkResult(
        chunk=Chunk(str(task["key"]), int(task["start"]), int(task["stop"])),
        t=np.asarray(stops, dtype=np.int64), regret=regret, estimator=estimator,
        best_pulls=best_pulls, pulls_sum=pulls_sum, wall_s=time.perf_counter() - start,
    )  # fmt: skip


# ---------------------------------------------------------------------------- the folder


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
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: unreadable manifest ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
        raise ConfigError(f"{path}: not a corraoi sweep manifest")
    if int(data.get("format_version", 0)) > MANIFEST_VERSION:
        raise ConfigError(f"{path}: manifest version {data['format_version']}: upgrade corraoi")
    return Grid.from_dict(data.get("grid", {}), where=str(path))


def write_manifest(out: Path, grid: Grid, status: str) -> None:
    data = {
        "format": MANIFEST_FORMAT,
        "format_version": MANIFEST_VERSION,
        "corraoi_version": __version__,
        "status": status,
        "grid": grid.to_dict(),
        "groups": {str(p.relative_to(out)) or ".": {"instance": name, "horizon": h}
                   for (name, h), p in group_dirs(grid, out).items()},  # fmt: skip
    }
    tmp = out / (MANIFEST + ".partial")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, out / MANIFEST)


def merge_grids(old: Grid, new: Grid, where: Path) -> Grid:
    """The grid of an existing folder extended by ``new`` (more runs, cells): an append."""
    if old.seed != new.seed:
        raise ConfigError(
            f"{where}: holds a sweep with seed {old.seed}; --resume needs the same seed "
            f"(got {new.seed})"
        )
    if old.chunk != new.chunk and new.chunk:
        raise ConfigError(
            f"{where}: holds a sweep in chunks of {old.chunk or old.runs} runs; --resume keeps "
            f"them (got --chunk {new.chunk})"
        )
    if old.checkpoints != new.checkpoints:
        raise ConfigError(
            f"{where}: holds a sweep with {old.checkpoints} checkpoints; --resume keeps them"
        )
    if old.backend != new.backend:  # other random streams: the runs would not pair
        raise ConfigError(
            f"{where}: holds a sweep run with --backend {old.backend}; --resume it with "
            f"--backend {old.backend} (got {new.backend})"
        )
    cells = list(old.cells)
    keys = {c.key for c in cells}
    cells += [c for c in new.cells if c.key not in keys]
    return Grid(tuple(cells), runs=max(old.runs, new.runs), seed=old.seed, chunk=old.chunk,
                checkpoints=old.checkpoints, baseline=new.baseline or old.baseline,
                backend=old.backend)  # fmt: skip


def _parts(out: Path) -> dict[str, list[ChunkResult]]:
    """The finished chunks of a folder by cell key (each run range once, sorted)."""
    found: dict[str, list[ChunkResult]] = {}
    folder = out / PARTS
    if not folder.is_dir():
        return found
    for f in sorted(folder.glob("*.npz")):
        part = ChunkResult.load(f)
        found.setdefault(part.chunk.cell, []).append(part)
    for parts in found.values():
        parts.sort(key=lambda p: p.chunk.start)
    return found


def _covered(parts: Sequence[ChunkResult]) -> list[tuple[int, int]]:
    return [(p.chunk.start, p.chunk.stop) for p in parts]


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
            on_done(run_chunk(task, on_slots=on_slots))
        return
    from .cluster import run_on_cluster

    run_on_cluster(client, tasks, on_done=on_done)


# ---------------------------------------------------------------------------- summaries


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
        )  # fmt: skip

    def points(self) -> list[Any]:
        """The sweep log's points: mean and 95% CI over runs at each checkpoint."""
        from .sweep import sweep_points

        if self.agg is not None:
            a = self.agg
            share = a.pulls_sum / (a.regret.n * a.t.astype(np.float64))[:, None]
            return sweep_points(self.label, a.t, a.regret, a.estimator, share)
        n = self.regret.shape[0]
        share = self.pulls_sum / (n * self.t.astype(np.float64))[:, None]
        return sweep_points(self.label, self.t, Moments.of(self.regret),
                            Moments.of(self.estimator), share)  # fmt: skip

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
        from .sweep import PolicyResult

        n = self.regret.shape[0]
        return PolicyResult(
            policy=self.cell.policy, regret=self.regret[:, -1], estimator=self.estimator[:, -1],
            pulls=None, best_arm=best_arm, wall_s=self.wall_s, label=self.label,
            best_pulls=self.best_pulls[:, -1], pulls_mean=self.pulls_sum[-1] / n,
            horizon=int(self.t[-1]),
        )  # fmt: skip


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


def group_config(grid: Grid, cells: Sequence[CellRuns]) -> dict[str, Any]:
    """The sweep log's configuration of a group (``sweep_config`` with cell labels)."""
    from .sweep import sweep_config

    c0 = cells[0].cell
    config = sweep_config(c0.instance, [c.cell.policy for c in cells], runs=grid.runs,
                          horizon=c0.horizon, seed=grid.seed,
                          checkpoints=[int(t) for t in cells[0].t],
                          channel=c0.channel)  # fmt: skip
    for entry, c in zip(config["policies"], cells, strict=True):
        entry["name"] = c.label
        if c.cell.policy.color is not None:  # every view draws the policy in its own colour
            entry["color"] = list(c.cell.policy.color)
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
        parts = _parts(folder)
    tasks: list[tuple[Chunk, dict[str, Any]]] = []
    skipped = 0
    threads = threads_per_worker if client is not None else None
    by_key = {cell.key: cell for cell in grid.cells}
    for cell in grid.cells:
        done = parts.get(cell.key, [])
        skipped += len(done)
        for chunk in grid.chunks(cell, covered=_covered(done)):
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
    with (
        SweepMcapSink(folder / "sweep.mcap", config) as log,
        open_sweep_recording(folder / "sweep.rrd", config) as rec,
    ):
        for c in cells:
            for point in c.points():
                log.write(point)
                rec.write(point)
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
