"""The sweep figure: AoI regret against t, one line per policy with its 95% band.

Drawn from a sweep log alone (:func:`recorder.sweep_log.read_sweep`), never by simulating.
Style of the paper's figures: a line per policy in its base policy's colour
(:data:`recorder.sweep_log.POLICY_COLORS`), AoI-aware variants dashed in the same colour, a
shaded 95% confidence band, the legend outside the axes. matplotlib is an optional extra
(``pip install 'corraoi[plot]'``) and is imported inside :func:`draw_figure` only; the
figure is drawn with the object-oriented API (no pyplot, no global backend switch).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from corraoi.errors import CorraoiError, UsageError
from recorder.sweep_log import SweepLog, is_aoi_aware, policy_color

#: Figure size in inches and resolution: 1500 x 900 pixels.
FIGSIZE = (10.0, 6.0)
DPI = 150
MISSING_MATPLOTLIB = "figures need matplotlib: pip install 'corraoi[plot]'"
_PARTIAL = ".partial"


class FigureUnavailable(CorraoiError):
    """matplotlib is not installed: the figure cannot be drawn (the logs are fine)."""

    exit_code = 1


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
    policies: Sequence[str] | None = None,
) -> Path:
    """Draw the regret figure of ``sweep`` to ``out`` (format from its suffix, PNG default).

    Raises :class:`FigureUnavailable` without matplotlib, ``UsageError`` for policies the
    log does not hold or a log without points. The file is written as ``<out>.partial``
    and renamed into place.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
        from matplotlib.lines import Line2D
        from matplotlib.patches import Patch
    except ImportError:
        raise FigureUnavailable(MISSING_MATPLOTLIB) from None

    names = check_policies(sweep, policies)
    curves = [sweep.curves[n] for n in names if len(sweep.curves[n])]
    if not curves:
        raise UsageError(f"{sweep.path}: the sweep log holds no points to draw")
    out = Path(out)
    fmt = (out.suffix[1:] or "png").lower()
    fig = Figure(figsize=FIGSIZE, dpi=DPI, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    if fmt not in canvas.get_supported_filetypes():
        known = ", ".join(sorted(canvas.get_supported_filetypes()))
        raise UsageError(f"{out}: cannot write a .{fmt} figure (known: {known})")

    ax = fig.add_subplot()
    # Fainter bands as curves are added, so twelve overlapping bands stay readable.
    alpha = 0.2 if len(curves) <= 4 else 0.13 if len(curves) <= 8 else 0.09
    handles: list[object] = []
    for c in curves:
        rgb = tuple(v / 255 for v in policy_color(c.policy))
        dashed = is_aoi_aware(c.policy)
        t = c.t.astype(np.float64)
        (line,) = ax.plot(
            t,
            c.regret_mean,
            color=rgb,
            linestyle=(0, (5, 2.5)) if dashed else "-",
            linewidth=1.6,
            label=c.policy,
            zorder=3,
        )
        handles.append(line)
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
    handles.append(Patch(facecolor=(0.5, 0.5, 0.5), alpha=0.3, label="95% confidence band"))
    if any(is_aoi_aware(c.policy) for c in curves):
        handles.append(
            Line2D([], [], color="0.3", linestyle=(0, (5, 2.5)), label="dashed: AoI-aware variant")
        )
    ax.legend(
        handles=handles,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        borderaxespad=0.0,
        fontsize=9,
        frameon=False,
        title="policy",
        title_fontsize=9,
    )
    if log_x:
        ax.set_xscale("log")
    else:
        ax.set_xlim(left=0)
    ax.set_xlabel("slot t (log scale)" if log_x else "slot t")
    ax.set_ylabel("pathwise AoI regret  sum (aoi - oracle aoi)  [slots]")
    ax.set_title(figure_title(sweep), fontsize=11)
    ax.grid(True, which="major", alpha=0.3, linewidth=0.6)
    ax.spines[["top", "right"]].set_visible(False)

    part = out.with_name(out.name + _PARTIAL)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with open(part, "wb") as f:
            fig.savefig(f, format=fmt, metadata=_metadata(fmt))
        os.replace(part, out)
    except BaseException:
        with contextlib.suppress(OSError):
            part.unlink()
        raise
    return out


def _metadata(fmt: str) -> dict[str, str | None]:
    """Reproducible files: no creation date, no version string where the format has one."""
    if fmt == "png":
        return {"Software": None}
    if fmt == "pdf":
        return {"Creator": None, "Producer": None, "CreationDate": None}
    if fmt == "svg":
        return {"Creator": None, "Date": None}
    return {}


__all__ = ["FigureUnavailable", "MISSING_MATPLOTLIB", "check_policies", "draw_figure"]
