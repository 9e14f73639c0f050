"""The names and the layout of a sweep's Rerun recording: entity paths, recording id and the
default blueprint.

Entities (timeline ``slot``, a sequence; arms numbered from 1):

* ``sweep/regret/<policy>``: mean pathwise AoI regret at each checkpoint;
  ``sweep/regret/<policy>/lo`` and ``.../hi``: the 95% confidence band (mean -/+ half-width;
  absent with a single run), thin lines in a lighter shade of the policy's colour;
* ``sweep/estimator/<policy>``: the paper's estimator sum aoi - t / mu*;
* ``sweep/collisions/<policy>``: a sweep with a cell of several sources: the mean
  collisions up to t of each run, summed over its sources (a tab beside the estimator);
* ``sweep/pulls/<policy>/<arm>``: mean share of pulls of that arm up to t; up to
  ``style.LINES_UP_TO`` arms each arm's line is thinner than the one before, so that
  shares that coincide show both colours (a thin line inside a wide one);
* ``sweep/share/<policy>``: beyond ``style.LINES_UP_TO`` arms, the shares of every arm at
  each checkpoint as a bar chart (the pull shares at the time cursor); the lines are then
  drawn for the arms that matter only (:func:`corraoi.recorder.style.arms_that_matter`).

The recording is named after its folder and instance (:func:`sweep_recording_name`), as
the viewer lists it.


:func:`sweep_blueprint` is the default layout: the regret overlay on top, the pulls per arm
of each policy in tabs below. :class:`corraoi.recorder.sweeplog.recording.SweepRerunSink` sends the
data.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from corraoi.recorder import style
from corraoi.recorder.rerun.names import TIMELINE
from corraoi.recorder.style import REGRET_UNIT, is_aoi_aware
from corraoi.stats import CELL_RUNS

ROOT = "sweep"
#: More policies than this: the regret view opens as small multiples (base policies beside
#: their AoI-aware forms), each legend short enough to fit.
SMALL_MULTIPLES_FROM = 6


def entity_part(name: str) -> str:
    """``name`` escaped as one entity path part."""
    return rr.escape_entity_path_part(name)


def regret_path(policy: str) -> str:
    return f"{ROOT}/regret/{entity_part(policy)}"


def estimator_path(policy: str) -> str:
    return f"{ROOT}/estimator/{entity_part(policy)}"


def collisions_path(policy: str) -> str:
    """``sweep/collisions/<policy>``: the mean collisions of a cell of several sources."""
    return f"{ROOT}/collisions/{entity_part(policy)}"


def pulls_path(policy: str, arm: int | None = None) -> str:
    """``sweep/pulls/<policy>`` or, with ``arm`` (numbered from 1), one arm's entity."""
    base = f"{ROOT}/pulls/{entity_part(policy)}"
    return base if arm is None else f"{base}/{arm}"


def share_path(policy: str) -> str:
    """``sweep/share/<policy>``: the pull shares at each checkpoint as a bar chart."""
    return f"{ROOT}/share/{entity_part(policy)}"


def shown_arms(config: dict[str, Any]) -> list[int]:
    """The arms (0-based) whose pull-share lines the layout shows: every arm up to
    ``style.LINES_UP_TO``, else the arms that matter."""
    from corraoi.model.instance import Instance
    from corraoi.model.theory import analyse

    inst = config.get("instance") or {}
    K = len(inst.get("Y") or [])
    if style.lines_for(K):
        return list(range(K))
    th = analyse(Instance.from_dict(inst, where="sweep"))
    return style.arms_that_matter(th.mu, th.best_arm, th.competitive)


def sweep_recording_name(path: str | os.PathLike[str], config: dict[str, Any]) -> str:
    """What the viewer lists a sweep recording as: ``<folder>: <instance> sweep, <runs>
    runs, T = <horizon>``, the folder first (the recording list shows the start of a name;
    a group's sub-folder named after the instance is shown with the sweep folder above)."""
    from corraoi.text import safe_text

    folder = Path(path).resolve().parent
    inst = str((config.get("instance") or {}).get("name", "?"))
    shown = folder.name if folder.name != inst else f"{folder.parent.name}/{folder.name}"
    return safe_text(f"{shown}: {inst} sweep, {config.get('runs', '?')} runs, "
                     f"T = {config.get('horizon', '?')}")  # fmt: skip


def policy_names(config: dict[str, Any]) -> list[str]:
    return [p["name"] if isinstance(p, dict) else str(p) for p in config.get("policies", [])]


def sweep_recording_id(config: dict[str, Any]) -> str:
    """A recording id that depends on the sweep configuration only."""
    digest = hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()
    return f"corraoi-sweep-{digest[:16]}"


def sweep_blueprint(config: dict[str, Any]) -> rrb.Blueprint:
    """The default layout: the regret overlay (and estimator tab), pulls per policy below."""
    inst = config.get("instance") or {}
    title = (
        f"AoI regret {REGRET_UNIT}, {inst.get('name', '?')}: {config.get('runs', '?')} runs, "
        "mean and 95% band"
    )
    from corraoi.recorder.rerun.layout import LEGEND, VIEWER_PX, legend_room, time_windows

    horizon = config.get("horizon")
    names = policy_names(config)
    # the whole horizon, not a window around the time cursor, and room right of it for the
    # legend (corraoi.recorder.rerun.layout's rule): the policies' names, or the arms'
    tw = time_windows(1, horizon if isinstance(horizon, int) and horizon > 0 else None)
    axis = tw.whole_axis(legend_room(names, VIEWER_PX))
    legend = LEGEND
    arm_names = list((config.get("instance") or {}).get("arms") or [])
    # the runs worth watching (SweepRerunSink.mark) have a tab of their own: one worst run
    # of 1,400 would flatten means of 20 in the overlay
    notable = [p for p in names if p in ((config.get("notable") or {}).get("cells") or {})]
    hidden = [f"- {regret_path(p)}/{k}" for p in notable for k in CELL_RUNS]
    overlay = rrb.TimeSeriesView(
        origin=f"{ROOT}/regret", contents=[f"+ {ROOT}/regret/**", *hidden], name=title,
        plot_legend=legend, axis_x=axis,
    )  # fmt: skip
    first: list[rrb.Container | rrb.View] = [overlay]
    base = [p for p in names if not is_aoi_aware(p)]
    aware = [p for p in names if is_aoi_aware(p)]
    if len(names) > SMALL_MULTIPLES_FROM and base and aware:
        # too many curves for one legend: the base policies beside their AoI-aware forms
        # (same colours), the overlay of all in the next tab
        def group(members: list[str], what: str) -> rrb.TimeSeriesView:
            return rrb.TimeSeriesView(
                origin=f"{ROOT}/regret",
                contents=[*(f"+ {regret_path(p)}/**" for p in members), *hidden],
                name=f"AoI regret {REGRET_UNIT}, {what}",
                plot_legend=legend,
                axis_x=axis,
            )

        first = [
            rrb.Horizontal(group(base, "policies"), group(aware, "AoI-aware forms"),
                           name=f"{title}: policies | AoI-aware forms"),
            overlay,
        ]  # fmt: skip
    top = rrb.Tabs(
        *first,
        rrb.TimeSeriesView(
            origin=f"{ROOT}/estimator",
            name=f"estimator sum aoi - t / mu* {REGRET_UNIT}",
            plot_legend=legend,
            axis_x=axis,
        ),
        *([rrb.TimeSeriesView(origin=f"{ROOT}/collisions", plot_legend=legend, axis_x=axis,
                              name="collisions (mean over runs, summed over the sources)")]
          if config.get("sources") else []),
        *([rrb.Grid(*(rrb.TimeSeriesView(origin=regret_path(p), axis_x=axis, plot_legend=legend,
                                         name=f"{p}: mean, worst, median, best run"
                                         + (", most collisions" if config.get("sources")
                                            else ""))
                      for p in notable), name="runs worth watching")] if notable else []),
        active_tab=0,
    )  # fmt: skip
    arms = shown_arms(config)
    K = len((config.get("instance") or {}).get("Y") or [])
    arm_names += [str(k + 1) for k in range(len(arm_names), K)]
    shares_axis = tw.whole_axis(legend_room(
        [style.arm_legend(k, arm_names[k]) for k in arms],
        VIEWER_PX if style.lines_for(K) else VIEWER_PX / 2,
    ))  # fmt: skip
    # tab titles share the width: the policy's name, with the quantity while there is room
    few = len(names) <= 4

    def pulls_view(p: str) -> rrb.View | rrb.Container:
        lines = rrb.TimeSeriesView(
            origin=pulls_path(p),
            contents=[f"$origin/{k + 1}" for k in arms],
            name=f"pull share {style.SHARE_UNIT}, {p}" if few else p,
            axis_x=shares_axis,
            plot_legend=legend,
        )
        if style.lines_for(K):
            return lines
        return rrb.Horizontal(
            rrb.BarChartView(origin=share_path(p), name=f"{p}: pull share of every arm at "
                             "the cursor", plot_legend=rrb.PlotLegend(visible=False)),
            rrb.TimeSeriesView(origin=pulls_path(p), contents=[f"$origin/{k + 1}" for k in arms],
                               name=f"{p}: pull share, arms that matter", axis_x=shares_axis,
                               plot_legend=legend),
            name=f"pull share {style.SHARE_UNIT}, {p}" if few else p,
        )  # fmt: skip

    pulls = [pulls_view(p) for p in names]
    parts: list[rrb.Container | rrb.View] = [top]
    if pulls:
        parts.append(rrb.Tabs(*pulls, active_tab=0, name="pull share per arm"))
    return rrb.Blueprint(
        rrb.Vertical(*parts, row_shares=[3, 2] if pulls else None),
        # the recording list (where its name shows) open, the time panel as a scrubber
        rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
        rrb.SelectionPanel(state="hidden"),
    )


__all__ = [
    "ROOT",
    "SMALL_MULTIPLES_FROM",
    "collisions_path",
    "entity_part",
    "estimator_path",
    "policy_names",
    "pulls_path",
    "regret_path",
    "share_path",
    "shown_arms",
    "sweep_blueprint",
    "sweep_recording_id",
    "sweep_recording_name",
]
