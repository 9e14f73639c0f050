"""A sweep folder's outputs, all of them: the recorder's (``results.parquet``, ``sweep.mcap``,
``sweep.rrd``) and the figure (``figure.png``). :class:`FolderOutputs` is what
``corraoi.experiments.sweep`` writes a folder with unless its caller hands it other outputs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from corraoi.grid import Grid
from corraoi.sweep_folder import CellRuns, ChunkResult
from recorder import sweep_outputs as formats


class FolderOutputs:
    """Writes a finished sweep's files (``corraoi.experiments.SweepOutputs``)."""

    def write_results(self, folder: Path, grid: Grid, parts: dict[str, list[ChunkResult]],
                      labels: dict[str, str], *,
                      warn: Callable[[str], None] | None) -> None:  # fmt: skip
        formats.write_results(folder, grid, parts, labels, warn=warn)

    def write_group(self, folder: Path, grid: Grid, cells: Sequence[CellRuns],
                    summary: dict[str, Any], *,
                    warn: Callable[[str], None] | None) -> None:  # fmt: skip
        from recorder.sweep_log import read_sweep

        from .figure import FigureUnavailable, draw_figure

        formats.write_group_logs(folder, grid, cells, summary)
        try:
            draw_figure(read_sweep(folder / "sweep.mcap"), folder / "figure.png")
        except FigureUnavailable as exc:
            if warn is not None:
                warn(f"{folder / 'figure.png'} not written: {exc}")
