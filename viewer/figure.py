"""The sweep figure: AoI regret against t, one line per policy with its 95% band.

Drawn from a sweep log alone (:func:`corraoi.recorder.sweeplog.log.read_sweep`), never by
simulating.
Style of the paper's figures, from :mod:`corraoi.recorder.style` (the colours of every view): a
line per policy in its base policy's colour, AoI-aware variants dashed in the same colour,
a shaded 95% confidence band, the legend outside the axes so that twelve curves never hide
behind it. ``split=True`` draws small multiples instead: the base policies beside their
AoI-aware forms, on a shared y axis. The format comes from the file's extension
(:data:`FORMATS`); anything else is one clear error. matplotlib is an optional extra
(``pip install 'corraoi[plot]'``) and is imported inside :func:`draw_figure` only; the
figure is drawn with the object-oriented API (no pyplot, no global backend switch).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from corraoi.errors import FigureUnavailable, UsageError
from corraoi.files.partial import PartialFile
from corraoi.policies import RGB
from corraoi.recorder.style import (
    DASH_AOI_AWARE,
    REGRET_UNIT,
    config_colors,
    is_aoi_aware,
    mpl,
    policy_color,
    rule_marker,
)
from corraoi.recorder.sweeplog.read import SweepCurve, SweepLog

#: Figure size in inches and resolution: 1500 x 900 pixels (split: 2100 x 900).
FIGSIZE = (10.0, 6.0)
FIGSIZE_SPLIT = (14.0, 6.0)
DPI = 150
#: Markers per curve of a multi-source rule that has them (recorder.style.RULE_MARKERS).
MARKS = 12
#: Legend entries that fit one column beside the axes, at the usual type and a smaller one.
LEGEND_ROWS = 24
LEGEND_ROWS_SMALL = 30
#: Resolutions ``--dpi`` accepts.
DPI_RANGE = (20, 1200)
#: Extensions a figure may have, and the matplotlib format each one means.
FORMATS = {
    "png": "png",
    "svg": "svg",
    "pdf": "pdf",
    "jpg": "jpg",
    "jpeg": "jpg",
    "webp": "webp",
    "tif": "tif",
    "tiff": "tif",
}
YLABEL = f"pathwise AoI regret  sum (aoi - oracle aoi)  {REGRET_UNIT}"
MISSING_MATPLOTLIB = "figures need matplotlib: pip install 'corraoi[plot]'"


def check_policies(sweep: SweepLog, policies: Sequence[str] | None) -> list[str]:
    """The policies to draw, in the order asked (all of the log's by default)."""
    if policies is None:
        return list(sweep.policies)
    chosen = [p.strip() for p in policies if p.strip()]
    if not chosen:
        raise UsageError("--policies: no policy named")
    unknown = [p for p in chosen if p not in sweep.curves]
    if unknown:
        present = ", ".join(sweep.policies) or "none"
        raise UsageError(
            f"{sweep.path}: no curve for {', '.join(unknown)} in this sweep log (it has: {present})"
        )
    return list(dict.fromkeys(chosen))


def figure_format(out: str | os.PathLike[str]) -> str:
    """The format of a figure file, from its extension; UsageError for any other."""
    suffix = Path(out).suffix.lower()
    fmt = FORMATS.get(suffix[1:]) if suffix else None
    if fmt is None:
        what = f"extension '{suffix}'" if suffix else "no extension"
        raise UsageError(
            f"{out}: cannot tell the figure format ({what}); expected a file name ending in "
            ".png, .svg, .pdf, .jpg, .webp or .tif"
        )
    return fmt


def check_dpi(dpi: int) -> int:
    lo, hi = DPI_RANGE
    if not lo <= dpi <= hi:
        raise UsageError(f"--dpi {dpi}: out of range, expected {lo}..{hi} dots per inch")
    return int(dpi)


def figure_title(sweep: SweepLog) -> str:
    runs, horizon = sweep.runs, sweep.horizon
    title = (
        f"AoI regret on {sweep.instance_name}: mean of {runs if runs is not None else '?'} runs "
        f"with 95% band, horizon T = {horizon if horizon is not None else '?'}"
    )
    if not sweep.complete:
        title += f" ({sweep.status})"
    return title


def draw_figure(
    sweep: SweepLog,
    out: str | os.PathLike[str],
    *,
    log_x: bool = False,
    log_y: bool = False,
    dpi: int = DPI,
    split: bool = False,
    policies: Sequence[str] | None = None,
) -> Path:
    """Draw the regret figure of ``sweep`` to ``out`` (format from its extension).

    ``log_y`` uses a symmetric log scale (linear within +-1 slot-age: pathwise regret can
    be 0 or negative early on); ``split`` draws the base policies and their AoI-aware
    forms side by side. Raises :class:`FigureUnavailable` without matplotlib,
    ``UsageError`` for an unknown extension, a bad ``dpi``, policies the log does not
    hold or a log without points. The file is written as ``<out>.partial`` and renamed
    into place.
    """
    out = Path(out)
    fmt = figure_format(out)
    dpi = check_dpi(dpi)
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise FigureUnavailable(MISSING_MATPLOTLIB) from None

    names = check_policies(sweep, policies)
    curves = [sweep.curves[n] for n in names if len(sweep.curves[n])]
    if not curves:
        raise UsageError(f"{sweep.path}: the sweep log holds no points to draw")
    groups = [curves]
    if split:
        base = [c for c in curves if not is_aoi_aware(c.policy)]
        aware = [c for c in curves if is_aoi_aware(c.policy)]
        groups = [g for g in (base, aware) if g]
    fig = Figure(figsize=FIGSIZE_SPLIT if len(groups) > 1 else FIGSIZE, dpi=dpi,
                 layout="constrained")  # fmt: skip
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(groups), sharey=True, squeeze=False)[0]
    colors = config_colors(sweep.config)
    for c in curves:
        colors.setdefault(c.policy, policy_color(c.policy))
    for i, (ax, group) in enumerate(zip(axes, groups, strict=True)):
        _draw_curves(ax, group, len(curves), colors)
        if len(groups) > 1:
            ax.set_title("AoI-aware forms" if is_aoi_aware(group[0].policy) else "policies",
                         fontsize=10)  # fmt: skip
        if log_x:
            ax.set_xscale("log")
        else:
            ax.set_xlim(left=0)
        if log_y:
            ax.set_yscale("symlog", linthresh=1.0)
        ax.set_xlabel("slot t (log scale)" if log_x else "slot t")
        if i == 0:
            ax.set_ylabel(YLABEL + ("  (symmetric log scale)" if log_y else ""))
        ax.grid(True, which="major", alpha=0.3, linewidth=0.6)
        ax.spines[["top", "right"]].set_visible(False)
    _legend(axes[-1], curves, colors)
    if len(groups) > 1:
        fig.suptitle(figure_title(sweep), fontsize=11)
    else:
        axes[0].set_title(figure_title(sweep), fontsize=11)

    # the recorder's locked .partial: a second writer of the same figure (another sweep
    # resuming this folder, say) is refused by name instead of renaming ours away
    with PartialFile(out, overwrite=True, what="figure") as target:  # discarded on error
        fig.savefig(target.file, format=fmt, metadata=_metadata(fmt))
    return out


def _draw_curves(ax: Any, curves: Sequence[SweepCurve], total: int, colors: dict[str, RGB]) -> None:
    """One line per curve with its shaded band (fainter bands as curves are added, so
    twelve overlapping bands stay readable)."""
    alpha = 0.2 if total <= 4 else 0.13 if total <= 8 else 0.09
    for c in curves:
        rgb = mpl(colors[c.policy])
        dashed = is_aoi_aware(c.policy)
        t = c.t.astype(np.float64)
        ax.plot(
            t,
            c.regret_mean,
            color=rgb,
            linestyle=DASH_AOI_AWARE if dashed else "-",
            linewidth=1.6,
            label=c.policy,
            zorder=3,
            marker=rule_marker(c.policy) or None,
            markevery=max(1, len(t) // MARKS),
            markersize=4.5,
        )
        band = np.isfinite(c.regret_ci95)
        if band.any():
            ax.fill_between(
                t,
                c.regret_mean - c.regret_ci95,
                c.regret_mean + c.regret_ci95,
                where=band,
                color=rgb,
                alpha=alpha * (0.7 if dashed else 1.0),
                linewidth=0,
                zorder=2,
            )


def _legend(ax: Any, curves: Sequence[SweepCurve], colors: dict[str, RGB]) -> None:
    """Every policy's entry, the band and the dash, outside the axes on the right."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list[object] = [
        Line2D([], [], color=mpl(colors[c.policy]), linewidth=1.6, label=c.policy,
               linestyle=DASH_AOI_AWARE if is_aoi_aware(c.policy) else "-",
               marker=rule_marker(c.policy) or None, markersize=4.5)
        for c in curves
    ]  # fmt: skip
    handles.append(Patch(facecolor=(0.5, 0.5, 0.5), alpha=0.3, label="95% confidence band"))
    if any(is_aoi_aware(c.policy) for c in curves):
        handles.append(
            Line2D([], [], color="0.3", linestyle=DASH_AOI_AWARE, label="dashed: AoI-aware variant")
        )
    # a long legend (reproduce decentralized: 48 curves) in columns of a smaller type: one
    # column of them was taller than the figure and squeezed the axes to a strip
    many = len(handles) > LEGEND_ROWS
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        borderaxespad=0.0,
        fontsize=7.5 if many else 9,
        ncols=-(-len(handles) // LEGEND_ROWS_SMALL) if many else 1,
        frameon=False,
        title="policy",
        title_fontsize=9,
    )


def _metadata(fmt: str) -> dict[str, str | None] | None:
    """Reproducible files: no creation date, no version string where the format has one
    (the Pillow-written formats take no metadata)."""
    if fmt == "png":
        return {"Software": None}
    if fmt == "pdf":
        return {"Creator": None, "Producer": None, "CreationDate": None}
    if fmt == "svg":
        return {"Creator": None, "Date": None}
    return None


__all__ = [
    "FORMATS",
    "MISSING_MATPLOTLIB",
    "check_dpi",
    "check_policies",
    "draw_figure",
    "figure_format",
]
