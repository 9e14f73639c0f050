"""The static data of one run's Rerun recording, logged once before its slots: how every
entity looks (names, colours, markers; :mod:`corraoi.recorder.style` owns them) and the ``about``
note, the run card (the run configuration, its arms and what the views show, as markdown).

rerun-sdk 0.41 has no axis titles: units are in the view titles and series names.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from corraoi.engine.block import RunConfig
from corraoi.recorder import style

#: Bars of the per-arm bar charts: width, and the offset of the empirical (left) and true
#: (right) bar from the arm's number.
BAR_WIDTH = 0.46
BAR_OFFSET = 0.25
#: States whose Y row the run card still spells out as 0/1 digits.
CARD_Y_STATES = 16
#: States the run card still lists with their names and probabilities.
CARD_STATES = 12


def _legend_names(config: RunConfig) -> list[str]:
    return [style.arm_legend(k, name) for k, name in enumerate(config.arm_names)]


def about_markdown(config: RunConfig) -> str:
    """The run card (the ``about`` entity): the configuration, every arm by its whole name
    with its mean, Y row and role, the hidden states, and (beyond ``style.LINES_UP_TO``
    arms) what the bars show. Short lines and a list, which wrap to the panel's width (a
    table does not), so that the card fits its panel."""
    inst, th = config.instance, config.theory
    K = config.K
    params = ", ".join(f"{k}={v:g}" for k, v in config.policy.params.items())
    policy = _md(config.policy.name) + (f" ({params})" if params else "")
    if inst is None or th is None:  # a loop logged without an instance: no p, Y or means
        return "\n".join([
            f"**{_md(config.label)}**", "",
            f"{policy}: {K} arms, no instance (p and Y unknown: no hidden state, oracle "
            f"or regret); seed {config.seed}, {config.horizon} slots",
        ])  # fmt: skip
    n = inst.n_states
    lines = [
        f"**{_md(config.label)}**",
        "",
        f"{policy} on {_md(inst.name)}: {K} arms, {n} states; seed {config.seed}, "
        f"{config.horizon} slots",
        "",
    ]

    def arm_line(k: int) -> str:
        name = inst.arm_names[k]
        who = f"**arm {k + 1}**" if name == str(k + 1) else f"**{k + 1}** {_md(name)}"
        parts = [who, f"mu {th.mu[k]:.3g}"]
        if n <= CARD_Y_STATES:
            parts.append("Y " + "".join(str(int(v)) for v in inst.Y[k]))
        if k == th.best_arm:
            parts.append("**best k\\***")
        elif k in th.competitive:
            parts.append("competitive")
        return "- " + " · ".join(parts)

    if style.lines_for(K):
        lines += [arm_line(k) for k in range(K)]
    else:
        shown = style.arms_that_matter(th.mu, th.best_arm, th.competitive)
        lines += [arm_line(k) for k in shown]
        if any(name != str(k + 1) for k, name in enumerate(inst.arm_names)):
            every = " · ".join(f"{k + 1} {_md(name)}" for k, name in enumerate(inst.arm_names))
            lines += ["", f"All {K} arms: {every}"]
    if n <= CARD_STATES:
        states = " · ".join(
            f"{x + 1}" + ("" if name == f"x{x + 1}" else f" {_md(name)}") + f" {p:.2g}"
            for x, (name, p) in enumerate(zip(inst.state_names, inst.p, strict=True))
        )
        lines += ["", f"States (p): {states}"]
    if not style.lines_for(K):
        lines += ["", "Bars: the values at the time cursor; an arm that matters in its "
                      "colour, the others grey. Means: empirical left (mid grey: in the "
                      "candidate set, light: out of it), true right (dark)."]
    return "\n".join(lines)


def _md(text: str) -> str:
    """A name as markdown text, whole: control characters escaped, white space made one
    space, markdown's own characters escaped."""
    out = style.shorten(text, 10**6)
    for ch in "\\`*_[]<>|#":
        out = out.replace(ch, "\\" + ch)
    return out


def log_static(rec: rr.RecordingStream, base: str, config: RunConfig, color: style.RGB) -> None:
    """Log the static styling of the entities under ``base`` and the ``about`` note.

    They go with ``send_columns`` without a time index (static data), like the slots:
    ``rr.log`` would queue them in Rerun's batcher, whose timer could let a first
    batch of slots reach the file before them, and two recordings of one run would
    then differ in the order of their chunks.
    """
    st = style
    K = config.K
    names = _legend_names(config)
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
    lines("estimator", [st.REFERENCE_COLOR], [st.ESTIMATOR_NAME], [st.WIDTH_SECONDARY])
    points("arm/success", st.SUCCESS_COLOR, st.SUCCESS_NAME, shape.Circle, st.MARKER_SUCCESS)
    points("arm/failure", st.FAILURE_COLOR, st.FAILURE_NAME, shape.Cross, st.MARKER_FAILURE)
    theory = config.theory  # None without an instance: no best arm, no true means
    if theory is not None:
        best = int(theory.best_arm)
        lines("arm/best", [st.REFERENCE_COLOR], [st.best_arm_name(best)], [st.WIDTH_REFERENCE])
    points("override", st.OVERRIDE_COLOR, st.OVERRIDE_NAME, shape.Diamond, st.MARKER_OVERRIDE)
    points("x", st.STATE_COLOR, st.STATE_NAME, shape.Square, st.MARKER_STATE)
    arms = range(K)
    lines("mu_hat", colors, names, [st.WIDTH_ARM] * K)
    if theory is not None:
        lines("mu_true", colors, names, [st.WIDTH_TRUE_MEAN] * K)
    lines("pulls", colors, names, [st.WIDTH_ARM] * K)
    if st.lines_for(K):
        for k in arms:
            points(f"candidates/{k + 1}", colors[k], names[k], shape.Square, st.MARKER_CANDIDATE)
            log_true_mean(rec, base, config, k, colors[k])
    else:
        # beyond LINES_UP_TO arms the rows are grey; an arm that matters gets its colour
        # when it comes to (log_focus)
        for k in arms:
            points(f"candidates/{k + 1}", st.BAR_IN_SET_COLOR, names[k], shape.Square,
                   st.MARKER_CANDIDATE)  # fmt: skip
        arm = np.arange(1, K + 1, dtype=np.float64)
        bars(rec, f"{base}/bars/mean", st.BAR_IN_SET_COLOR, arm - BAR_OFFSET)
        bars(rec, f"{base}/bars/mean_other", st.BAR_OUT_COLOR, arm - BAR_OFFSET)
        if theory is not None:
            mu = np.asarray(theory.mu, dtype=np.float64)
            bars(rec, f"{base}/bars/mean_true", st.BAR_TRUE_COLOR, arm + BAR_OFFSET, values=mu)
        bars(rec, f"{base}/bars/pulls", st.BAR_IN_SET_COLOR, arm, width=2 * BAR_WIDTH)
    static("about", rr.TextDocument.columns(text=[about_markdown(config)],
                                            media_type=[rr.MediaType.MARKDOWN]))  # fmt: skip


def log_why_static(rec: rr.RecordingStream, base: str, config: RunConfig, color: style.RGB,
                   *, threshold: bool) -> None:  # fmt: skip
    """The styling of the "why this arm" entities (``why/``), logged when the first block
    that has scores arrives (a run without them has none of these entities):
    ``threshold`` when the run logs the AoI-aware rule's threshold."""
    st = style
    K = config.K
    names = [f"{n} {st.SCORE_UNIT}" if i == 0 else n for i, n in enumerate(_legend_names(config))]
    shape = rr.components.MarkerShape

    def static(path: str, columns: Any, count: int = 1) -> None:
        rec.send_columns(f"{base}/{path}", indexes=[], columns=columns.partition([count]))

    def points(path: str, rgb: Any, name: str, marker: Any, size: float) -> None:
        static(path, rr.SeriesPoints.columns(colors=[rgb], names=[name], markers=[marker],
                                             marker_sizes=[size]))  # fmt: skip

    if st.lines_for(K):  # one entity, a series per arm (as mu_hat)
        static("why/score", rr.SeriesLines.columns(
            colors=[st.arm_color(k) for k in range(K)], names=names,
            widths=[st.WIDTH_ARM] * K), K)  # fmt: skip
    else:
        arm = np.arange(1, K + 1, dtype=np.float64)
        bars(rec, f"{base}/why/bars/score", st.BAR_IN_SET_COLOR, arm,
             width=2 * BAR_WIDTH)  # fmt: skip
        bars(rec, f"{base}/why/bars/chosen", color, arm, width=max(2 * BAR_WIDTH, K / 64))
    chosen = st.CHOSEN_BELOW_NAME if st.lines_for(K) else st.CHOSEN_NAME
    points("why/chosen", color, chosen, shape.Circle, st.MARKER_CHOSEN)
    points("why/forced", st.FORCED_COLOR, st.FORCED_NAME, shape.Asterisk, st.MARKER_FORCED)
    if threshold:
        static("why/threshold", rr.SeriesLines.columns(
            colors=[st.OVERRIDE_COLOR], names=[st.THRESHOLD_NAME],
            widths=[st.WIDTH_SECONDARY]))  # fmt: skip


def log_why_focus(rec: rr.RecordingStream, base: str, config: RunConfig, k: int,
                  color: style.RGB) -> None:  # fmt: skip
    """The styling of ``why/focus/<k>``: arm k's score, a line in its colour."""
    name = style.arm_legend(k, config.arm_names[k])
    rec.send_columns(f"{base}/why/focus/{k + 1}", indexes=[], columns=rr.SeriesLines.columns(
        colors=[color], names=[name], widths=[style.WIDTH_ARM]).partition([1]))  # fmt: skip


def log_true_mean(rec: rr.RecordingStream, base: str, config: RunConfig, k: int,
                  color: style.RGB) -> None:  # fmt: skip
    """The styling of ``true_means/<k>``: dots in arm k's colour, named like its line."""
    name = style.arm_legend(k, config.arm_names[k])
    rec.send_columns(
        f"{base}/true_means/{k + 1}",
        indexes=[],
        columns=rr.SeriesPoints.columns(
            colors=[color], names=[name], markers=[rr.components.MarkerShape.Circle],
            marker_sizes=[style.MARKER_TRUE_MEAN],
        ).partition([1]),
    )  # fmt: skip


def log_focus(rec: rr.RecordingStream, base: str, config: RunConfig, k: int,
              color: style.RGB) -> None:  # fmt: skip
    """Arm k came to matter (beyond LINES_UP_TO arms): the styling of ``focus/<k>`` (its
    empirical mean, a line), of its true-mean dots, of its bars and of its row of the
    candidate set, all in ``color``."""
    name = style.arm_legend(k, config.arm_names[k])
    rec.send_columns(
        f"{base}/focus/{k + 1}",
        indexes=[],
        columns=rr.SeriesLines.columns(
            colors=[color], names=[name], widths=[style.WIDTH_ARM]
        ).partition([1]),
    )
    log_true_mean(rec, base, config, k, color)
    at = np.array([k + 1.0])
    # wider than one arm's share where there are many, so that its colour shows
    K = config.K
    bars(rec, f"{base}/bars/mean_arm/{k + 1}", color, at - BAR_OFFSET,
         width=max(BAR_WIDTH, K / 128))  # fmt: skip
    bars(rec, f"{base}/bars/pulls_arm/{k + 1}", color, at, width=max(2 * BAR_WIDTH, K / 64))
    rec.send_columns(
        f"{base}/candidates/{k + 1}",
        indexes=[],
        columns=rr.SeriesPoints.columns(
            colors=[color], names=[name], markers=[rr.components.MarkerShape.Square],
            marker_sizes=[style.MARKER_CANDIDATE],
        ).partition([1]),
    )  # fmt: skip


def bars(
    rec: rr.RecordingStream,
    path: str,
    color: style.RGB,
    abscissa: np.ndarray,
    *,
    values: np.ndarray | None = None,
    width: float = BAR_WIDTH,
) -> None:
    """Static parts of a bar chart at ``path``: its colour, bar positions and widths, and
    with ``values`` the bars themselves (a constant chart)."""
    K = len(abscissa)
    columns = [
        rr.ComponentColumn(rr.BarChart.descriptor_color(), rr.components.ColorBatch([color]),
                           lengths=[1]),
        rr.ComponentColumn(rr.BarChart.descriptor_widths(),
                           rr.components.LengthBatch(np.full(K, width, np.float32)), lengths=[K]),
        rr.ComponentColumn(rr.BarChart.descriptor_abscissa(),
                           tensor_batch(np.asarray(abscissa, np.float64)[None, :]), lengths=[1]),
    ]  # fmt: skip
    if values is not None:
        columns.append(rr.ComponentColumn(rr.BarChart.descriptor_values(),
                                          tensor_batch(values[None, :]), lengths=[1]))  # fmt: skip
    rec.send_columns(path, indexes=[], columns=columns)


def tensor_batch(values: np.ndarray) -> rr.components.TensorDataBatch:
    """Rows of ``values`` (N x K) as N one-dimensional tensors, built as one Arrow array
    (N x M x K: N two-dimensional M x K tensors).

    rerun-sdk 0.41 turns a list of arrays into one 2-D tensor ("Tensors do not support
    batches"), so a column of bar charts for ``send_columns`` is assembled here, in the
    component's own Arrow type: its shape, no dimension names, the float64 buffer.
    """
    import pyarrow as pa

    v = np.ascontiguousarray(values, dtype=np.float64)
    n, *dims = v.shape
    k = int(np.prod(dims))
    typ = rr.components.TensorDataBatch._ARROW_DATATYPE
    shape_f, names_f, buffer_f = (typ.field(i) for i in range(3))
    union = buffer_f.type
    f64 = union.type_codes.index(11)  # the F64 member
    shape = pa.ListArray.from_arrays(pa.array(np.arange(n + 1, dtype=np.int32) * len(dims)),
                                     pa.array(np.tile(np.asarray(dims, np.uint64), n)),
                                     type=shape_f.type)  # fmt: skip
    children = [pa.array([], type=union.field(i).type) for i in range(union.num_fields)]
    children[f64] = pa.ListArray.from_arrays(
        pa.array(np.arange(n + 1, dtype=np.int32) * k), pa.array(v.reshape(-1)),
        type=union.field(f64).type,
    )
    buffer = pa.Array.from_buffers(
        union, n, [None, pa.py_buffer(np.full(n, 11, np.int8)),
                   pa.py_buffer(np.arange(n, dtype=np.int32))], children=children,
    )  # fmt: skip
    array = pa.StructArray.from_arrays(
        [shape, pa.nulls(n, type=names_f.type), buffer], fields=[shape_f, names_f, buffer_f]
    )
    return rr.components.TensorDataBatch(array)


__all__ = [
    "about_markdown",
    "bars",
    "log_focus",
    "log_static",
    "log_true_mean",
    "log_why_focus",
    "log_why_static",
    "tensor_batch",
]
