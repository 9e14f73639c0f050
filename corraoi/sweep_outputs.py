"""What a finished sweep reports and writes for each (instance, horizon) group: its summary
(``--json``, ``summary.json``, ``summary.md``) with the runs worth watching, the sweep log
(``sweep.mcap``), its Rerun recording (``sweep.rrd``), ``figure.png`` and the folder's
``results.parquet``. All are made from the parts after every chunk has finished, so their
order and bytes do not depend on which worker finished first.

This is the one place the core still reaches up (issue 23, listed in tests/test_layers.py):
the sweep log, recording and Parquet are the recorder's formats and the figure the viewer's.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .grid import Grid
from .sweep_folder import CellRuns, ChunkResult, write_text


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
    from recorder.results import write_dataset

    write_dataset(folder / "results.parquet", grid, parts)


def write_group(
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
