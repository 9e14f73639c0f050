"""``corraoi compare``: several recorded runs in one Rerun recording, side by side.

Each run goes through the same :class:`corraoi.recorder.rerun.sink.RerunSink` as ``record`` and
``replay``, under ``runs/<label>/...`` (labels from the policy names, made unique with the
instance, seed, horizon or parameters where needed). The embedded blueprint puts one
column per run -- its AoI against the oracle's, the channel played, the empirical means
and the candidate (competitive) set -- above one overlay panel of every run's regret
curve and the summary table. The summary figures are gathered while the blocks stream
through, so every log is read once. Nothing is simulated.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from corraoi.engine.block import SourcesBlock
from corraoi.engine.summary import RunSummary, SummaryAccumulator
from corraoi.policies import RGB
from corraoi.recorder.style import REGRET_UNIT, run_colors, spec_color

from .info import summary_rows
from .readahead import read_ahead
from .runs import LogLike, as_log, require_slots, unique_labels

if TYPE_CHECKING:
    import rerun.blueprint as rrb

    from corraoi.recorder.slotlog.reader import RunLog

#: Slots per block handed to the sinks.
BLOCK = 1000
#: Entity of the summary table (a markdown document) in a compare recording.
SUMMARY_ENTITY = "compare/summary"
#: Slots shown left of the cursor in the windowed views (AoI, arms, candidates): few
#: enough that a success or failure marker stays legible in a third of a screen.
WINDOW = 120



@dataclass
class ComparedRun:
    """One run of a comparison: its label in the recording, colour and summary figures."""

    label: str
    log: RunLog
    color: RGB
    summary: RunSummary | None = None

    @property
    def config(self) -> Any:
        return self.log.config


@dataclass
class Comparison:
    """What :func:`compare` sent; ``table()`` is the summary printed side by side."""

    runs: list[ComparedRun]
    warnings: list[str] = field(default_factory=list)
    path: Path | None = None

    def table(self) -> str:
        return summary_table(self.runs)

    def to_dict(self) -> dict[str, Any]:
        return {
            "path": None if self.path is None else str(self.path),
            "warnings": list(self.warnings),
            "runs": [
                {
                    "label": r.label,
                    "path": str(r.log.path),
                    "policy": r.config.policy.name,
                    "instance": r.config.instance_name,
                    "seed": r.config.seed,
                    "horizon": r.config.horizon,
                    "status": r.log.status,
                    "summary": None if r.summary is None else r.summary.to_dict(),
                }
                for r in self.runs
            ],
        }


def comparability_warnings(logs: Sequence[RunLog]) -> list[str]:
    """Warnings for runs whose regret curves cannot be compared (or only partly)."""
    out = []
    instances = {log.config.instance_name for log in logs}
    same_instance = all(log.config.instance == logs[0].config.instance for log in logs)
    if not same_instance:
        names = ", ".join(sorted(instances))
        what = f"instances {names}" if len(instances) > 1 else f"different instances named {names}"
        out.append(f"the runs are on {what}: their regret is not comparable")
    horizons = sorted({log.config.horizon for log in logs})
    if len(horizons) > 1:
        out.append(
            "the runs have different horizons ("
            + ", ".join(str(h) for h in horizons)
            + "): regret at the end is not comparable"
        )
    short = [log for log in logs if log.cut_short]
    for log in short:
        out.append(f"{log.path}: {log.summary}")
    if same_instance and len(horizons) == 1:
        seeds = {log.config.seed for log in logs}
        if len(seeds) > 1:
            out.append(
                "the runs use different seeds (hidden paths differ): their regret differs by "
                "chance as well as by policy"
            )
    return out


def log_colors(logs: Sequence[RunLog]) -> list[RGB]:
    """A colour per log (:func:`corraoi.recorder.style.run_colors`): its policy's, in lighter
    shades for runs that would share one."""
    return run_colors([spec_color(log.config.policy) for log in logs])


def compare_name(runs: Sequence[ComparedRun]) -> str:
    """What the viewer lists a comparison as: ``compare ucb, ts, cts-gauss``."""
    from corraoi.text import safe_text

    return "compare " + ", ".join(safe_text(r.label) for r in runs)


def compare_recording_id(runs: Sequence[ComparedRun]) -> str:
    """A recording id that depends on the labels and configurations only."""
    text = json.dumps([[r.label, r.config.to_dict()] for r in runs], sort_keys=True)
    return "corraoi-compare-" + hashlib.sha256(text.encode()).hexdigest()[:16]


def compare_blueprint(
    runs: Sequence[ComparedRun], *, window: int = WINDOW, aoi_max: float | None = None
) -> rrb.Blueprint:
    """One column per run above an overlay of every run's regret and the summary table.

    The columns are the views ``record`` shows (:class:`corraoi.recorder.rerun.layout.RunViews`,
    chosen by each run's number of arms), on y-scales shared by every column: the AoI up
    to ``aoi_max`` (the largest AoI of any run; None: each column its own), the arms up to
    the largest K.
    """
    import rerun as rr
    import rerun.blueprint as rrb

    from corraoi.recorder.rerun.layout import (
        LEGEND,
        VIEWER_PX,
        RunViews,
        SourcesViews,
        fit,
        legend_room,
        time_windows,
    )
    from corraoi.recorder.rerun.names import TIMELINE, run_path

    horizon = max(r.config.horizon for r in runs)
    tw = time_windows(window, horizon)
    arms = max(r.config.K for r in runs)
    aoi_y = None if aoi_max is None else (0.5, float(aoi_max) + 0.5)
    px = VIEWER_PX / len(runs)
    columns = []
    for r in runs:
        if r.config.sources > 1:  # several sources: who played which channel, each one's age
            s = SourcesViews(r.label, r.config, tw, prefix=r.label)
            columns.append(rrb.Vertical(
                s.occupancy(px), rrb.Grid(*s.ages(px / 2), grid_columns=2), s.means(px),
                row_shares=[1.5, 2, 1.2], name=r.label))  # fmt: skip
            continue
        v = RunViews(r.label, r.config, tw, prefix=r.label, aoi_y=aoi_y, arms=arms)
        # tab titles share the column's width: short ones
        tabs: list[rrb.View]
        if v.lines:
            tabs = [v.means(px, name=f"{r.label}: means"),
                    v.candidates(px, name=f"{r.label}: candidate set")]  # fmt: skip
        else:
            tabs = [v.mean_bars(px, name=f"{r.label}: means now"),
                    v.means(px, name=f"{r.label}: arms that matter"),
                    v.candidates(px, name=f"{r.label}: candidates")]  # fmt: skip
        columns.append(
            # the arm played gets the height that labels every arm's row up to 8 arms
            rrb.Vertical(v.aoi(px), v.arm_played(px), rrb.Tabs(*tabs, active_tab=0),
                         row_shares=[1.2, 1.5, 2], name=r.label)  # fmt: skip
        )
    overrides = {
        f"{run_path(r.label)}/regret": rr.SeriesLines.from_fields(
            names=[r.label], colors=[r.color], widths=[2.0]
        )
        for r in runs
    }
    overlay_px = VIEWER_PX * 3 / 5
    room = legend_room([r.label for r in runs], overlay_px)
    overlay = rrb.TimeSeriesView(
        origin="/",
        contents=[f"{run_path(r.label)}/regret" for r in runs],
        name=fit(f"AoI regret {REGRET_UNIT} (pathwise), every run", overlay_px),
        axis_x=tw.whole_axis(room),
        overrides=overrides,  # type: ignore[arg-type]
        plot_legend=LEGEND,
    )
    summary = rrb.TextDocumentView(origin=SUMMARY_ENTITY, name="summary")
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(*columns, name="runs"),
            rrb.Horizontal(overlay, summary, column_shares=[3, 2]),
            row_shares=[3.8, 2],
        ),
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        rrb.BlueprintPanel(state="hidden"),
        rrb.SelectionPanel(state="hidden"),
    )


def prepare(logs: Sequence[LogLike]) -> tuple[list[ComparedRun], list[str]]:
    """Open every log (LogError on the first bad one), label and colour the runs."""
    if not logs:
        from corraoi.errors import UsageError

        raise UsageError("compare needs at least one log")
    opened = [require_slots(as_log(x), "compare") for x in logs]
    labels = unique_labels(opened)
    colors = log_colors(opened)
    runs = [
        ComparedRun(lab, log, col) for lab, log, col in zip(labels, opened, colors, strict=True)
    ]
    return runs, comparability_warnings(opened)


def compare(
    logs: Sequence[LogLike],
    *,
    rrd_path: str | os.PathLike[str] | None = None,
    viewer_url: str | None = None,
    overwrite: bool = False,
    block: int = BLOCK,
    on_block: Callable[[int], None] | None = None,
) -> Comparison:
    """Send every run of ``logs`` into one recording (an ``.rrd`` and/or a viewer).

    With neither ``rrd_path`` nor ``viewer_url`` nothing is sent and only the summary
    figures are gathered. Every log is opened (and checked) before anything is written.
    """
    runs, warnings = prepare(logs)
    if rrd_path is None and viewer_url is None:
        for r in runs:
            acc = SummaryAccumulator(r.config)
            for b in r.log.blocks(4096):
                acc.update(b)
                if on_block is not None:
                    on_block(len(b))
            r.summary = acc.result()
        return Comparison(runs, warnings, None)

    import rerun as rr

    from corraoi.recorder.rerun.output import RrdOutput
    from corraoi.recorder.rerun.sink import run_sink

    with RrdOutput(
        runs[0].config,
        rrd_path=rrd_path,
        viewer_url=viewer_url,
        overwrite=overwrite,
        label="compare",
        name=compare_name(runs),
        recording_id=compare_recording_id(runs),
        discard_on_abort=True,  # Ctrl-C or a damaged chunk: no half-written .rrd is left
        blueprint_at_end=True,  # its AoI scale is the largest AoI sent
    ) as out:
        sinks = []
        for r in runs:
            sinks.append(run_sink(out.recording, r.label, r.config, color=r.color))
        accs = [SummaryAccumulator(r.config) for r in runs]
        opened = [r.log for r in runs]

        every = ((i, b) for i, log in enumerate(opened) for b in log.blocks(block))
        aoi_max = 1.0
        for i, b in read_ahead(every):  # the next blocks are read while these are sent
            sinks[i].write(b)
            accs[i].update(b)
            for part in b.sources if isinstance(b, SourcesBlock) else (b,):
                aoi_max = max(aoi_max, float(part.aoi.max()), float(part.oracle_aoi.max()))
            if on_block is not None:
                on_block(len(b))
        for r, sink, acc in zip(runs, sinks, accs, strict=True):
            sink.close()
            r.summary = acc.result()
        out.recording.log(
            SUMMARY_ENTITY,
            rr.TextDocument(compare_markdown(runs, warnings), media_type=rr.MediaType.MARKDOWN),
            static=True,
        )
        out.set_blueprint(compare_blueprint(runs, aoi_max=aoi_max))
    return Comparison(runs, warnings, out.path)


# ---------------------------------------------------------------------------- tables


def _rows(runs: Sequence[ComparedRun]) -> tuple[list[str], list[list[str]]]:
    """The row names and each run's column. Runs of one source and of several have
    different figures (regret per source, collisions): every figure any run has is a row,
    "-" in the columns of the runs without it."""
    head = ["policy", "instance", "seed", "slots"]
    names = list(head)
    columns: list[dict[str, str]] = []
    for r in runs:
        s = r.summary
        assert s is not None
        status = "" if not r.log.cut_short else f" of {r.config.horizon} (cut short)"
        col = dict(zip(head, [r.config.policy.name, r.config.instance_name,
                               str(r.config.seed), f"{s.slots}{status}"], strict=True))  # fmt: skip
        for name, value in summary_rows(s):
            col[name] = value
            if name not in names:
                names.append(name)
        columns.append(col)
    return names, [[col.get(name, "-") for name in names] for col in columns]


def summary_table(runs: Sequence[ComparedRun]) -> str:
    """The summary figures side by side: one column per run, one row per figure."""
    names, cells = _rows(runs)
    first = max(len(n) for n in names) + 2
    widths = [
        max(len(r.label), *(len(c) for c in col)) + 2 for r, col in zip(runs, cells, strict=True)
    ]
    lines = [" " * first + "".join(f"{r.label:>{w}}" for r, w in zip(runs, widths, strict=True))]
    for i, name in enumerate(names):
        row = "".join(f"{col[i]:>{w}}" for col, w in zip(cells, widths, strict=True))
        lines.append(f"{name:<{first}}{row}")
    return "\n".join(lines)


def compare_markdown(runs: Sequence[ComparedRun], warnings: Sequence[str]) -> str:
    """The summary table as markdown (shown in the compare recording).

    Made to fit its panel: a row whose value is the same for every run (instance, seed,
    slots, best arm; the policy when the labels are the policy names) becomes one line
    under the table instead.
    """
    names, cells = _rows(runs)
    keep, same = [], []
    for i, name in enumerate(names):
        values = {col[i] for col in cells}
        if len(runs) > 1 and len(values) == 1 and name not in _ALWAYS:
            same.append(f"{name} {values.pop()}")
        elif name == "policy" and all(r.label == col[i] for r, col in zip(runs, cells,
                                                                          strict=True)):
            continue  # the column headings already say it
        else:
            keep.append(i)
    lines = ["| | " + " | ".join(r.label for r in runs) + " |",
             "|---|" + "---:|" * len(runs)]  # fmt: skip
    for i in keep:
        lines.append(f"| {names[i]} | " + " | ".join(col[i] for col in cells) + " |")
    if same:
        lines += ["", "Every run: " + ", ".join(same) + "."]
    if warnings:
        lines.append("")
        lines += [f"**warning:** {w}" for w in warnings]
    lines += ["", f"Arms from 1; regret = sum(aoi - oracle_aoi) {REGRET_UNIT}."]
    return "\n".join(lines)


#: Rows the compare summary keeps even when every run has the same value.
_ALWAYS = ("pathwise regret", "paper's estimator", "pulls per arm", "share on best arm")
