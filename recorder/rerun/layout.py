"""The layout of one run in the Rerun viewer: the default blueprint ``record`` and ``replay``
embed, and the views and time windows it is made of (``compare`` builds its columns from
the same views, so that a run reads the same in both).

The views are chosen by the number of arms K (:func:`corraoi.recorder.style.lines_for`): up to
``style.LINES_UP_TO`` arms a line per arm; beyond it the per-arm values at the time cursor
as bar charts, strips of arms x slots for the arm played and the candidate set, and lines
for the arms that matter only. Legends stand in room right of the data: a view's time axis
reaches past the cursor (or the horizon) by as much as its legend needs at the panel's
width in a 1600-pixel-wide viewer (:func:`legend_room`). Views whose title says what each
series is have no legend. Titles are cut to what their panel shows (:func:`fit`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import rerun.blueprint as rrb

from corraoi.engine.block import RunConfig
from corraoi.recorder import style

from .names import TIMELINE, run_path

#: Slots shown by the windowed views (AoI, arms, states, candidates) left of the cursor:
#: few enough that every success and failure marker stays legible.
WINDOW = 200
#: The viewer width the layouts are made for (pixels; the screenshots' 1600 x 900).
VIEWER_PX = 1600
#: Pixels of a legend besides its text, and of a character of it (egui's 13 px font).
LEGEND_PAD_PX, CHAR_PX = 36, 6.8
#: Pixels a panel's title bar keeps for its icons, and a plot for its y-axis labels.
TITLE_ICONS_PX, AXIS_PX = 100, 46
#: The most room a legend is given, as a share of the span of data shown.
MAX_ROOM = 1.5


@dataclass(frozen=True)
class TimeWindows:
    """What the time axes show: the last ``window`` slots before the cursor, and the whole
    run (up to ``horizon``, or the data's extent when it is None)."""

    window: int
    horizon: int | None
    window_query: Any
    whole_query: Any

    def window_axis(self, room: float = 0.0) -> Any:
        """The windowed views' axis, reaching ``room`` x window past the cursor."""
        return rrb.TimeAxis(view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.cursor_relative(seq=-self.window),
            end=rrb.TimeRangeBoundary.cursor_relative(seq=round(self.window * room)),
        ))  # fmt: skip

    def whole_axis(self, room: float = 0.0) -> Any:
        """The whole-run views' axis, from slot 0 to ``room`` x horizon past the horizon."""
        if self.horizon is None or self.horizon <= 0:
            return rrb.TimeAxis(view_range=rrb.TimeRange(
                start=rrb.TimeRangeBoundary.infinite(), end=rrb.TimeRangeBoundary.infinite()))
        return rrb.TimeAxis(view_range=rrb.TimeRange(
            start=rrb.TimeRangeBoundary.absolute(seq=0),
            end=rrb.TimeRangeBoundary.absolute(seq=round(self.horizon * (1 + room))),
        ))  # fmt: skip


def time_windows(window: int, horizon: int | None = None) -> TimeWindows:
    """The time windows of the blueprints (``horizon``: the last slot of the longest run
    shown; None: the whole-run axes follow the data)."""
    recent = (rrb.TimeRangeBoundary.cursor_relative(seq=-window),
              rrb.TimeRangeBoundary.cursor_relative())  # fmt: skip
    infinite = rrb.TimeRangeBoundary.infinite()
    return TimeWindows(
        window=window,
        horizon=horizon,
        window_query=rrb.VisibleTimeRange(TIMELINE, start=recent[0], end=recent[1]),
        whole_query=rrb.VisibleTimeRange(TIMELINE, start=infinite, end=infinite),
    )


LEGEND = rrb.PlotLegend(corner=rrb.components.Corner2D.RightTop)
NO_LEGEND = rrb.PlotLegend(visible=False)


def legend_room(entries: Sequence[str], panel_px: float) -> float:
    """Room for a legend of ``entries`` right of the data, as a share of the data's span,
    in a panel ``panel_px`` wide: the legend's width over the plot's width left of it."""
    if not entries:
        return 0.0
    legend = LEGEND_PAD_PX + CHAR_PX * max(len(e) for e in entries)
    data = panel_px - AXIS_PX - legend - 8
    return MAX_ROOM if data <= 0 else min(legend / data, MAX_ROOM)


def title_chars(panel_px: float) -> int:
    """Characters of a title that a panel ``panel_px`` wide shows in full."""
    return max(int((panel_px - TITLE_ICONS_PX) / (CHAR_PX + 0.4)), 16)


def fit(title: str, panel_px: float) -> str:
    """A view title cut to what its panel shows (:func:`corraoi.recorder.style.shorten`)."""
    return style.shorten(title, title_chars(panel_px))


def first_fit(panel_px: float, *titles: str) -> str:
    """The first of ``titles`` (longest first) that its panel shows in full, else the last
    one cut (:func:`fit`)."""
    for title in titles:
        if len(title) <= title_chars(panel_px):
            return title
    return fit(titles[-1], panel_px)


def names_in_title(prefix: str, names: Sequence[str], panel_px: float, fallback: str) -> str:
    """``prefix: 1 los · 2 nlos-a · ...`` when the names fit the panel's title (each cut
    to what leaves room for all), else ``fallback``: the instance's names where a title has
    room for them. ``names``: number and name as text, ``"2 los"``; none: ``fallback``."""
    if not names:
        return fallback
    whole = f"{prefix}: " + " · ".join(style.shorten(n, 10**6) for n in names)
    if len(whole) <= title_chars(panel_px):
        return whole
    each = (title_chars(panel_px) - len(prefix) - 2) // len(names) - 3  # " · " between
    if each < 6:
        return fallback
    return f"{prefix}: " + " · ".join(style.shorten(n, each) for n in names)


def _names(names: Sequence[str], default: Sequence[str]) -> list[str]:
    """``"2 los"`` for each named entry; none when every name is its default."""
    if list(names) == list(default):
        return []
    return [style.numbered(i, n, d, 10**6) for i, (n, d) in enumerate(zip(names, default,
                                                                           strict=True))]


class RunViews:
    """The views of one run under ``runs/<label>``, for its number of arms.

    Each view takes the width of its panel in a 1600-pixel viewer (``px``), which sets its
    legend room and how much of its title is kept. ``compare`` builds the same views for
    each of its columns: ``prefix`` (the run's label before each title), ``aoi_y`` and
    ``arms`` (y ranges shared by the columns). ``why``: the run logs scores, so its views
    show why the policy chose its arm (:meth:`why`; the forced slots on the arm played,
    the override's threshold on the AoI).
    """

    def __init__(self, label: str, config: RunConfig, tw: TimeWindows, *, prefix: str = "",
                 aoi_y: tuple[float, float] | None = None, arms: int | None = None,
                 why: bool = False) -> None:
        self.base = run_path(label)
        self.config = config
        self.K = config.K
        self.arms = arms or self.K
        self.lines = style.lines_for(self.K)
        self.tw = tw
        self.prefix = f"{prefix}: " if prefix else ""
        self.aoi_y = aoi_y
        self.arm_legends = [style.arm_legend(k, n) for k, n in enumerate(config.arm_names)]
        theory = config.theory  # None for a run without an instance: no best arm
        self.best = None if theory is None else int(theory.best_arm)
        self.why_shown = why
        self.aware = style.is_aoi_aware(config.policy.name)

    def _title(self, px: float, *titles: str) -> str:
        """The first of ``titles`` that fits the panel, after the run's prefix."""
        return first_fit(px, *(self.prefix + t for t in titles))

    def _series(self, name: str, contents: list[str], px: float, *, windowed: bool,
                y: tuple[float, float] | None = None, legend: Sequence[str] = (),
                lock: bool = True) -> rrb.TimeSeriesView:  # fmt: skip
        tw = self.tw
        room = legend_room(legend, px)
        return rrb.TimeSeriesView(
            origin=self.base,
            contents=contents,
            name=name,
            axis_x=tw.window_axis(room) if windowed else tw.whole_axis(room),
            axis_y=rrb.ScalarAxis(range=y, zoom_lock=lock) if y else None,
            time_ranges=[tw.window_query if windowed else tw.whole_query],
            plot_legend=LEGEND if legend else NO_LEGEND,
        )

    def aoi(self, px: float) -> rrb.TimeSeriesView:
        w = self.tw.window
        contents = ["$origin/aoi", "$origin/oracle_aoi"]
        if self.why_shown and self.aware:  # the override acts where the AoI crosses it
            contents.append("$origin/why/threshold")
            title = self._title(
                px, f"AoI {style.AOI_UNIT}: policy (line), oracle k* (black dots), override "
                f"threshold (gold), last {w} slots",
                f"AoI {style.AOI_UNIT}: line, oracle: dots, threshold: gold",
                f"AoI {style.AOI_UNIT}, threshold: gold",
            )  # fmt: skip
        else:
            title = self._title(
                px, f"AoI {style.AOI_UNIT}: policy (line), oracle k* (black dots), last {w} "
                "slots",
                f"AoI {style.AOI_UNIT}: line, oracle k*: dots, last {w}",
                f"AoI {style.AOI_UNIT}, oracle: dots",
            )  # fmt: skip
        return self._series(title, contents, px, windowed=True, y=self.aoi_y, lock=False)

    def regret(self, px: float) -> rrb.TimeSeriesView:
        title = self._title(
            px, f"AoI regret {style.REGRET_UNIT}: pathwise (colour), paper's estimator (grey)",
            f"AoI regret {style.REGRET_UNIT}, estimator: grey",
        )  # fmt: skip
        return self._series(title, ["$origin/regret", "$origin/estimator"], px, windowed=False)

    def arm_played(self, px: float) -> rrb.TimeSeriesView:
        arm_names = self.config.arm_names
        names = _names(arm_names, [str(k + 1) for k in range(self.K)]) if self.lines else []
        title = names_in_title(f"{self.prefix}arm played", names, px,
                               self._title(px, f"arm played (1..{self.K})"))  # fmt: skip
        legend = [style.SUCCESS_NAME, style.FAILURE_NAME]
        if self.best is not None:
            legend.append(style.best_arm_name(self.best))
        if self.aware:
            legend.append(style.OVERRIDE_NAME)
        contents = ["$origin/arm/**", "$origin/override"]
        if self.why_shown:
            contents.append("$origin/why/forced")
            legend.append(style.FORCED_NAME)
        view = self._series(title, contents, px, windowed=True,
                            y=(0.5, self.arms + 0.5), legend=legend)  # fmt: skip
        return view

    def why(self, px: float) -> rrb.TimeSeriesView:
        """Why the policy chose its arm: the score of every arm (what it maximised; up to
        LINES_UP_TO arms, else of the arms that matter) and of the arm played, over the
        last slots before the cursor. Up to LINES_UP_TO arms the arm played is the top
        line where the score chose it: its dot marks only the slots it was below the top."""
        w = self.tw.window
        if self.lines:
            contents, legend = ["$origin/why/score", "$origin/why/chosen"], self.arm_legends
            chosen = style.CHOSEN_BELOW_NAME
            title = self._title(
                px, f"why this arm: score {style.SCORE_UNIT} per arm (lines; the top one "
                f"played), dots: played below the top, last {w} slots",
                f"why this arm: scores (top played), dots: played below, last {w}",
                "why this arm: scores",
            )  # fmt: skip
        else:
            contents = ["$origin/why/focus/**", "$origin/why/chosen"]
            legend = [self.arm_legends[k] for k in range(min(self.K, style.FOCUS_MAX))]
            chosen = style.CHOSEN_NAME
            title = self._title(
                px, f"why this arm: score {style.SCORE_UNIT} per arm (lines), the chosen "
                f"one's (dots), last {w} slots",
                f"why this arm: scores, the chosen one's: dots, last {w}",
                "why this arm: scores",
            )  # fmt: skip
        return self._series(title, contents, px, windowed=True, legend=[*legend, chosen])

    def why_bars(self, px: float) -> rrb.BarChartView:
        """The scores at the cursor, the arm played's in the policy's colour (beyond
        LINES_UP_TO arms)."""
        return rrb.BarChartView(
            origin=self.base,
            contents=["$origin/why/bars/**"],
            name=self._title(
                px, f"why this arm: scores {style.SCORE_UNIT} at the cursor, the chosen arm "
                "in colour", "why this arm: scores now",
            ),
            plot_legend=NO_LEGEND,
        )  # fmt: skip

    def candidates(self, px: float, *, name: str | None = None) -> rrb.TimeSeriesView:
        what = "a dot per slot in the set" if self.lines else "a dot per arm and slot in it"
        title = name or self._title(px, f"candidate set (y: arm; {what})", "candidate set")
        return self._series(title, ["$origin/candidates/**"], px, windowed=True,
                            y=(0.5, self.arms + 0.5),
                            legend=self.arm_legends if self.lines else ())  # fmt: skip

    def means(self, px: float, *, name: str | None = None) -> rrb.TimeSeriesView:
        if self.lines:
            title = name or self._title(
                px, f"mean reward {style.MEAN_UNIT}: line empirical, dots true",
                f"mean {style.MEAN_UNIT}, dots: true",
            )  # fmt: skip
            return self._series(title, ["$origin/mu_hat", "$origin/true_means/**"], px,
                                windowed=False, y=(0.0, 1.02), legend=self.arm_legends)
        legends = [self.arm_legends[k] for k in range(min(self.K, style.FOCUS_MAX))]
        title = name or self._title(
            px, f"mean {style.MEAN_UNIT} of the arms that matter (dots: true)",
            f"arms that matter: mean {style.MEAN_UNIT}",
        )  # fmt: skip
        return self._series(title, ["$origin/focus/**", "$origin/true_means/**"], px,
                            windowed=False, y=(0.0, 1.02), legend=legends)  # fmt: skip

    def mean_bars(self, px: float, *, name: str | None = None) -> rrb.BarChartView:
        return rrb.BarChartView(
            origin=self.base,
            contents=["$origin/bars/mean", "$origin/bars/mean_other", "$origin/bars/mean_true",
                      "$origin/bars/mean_arm/**"],
            name=name or self._title(
                px, f"mean {style.MEAN_UNIT} at the cursor: empirical | true",
                f"mean {style.MEAN_UNIT} now: empirical | true",
            ),
            plot_legend=NO_LEGEND,
        )

    def pulls(self, px: float) -> rrb.View:
        if self.lines:
            return self._series(self._title(px, f"pulls per arm {style.PULLS_UNIT}"),
                                ["$origin/pulls"], px, windowed=False,
                                legend=self.arm_legends)  # fmt: skip
        return rrb.BarChartView(
            origin=self.base, contents=["$origin/bars/pulls", "$origin/bars/pulls_arm/**"],
            name=self._title(px, f"pulls at the cursor {style.PULLS_UNIT}",
                             f"pulls now {style.PULLS_UNIT}"),
            plot_legend=NO_LEGEND,
        )  # fmt: skip

    def state(self, px: float) -> rrb.TimeSeriesView:
        inst = self.config.instance
        if inst is None:  # a run without an instance logs no hidden state
            return self._series(self._title(px, "hidden state x: none (no instance)"),
                                ["$origin/x"], px, windowed=True)  # fmt: skip
        n = inst.n_states
        names = _names(inst.state_names, [f"x{x + 1}" for x in range(n)])
        title = names_in_title("hidden state x", names, px,
                               self._title(px, f"hidden state x (1..{n})"))  # fmt: skip
        return self._series(title, ["$origin/x"], px, windowed=True, y=(0.5, n + 0.5))

    def card(self) -> rrb.TextDocumentView:
        return rrb.TextDocumentView(origin=f"{self.base}/about", name="run")


def one_run_blueprint(label: str, config: RunConfig, *, window: int = WINDOW,
                      why: bool | None = None) -> rrb.Blueprint:  # fmt: skip
    """The default layout of one run.

    Top: AoI against the oracle's (the last ``window`` slots before the cursor) and the
    regret with the paper's estimator (whole run). Below, beside the run card: the arm
    played (successes and failures apart, AoI-aware overrides marked, the best arm as a
    line) and the candidate set, windowed; then, up to ``style.LINES_UP_TO`` arms, the
    means and the pulls per arm (whole run) and the hidden state; beyond, the means at the
    cursor as bars, the means of the arms that matter, and the pulls at the cursor (the
    hidden state goes to a tab beside the run card).

    ``why`` (by default when the run is one that logs scores, ``RunConfig.scored``): the
    "why this arm" view beside the means (beyond LINES_UP_TO arms, the scores at the cursor
    as bars, with the scores of the arms that matter in a tab).
    """
    why = config.scored if why is None else why
    v = RunViews(label, config, time_windows(window, config.horizon), why=why)
    W = VIEWER_PX
    top = rrb.Horizontal(v.aoi(W * 3 / 5), v.regret(W * 2 / 5), column_shares=[3, 2])
    if v.lines:
        inner = W * 4 / 5  # left of the run card
        middle = rrb.Horizontal(v.arm_played(inner * 3 / 5), v.candidates(inner * 2 / 5),
                                column_shares=[3, 2])  # fmt: skip
        if why:  # beside the means it explains
            bottom = rrb.Horizontal(v.means(inner * 0.3), v.why(inner * 0.3),
                                    v.pulls(inner * 0.2), v.state(inner * 0.2),
                                    column_shares=[3, 3, 2, 2])  # fmt: skip
        else:
            bottom = rrb.Horizontal(v.means(inner * 0.4), v.pulls(inner * 0.3),
                                    v.state(inner * 0.3), column_shares=[4, 3, 3])  # fmt: skip
        root = rrb.Vertical(
            top,
            rrb.Horizontal(rrb.Vertical(middle, bottom, row_shares=[2.6, 3.4]), v.card(),
                           column_shares=[4, 1]),  # fmt: skip
            row_shares=[3, 6],
        )
    else:
        # the strips get the height that labels every arm's row up to about 16 arms (egui
        # labels a y-axis step of 1 from about 20 pixels an arm), the card a tab with the
        # hidden state beside them, the bars and lines the whole width below
        middle = rrb.Horizontal(
            v.arm_played(W * 3 / 6.4), v.candidates(W * 2 / 6.4),
            rrb.Tabs(v.card(), v.state(W * 1.4 / 6.4), active_tab=0),
            column_shares=[3, 2, 1.4],
        )  # fmt: skip
        if why:
            bottom = rrb.Horizontal(
                v.mean_bars(W * 0.27), rrb.Tabs(v.why_bars(W * 0.27), v.why(W * 0.27)),
                v.means(W * 0.27), v.pulls(W * 0.19), column_shares=[27, 27, 27, 19],
            )  # fmt: skip
        else:
            bottom = rrb.Horizontal(v.mean_bars(W * 0.37), v.means(W * 0.37),
                                    v.pulls(W * 0.26), column_shares=[37, 37, 26])  # fmt: skip
        root = rrb.Vertical(top, middle, bottom, row_shares=[2.0, 4.0, 3.0])
    return rrb.Blueprint(
        root,
        # the views get the room: the time panel shows only its scrubber, the blueprint and
        # selection panels open when asked
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="hidden"),
    )


#: The most sources the views of a run of several sources give a legend.
LEGEND_SOURCES = 4


@dataclass(frozen=True)
class SourcesViews:
    """The views of a run of several sources (:mod:`corraoi.recorder.rerun.sources`), each
    made for a panel ``px`` pixels wide: ``prefix`` before each title (compare's columns)."""

    label: str
    config: RunConfig
    tw: TimeWindows
    prefix: str = ""

    def _series(self, name: str, contents: list[str], px: float, *, windowed: bool,
                y: tuple[float, float] | None = None,
                legend: Sequence[str] = ()) -> rrb.TimeSeriesView:  # fmt: skip
        tw, room = self.tw, legend_room(legend, px)
        return rrb.TimeSeriesView(
            origin=run_path(self.label), contents=contents,
            name=fit(f"{self.prefix}: {name}" if self.prefix else name, px),
            axis_x=tw.window_axis(room) if windowed else tw.whole_axis(room),
            axis_y=rrb.ScalarAxis(range=y, zoom_lock=True) if y else None,
            time_ranges=[tw.window_query if windowed else tw.whole_query],
            plot_legend=LEGEND if legend else NO_LEGEND,
        )  # fmt: skip

    def _names(self) -> list[str]:
        return [style.source_name(m) for m in range(1, self.config.sources + 1)]

    def _legend(self, *entries: str) -> list[str]:
        """A legend of up to LEGEND_SOURCES sources (beyond, the views would be all legend:
        the colours are named in the run card and the titles)."""
        return list(entries) if self.config.sources <= LEGEND_SOURCES else []

    def regret(self, px: float) -> rrb.TimeSeriesView:
        return self._series(
            f"AoI regret {style.REGRET_UNIT}: all sources (black) and each source",
            ["$origin/regret", *(f"$origin/sources/{m}/regret"
                                 for m in range(1, self.config.sources + 1))],
            px, windowed=False,
            legend=self._legend("all sources", *self._names()),
        )  # fmt: skip

    def occupancy(self, px: float) -> rrb.TimeSeriesView:
        K, w = self.config.K, self.tw.window
        return self._series(
            f"channel played (1..{K}) by each source, collisions: red crosses, last {w} slots",
            ["$origin/occupancy/**"], px, windowed=True, y=(0.5, K + 0.5),
            legend=self._legend(*self._names(), "collision"),
        )  # fmt: skip

    def ages(self, px: float) -> list[rrb.TimeSeriesView]:
        """A view per source (each ``px`` wide): its age against its oracle's."""
        w = self.tw.window
        return [
            self._series(f"source {m}: AoI {style.AOI_UNIT} (line), its oracle (dots), last {w}",
                         [f"$origin/sources/{m}/aoi", f"$origin/sources/{m}/oracle_aoi"],
                         px, windowed=True)  # fmt: skip
            for m in range(1, self.config.sources + 1)
        ]

    def means(self, px: float) -> rrb.View:
        M, K = self.config.sources, self.config.K
        if K > style.SOURCE_BARS_UP_TO:  # a heatmap: rows the sources, columns the arms
            title = (f"mean {style.MEAN_UNIT} at the cursor: rows sources 1..{M}, columns "
                     f"arms 1..{K}, dark 0 .. bright 1")  # fmt: skip
            return rrb.TensorView(
                origin=f"{run_path(self.label)}/means",
                name=fit(f"{self.prefix}: {title}" if self.prefix else title, px),
                view_fit="fill",
            )
        title = (f"mean {style.MEAN_UNIT} per arm at the cursor: each source's bar in its "
                 "colour, then the true mean (dark grey)")  # fmt: skip
        return rrb.BarChartView(
            origin=run_path(self.label), contents=["$origin/true_means", "$origin/means/**"],
            name=fit(f"{self.prefix}: {title}" if self.prefix else title, px),
            plot_legend=NO_LEGEND,
        )  # fmt: skip


def sources_blueprint(label: str, config: RunConfig, *, window: int = WINDOW) -> rrb.Blueprint:
    """The default layout of a run of several sources (:mod:`corraoi.recorder.rerun.sources`).

    Top: the regret of the run (the sum, near-black) and of each source (its colour), whole
    run, beside the channel occupancy (y: channel, a point per source and slot in the
    source's colour, red crosses where sources collided), the last ``window`` slots. Middle:
    a panel per source, its age against its oracle's (last ``window`` slots), in a grid of
    up to four columns. Bottom: each source's empirical means at the cursor (the sources'
    bars side by side over each arm, then the true mean's), and the run card.
    """
    M = config.sources
    v = SourcesViews(label, config, time_windows(window, config.horizon))
    W = VIEWER_PX
    columns = min(M, 4)
    root = rrb.Vertical(
        rrb.Horizontal(v.regret(W * 0.4), v.occupancy(W * 0.6), column_shares=[2, 3]),
        rrb.Grid(*v.ages(W / columns), grid_columns=columns),
        rrb.Horizontal(v.means(W * 0.8),
                       rrb.TextDocumentView(origin=f"{run_path(label)}/about", name="run"),
                       column_shares=[4, 1]),  # fmt: skip
        row_shares=[3.0, 2.0 if M <= columns else 3.0, 2.5],
    )
    return rrb.Blueprint(
        root,
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="hidden"),
    )


def run_blueprint(label: str, config: RunConfig, *, window: int = WINDOW) -> rrb.Blueprint:
    """The default layout of a run: :func:`one_run_blueprint`, or for a run of several
    sources :func:`sources_blueprint`."""
    if config.sources > 1:
        return sources_blueprint(label, config, window=window)
    return one_run_blueprint(label, config, window=window)


__all__ = [
    "VIEWER_PX",
    "WINDOW",
    "RunViews",
    "SourcesViews",
    "TimeWindows",
    "first_fit",
    "fit",
    "legend_room",
    "names_in_title",
    "one_run_blueprint",
    "run_blueprint",
    "sources_blueprint",
    "time_windows",
    "title_chars",
]
