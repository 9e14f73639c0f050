"""A sweep folder's outputs, all of them: the recorder's (``results.parquet``, ``sweep.mcap``,
``sweep.rrd``) and the figure (``figure.png``). :class:`FolderOutputs` is what
``corraoi.experiments.sweeps.sweep`` writes a folder with unless its caller hands it other outputs.

Handed a :class:`~viewer.figure_worker.FigureWorker` (``corraoi sweep -o`` starts one when
the sweep starts), it has each group's figure drawn there while it writes the group's
Rerun recording, and waits for the figures in :meth:`FolderOutputs.finish`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from corraoi.experiments.folder import CellRuns, ChunkResult
from corraoi.experiments.grid import Grid
from viewer.figure_worker import FigureWorker, draw_from_log

from . import sweep_files as formats


class FolderOutputs:
    """Writes a finished sweep's files (``corraoi.experiments.sweeps.SweepOutputs``); with
    ``figures``, the figures are drawn by that worker process."""

    def __init__(self, figures: FigureWorker | None = None) -> None:
        self._figures = figures
        self._drawn: list[tuple[Path, BaseException | None]] = []

    def write_results(self, folder: Path, grid: Grid, parts: dict[str, list[ChunkResult]],
                      labels: dict[str, str], *,
                      warn: Callable[[str], None] | None) -> None:  # fmt: skip
        formats.write_results(folder, grid, parts, labels, warn=warn)

    def write_group(self, folder: Path, grid: Grid, cells: Sequence[CellRuns],
                    summary: dict[str, Any], *,
                    warn: Callable[[str], None] | None) -> None:  # fmt: skip
        config = formats.write_group_log(folder, grid, cells, summary)
        log, figure = folder / "sweep.mcap", folder / "figure.png"
        if self._figures is not None:
            self._figures.draw(log, figure)  # drawn meanwhile
        else:
            self._drawn.append((figure, draw_from_log(str(log), str(figure))))
        formats.write_group_recording(folder, config, cells, summary)

    def finish(self, *, warn: Callable[[str], None] | None) -> None:
        """Every figure written (waited for when a worker draws them); a figure that could
        not be drawn is a warning (without matplotlib) or its error."""
        from corraoi.errors import FigureUnavailable

        drawn, self._drawn = self._drawn, []
        if self._figures is not None:
            drawn += self._figures.results()
        for figure, failure in drawn:
            if isinstance(failure, FigureUnavailable):
                if warn is not None:
                    warn(f"{figure} not written: {failure}")
            elif failure is not None:
                raise failure
