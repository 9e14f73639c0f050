"""A sweep folder's outputs beyond its parts, manifest and summaries: per (instance, horizon)
group the sweep log (``sweep.mcap``), its Rerun recording (``sweep.rrd``) and the figure
(``figure.png``), and for the folder ``results.parquet``. Made from the parts after every chunk
has finished, so their order and bytes do not depend on which worker finished first.

:class:`FolderOutputs` is what the top floor hands ``corraoi.experiments.sweeps.sweep``.
Handed a :class:`~corraoi.viewer.figure_worker.FigureWorker` (``corraoi sweep -o`` and
``corraoi.sweep`` start one with the sweep), it has each group's figure drawn there while it
writes the group's Rerun recording, and waits for the figures in :meth:`FolderOutputs.finish`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from corraoi.experiments.backends import sweep_backend
from corraoi.experiments.folder import CellRuns, ChunkResult
from corraoi.experiments.grid import Grid
from corraoi.experiments.montecarlo import sweep_config
from corraoi.experiments.sweeps import folder_provenance
from corraoi.provenance import Provenance
from corraoi.recorder.style import spec_color, variant_colors
from corraoi.recorder.sweeplog.log import SweepMcapSink
from corraoi.recorder.sweeplog.results import write_dataset
from corraoi.viewer.figure_worker import FigureWorker, draw_from_log


def group_config(grid: Grid, cells: Sequence[CellRuns]) -> dict[str, Any]:
    """The sweep log's configuration of a group (``sweep_config`` with cell labels)."""
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
    if any(c.cell.sources > 1 for c in cells):  # each policy's number of sources, in order
        config["sources"] = [int(c.cell.sources) for c in cells]
    return config


def write_results(
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
    write_dataset(folder / "results.parquet", grid, parts, folder_provenance(grid))


def write_group_log(
    folder: Path, grid: Grid, cells: Sequence[CellRuns], summary: dict[str, Any]
) -> dict[str, Any]:
    """A group's sweep log (``sweep.mcap``); returns its configuration, which
    :func:`write_group_recording` takes."""
    folder.mkdir(parents=True, exist_ok=True)
    config = group_config(grid, cells)
    config["notable"] = summary["notable"]  # read back by SweepLog.notable
    prov = Provenance.of([c.cell.policy for c in cells], backend=sweep_backend(grid.backend))
    # in log-time order: each checkpoint's points, the cells in grid order (a stable sort)
    points = sorted((p for c in cells for p in c.points()), key=lambda p: int(p.t))
    with SweepMcapSink(folder / "sweep.mcap", config, provenance=prov) as log:
        for point in points:
            log.write(point)
    return config


def write_group_recording(
    folder: Path, config: dict[str, Any], cells: Sequence[CellRuns], summary: dict[str, Any]
) -> None:
    """A group's Rerun recording (``sweep.rrd``): the points of its sweep log, with the runs
    worth watching drawn over the mean. Imports Rerun (only here)."""
    from corraoi.recorder.sweeplog.recording import open_sweep_recording

    with open_sweep_recording(folder / "sweep.rrd", config) as rec:
        for c in cells:
            for point in c.points():
                rec.write(point)
        for c in cells:  # the runs worth watching, over the mean (CPU: every checkpoint)
            if c.agg is not None or c.regret.shape[1] < 2:
                continue
            for kind, e in summary["notable"]["cells"].get(c.label, {}).items():
                rec.mark(c.label, kind, e["run"], e["seed"], c.t, c.regret[e["run"]])


class FolderOutputs:
    """Writes a finished sweep's files (``corraoi.experiments.sweeps.SweepOutputs``); with
    ``figures``, the figures are drawn by that worker process."""

    def __init__(self, figures: FigureWorker | None = None) -> None:
        from corraoi.extras import require_package

        # written after every run: a machine without Rerun is told before the sweep runs
        require_package("rerun", "a sweep folder (its sweep.rrd)")
        self._figures = figures
        self._drawn: list[tuple[Path, BaseException | None]] = []

    def write_results(self, folder: Path, grid: Grid, parts: dict[str, list[ChunkResult]],
                      labels: dict[str, str], *,
                      warn: Callable[[str], None] | None) -> None:  # fmt: skip
        write_results(folder, grid, parts, labels, warn=warn)

    def write_group(self, folder: Path, grid: Grid, cells: Sequence[CellRuns],
                    summary: dict[str, Any], *,
                    warn: Callable[[str], None] | None) -> None:  # fmt: skip
        config = write_group_log(folder, grid, cells, summary)
        log, figure = folder / "sweep.mcap", folder / "figure.png"
        if self._figures is not None:
            self._figures.draw(log, figure)  # drawn meanwhile
        else:
            self._drawn.append((figure, draw_from_log(str(log), str(figure))))
        write_group_recording(folder, config, cells, summary)

    def finish(self, *, warn: Callable[[str], None] | None) -> None:
        """Every figure written (waited for when a worker draws them). A figure that could
        not be drawn is a warning without matplotlib; any other failure to draw one is a
        WriteError (one line: the figure, the error, how to redraw it) once every figure was
        tried, which the sweep raises after its folder is complete."""
        from corraoi.errors import FigureUnavailable, WriteError

        drawn, self._drawn = self._drawn, []
        if self._figures is not None:
            drawn += self._figures.results()
        failed: list[tuple[str, BaseException]] = []
        for figure, failure in drawn:
            if isinstance(failure, FigureUnavailable):
                if warn is not None:
                    warn(f"{figure} not written: {failure}")
            elif failure is not None:
                detail = " ".join(f"{type(failure).__name__}: {failure}".split())[:300]
                redraw = f"corraoi figure {figure.parent / 'sweep.mcap'} -o {figure}"
                failed.append((f"{figure} not written: {detail} (the sweep's results are "
                               f"complete; redraw it: {redraw})", failure))  # fmt: skip
        if failed:
            n = len(failed) - 1
            more = f"; and {n} more figure{'s' if n > 1 else ''}" if n else ""
            raise WriteError(failed[0][0] + more) from failed[0][1]


__all__ = ["FolderOutputs", "group_config", "write_group_log", "write_group_recording",
           "write_results"]  # fmt: skip
