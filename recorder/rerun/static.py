"""The static data of one run's Rerun recording, logged once before its slots: how every
entity looks (names, colours, markers; :mod:`recorder.style` owns them) and the ``about``
note (the run configuration as markdown).

rerun-sdk 0.41 has no axis titles: units are in the view titles and series names.
"""

from __future__ import annotations

from typing import Any

import rerun as rr

from corraoi.engine.block import RunConfig
from corraoi.model.theory import analyse
from recorder import style


def _arm_names(config: RunConfig) -> list[str]:
    return [style.arm_label(k, name) for k, name in enumerate(config.instance.arm_names)]


def about_markdown(config: RunConfig) -> str:
    """The run configuration as markdown (the ``about`` entity and the blueprint's note)."""
    inst = config.instance
    th = analyse(inst)
    params = ", ".join(f"{k}={v:g}" for k, v in config.policy.params.items()) or "none"
    lines = [
        f"## {config.label}",
        "",
        f"policy **{config.policy.name}** ({params}), instance **{inst.name}**, "
        f"seed {config.seed}, horizon {config.horizon}, corraoi {config.version}",
        "",
        "| arm | Y(x) | mu | role |",
        "|---|---|---|---|",
    ]
    for k in range(inst.K):
        row = " ".join(str(int(v)) for v in inst.Y[k])
        if k == th.best_arm:
            role = "best (k*)"
        elif k in th.competitive:
            role = "competitive"
        else:
            role = "non-competitive"
        lines.append(f"| {_arm_names(config)[k]} | {row} | {th.mu[k]:.4g} | {role} |")
    p = "  ".join(f"{s}={v:g}" for s, v in zip(inst.state_names, inst.p, strict=True))
    lines += [
        "",
        f"p: {p}",
        "",
        "Arms and states are numbered from 1. AoI and regret are in slots; the regret is "
        "the pathwise sum (aoi - oracle_aoi), the oracle playing k* on the same hidden path.",
    ]
    return "\n".join(lines)


def log_static(rec: rr.RecordingStream, base: str, config: RunConfig, color: style.RGB) -> None:
    """Log the static styling of the entities under ``base`` and the ``about`` note.

    They go with ``send_columns`` without a time index (static data), like the slots:
    ``rr.log`` would queue them in Rerun's batcher, whose timer could let a first
    batch of slots reach the file before them, and two recordings of one run would
    then differ in the order of their chunks.
    """
    st = style
    K = config.instance.K
    names = _arm_names(config)
    colors = [st.arm_color(k) for k in range(K)]

    def static(path: str, columns: Any, count: int = 1) -> None:
        rec.send_columns(f"{base}/{path}", indexes=[], columns=columns.partition([count]))

    def lines(path: str, rgb: list[Any], name: list[str], width: list[float]) -> None:
        static(path, rr.SeriesLines.columns(colors=rgb, widths=width, names=name), len(rgb))

    def points(path: str, rgb: Any, name: str, marker: Any, size: float) -> None:
        static(path, rr.SeriesPoints.columns(colors=[rgb], names=[name], markers=[marker],
                                             marker_sizes=[size]))  # fmt: skip

    shape = rr.components.MarkerShape
    lines("aoi", [color], [st.AOI_NAME], [st.WIDTH_MAIN])
    # the oracle: another colour AND another line style (dotted: a point per slot, no
    # line, since Rerun 0.41 lines cannot be dashed), named
    points("oracle_aoi", st.ORACLE_COLOR, st.ORACLE_NAME, shape.Circle, st.MARKER_ORACLE)
    lines("regret", [color], [st.REGRET_NAME], [st.WIDTH_MAIN])
    lines("estimator", [st.lighter(color, 0.5)], [st.ESTIMATOR_NAME], [st.WIDTH_SECONDARY])
    points("arm/success", st.SUCCESS_COLOR, st.SUCCESS_NAME, shape.Circle, st.MARKER_SUCCESS)
    points("arm/failure", st.FAILURE_COLOR, st.FAILURE_NAME, shape.Cross, st.MARKER_FAILURE)
    points("override", st.OVERRIDE_COLOR, st.OVERRIDE_NAME, shape.Diamond, st.MARKER_OVERRIDE)
    points("x", st.STATE_COLOR, st.STATE_NAME, shape.Square, st.MARKER_STATE)
    arms = range(K)
    lines("mu_hat", colors, [st.mean_name(k, true=False) for k in arms], [st.WIDTH_ARM] * K)
    lines("mu_true", [st.true_mean_color(k) for k in arms],
          [st.mean_name(k, true=True) for k in arms], [st.WIDTH_TRUE_MEAN] * K)
    lines("pulls", colors, names, [st.WIDTH_ARM] * K)  # fmt: skip
    for k in arms:
        points(f"candidates/{k + 1}", colors[k], names[k], shape.Square, st.MARKER_CANDIDATE)
    static("about", rr.TextDocument.columns(text=[about_markdown(config)],
                                            media_type=[rr.MediaType.MARKDOWN]))  # fmt: skip


__all__ = ["about_markdown", "log_static"]
