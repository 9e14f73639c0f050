"""The names and the layout of a sweep's Rerun recording: entity paths, recording id and the
default blueprint.

Entities (timeline ``slot``, a sequence; arms numbered from 1):

* ``sweep/regret/<policy>``: mean pathwise AoI regret at each checkpoint;
  ``sweep/regret/<policy>/lo`` and ``.../hi``: the 95% confidence band (mean -/+ half-width;
  absent with a single run), thin lines in a lighter shade of the policy's colour;
* ``sweep/estimator/<policy>``: the paper's estimator sum aoi - t / mu*;
* ``sweep/pulls/<policy>/<arm>``: mean share of pulls of that arm up to t.


:func:`sweep_blueprint` is the default layout: the regret overlay on top, the pulls per arm
of each policy in tabs below. :class:`recorder.sweeplog.recording.SweepRerunSink` sends the data.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from recorder.rerun.names import TIMELINE
from recorder.style import REGRET_UNIT, is_aoi_aware

ROOT = "sweep"
#: More policies than this: the regret view opens as small multiples (base policies beside
#: their AoI-aware forms), each legend short enough to fit.
SMALL_MULTIPLES_FROM = 6
#: The named runs of a cell drawn over its mean (corraoi.experiments.notable).
NOTABLE_KINDS = ("worst", "median", "best")


def entity_part(name: str) -> str:
    """``name`` escaped as one entity path part."""
    return rr.escape_entity_path_part(name)


def regret_path(policy: str) -> str:
    return f"{ROOT}/regret/{entity_part(policy)}"


def estimator_path(policy: str) -> str:
    return f"{ROOT}/estimator/{entity_part(policy)}"


def pulls_path(policy: str, arm: int | None = None) -> str:
    """``sweep/pulls/<policy>`` or, with ``arm`` (numbered from 1), one arm's entity."""
    base = f"{ROOT}/pulls/{entity_part(policy)}"
    return base if arm is None else f"{base}/{arm}"


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
    horizon = config.get("horizon")
    # The whole horizon, not a window around the time cursor.
    axis = (
        rrb.TimeAxis(
            view_range=rrb.TimeRange(
                start=rrb.TimeRangeBoundary.absolute(seq=0),
                end=rrb.TimeRangeBoundary.absolute(seq=int(horizon)),
            )
        )
        if isinstance(horizon, int) and horizon > 0
        else None
    )
    legend = rrb.PlotLegend(corner=rrb.components.Corner2D.LeftTop)
    names = policy_names(config)
    # the runs worth watching (SweepRerunSink.mark) have a tab of their own: one worst run
    # of 1,400 would flatten means of 20 in the overlay
    notable = [p for p in names if p in ((config.get("notable") or {}).get("cells") or {})]
    hidden = [f"- {regret_path(p)}/{k}" for p in notable for k in NOTABLE_KINDS]
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
        *([rrb.Grid(*(rrb.TimeSeriesView(origin=regret_path(p), axis_x=axis, plot_legend=legend,
                                         name=f"{p}: mean, worst, median, best run")
                      for p in notable), name="runs worth watching")] if notable else []),
        active_tab=0,
    )  # fmt: skip
    pulls = [
        rrb.TimeSeriesView(
            origin=pulls_path(p),
            name=f"pull share per arm [fraction], {p}",
            axis_x=axis,
            plot_legend=legend,
        )  # fmt: skip
        for p in names
    ]
    parts: list[rrb.Container | rrb.View] = [top]
    if pulls:
        parts.append(rrb.Tabs(*pulls, active_tab=0, name="pull share per arm"))
    return rrb.Blueprint(
        rrb.Vertical(*parts, row_shares=[3, 2] if pulls else None),
        rrb.TimePanel(timeline=TIMELINE),
        collapse_panels=False,
    )


__all__ = [
    "NOTABLE_KINDS",
    "ROOT",
    "SMALL_MULTIPLES_FROM",
    "entity_part",
    "estimator_path",
    "policy_names",
    "pulls_path",
    "regret_path",
    "sweep_blueprint",
    "sweep_recording_id",
]
