"""The layout of one run in the Rerun viewer: the default blueprint ``record`` and ``replay``
embed, and the time windows the views share (``compare`` uses them too)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import rerun.blueprint as rrb

from corraoi.engine.block import RunConfig
from recorder import style

from .names import TIMELINE, run_path

#: Slots shown by the windowed views (AoI, arms, states, candidates) left of the cursor:
#: few enough that every success and failure marker stays legible.
WINDOW = 200


@dataclass(frozen=True)
class TimeWindows:
    """Time axes and query ranges of the blueprints: the last ``window`` slots before the
    cursor, and the whole run."""

    window_axis: Any
    window_query: Any
    whole_axis: Any
    whole_query: Any


def time_windows(window: int) -> TimeWindows:
    recent = rrb.TimeRange(
        start=rrb.TimeRangeBoundary.cursor_relative(seq=-window),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )
    everything = rrb.TimeRange(
        start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()
    )
    return TimeWindows(
        window_axis=rrb.TimeAxis(view_range=recent),
        window_query=rrb.VisibleTimeRange(TIMELINE, start=recent.start, end=recent.end),
        whole_axis=rrb.TimeAxis(view_range=everything),
        whole_query=rrb.VisibleTimeRange(TIMELINE, start=everything.start, end=everything.end),
    )


def one_run_blueprint(label: str, config: RunConfig, *, window: int = WINDOW) -> rrb.Blueprint:
    """The default layout of one run.

    Top: AoI against the oracle's (the last ``window`` slots before the cursor) and the
    regret with the paper's estimator (whole run). Middle: the arm played (successes and
    failures apart, AoI-aware overrides marked) and the candidate set, windowed. Bottom:
    the empirical means (whole run), the pulls, the hidden state and the configuration.
    """
    base = run_path(label)
    K = config.instance.K
    n = config.instance.n_states
    tw = time_windows(window)
    window_axis, window_query = tw.window_axis, tw.window_query
    whole_axis, whole_query = tw.whole_axis, tw.whole_query
    legend = rrb.PlotLegend(corner=rrb.components.Corner2D.LeftTop)

    def windowed(name: str, contents: list[str], y: tuple[float, float] | None = None) -> Any:
        return rrb.TimeSeriesView(
            origin=base,
            contents=contents,
            name=name,
            axis_x=window_axis,
            axis_y=rrb.ScalarAxis(range=y, zoom_lock=True) if y else None,
            time_ranges=[window_query],
            plot_legend=legend,
        )

    aoi = windowed(
        f"AoI {style.AOI_UNIT}: policy vs oracle (last {window} slots)",
        ["$origin/aoi", "$origin/oracle_aoi"],
    )

    def whole(name: str, contents: list[str], y: tuple[float, float] | None = None) -> Any:
        return rrb.TimeSeriesView(
            origin=base,
            contents=contents,
            name=name,
            axis_x=whole_axis,
            axis_y=rrb.ScalarAxis(range=y) if y else None,
            time_ranges=[whole_query],
            plot_legend=legend,
        )

    regret = whole(
        f"AoI regret {style.REGRET_UNIT}: pathwise and the paper's estimator",
        ["$origin/regret", "$origin/estimator"],
    )
    arms = windowed(
        f"arm played (1..{K}): success / failure / AoI-aware override",
        ["$origin/arm/**", "$origin/override"],
        (0.5, K + 0.5),
    )
    candidates = windowed(f"candidate set (arms 1..{K})", ["$origin/candidates/**"],
                          (0.5, K + 0.5))  # fmt: skip
    means = whole(
        "mean reward per arm: empirical and true [probability]",
        ["$origin/mu_hat", "$origin/mu_true"],
        (0.0, 1.0),
    )
    pulls = whole("pulls per arm [count]", ["$origin/pulls"])
    state = windowed(f"hidden state x (1..{n})", ["$origin/x"], (0.5, n + 0.5))
    about = rrb.TextDocumentView(origin=f"{base}/about", name="run")
    return rrb.Blueprint(
        rrb.Vertical(
            rrb.Horizontal(aoi, regret, column_shares=[3, 2]),
            rrb.Horizontal(arms, candidates, column_shares=[3, 2]),
            rrb.Horizontal(
                rrb.Tabs(means, pulls, active_tab=0),
                state,
                about,
                column_shares=[2, 2, 1],
            ),
            row_shares=[3, 2.5, 3],  # the means' legend lists 2 K series
        ),
        # the views get the room: the time panel shows only its scrubber, the selection
        # panel opens when asked
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        rrb.SelectionPanel(state="hidden"),
    )


__all__ = ["WINDOW", "TimeWindows", "one_run_blueprint", "time_windows"]
