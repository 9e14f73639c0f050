"""SweepRerunSink: the aggregated curves of a sweep, streamed into a Rerun recording.

The entities, their paths and the default layout are :mod:`corraoi.recorder.sweeplog.layout`'s
(its names stay importable from here).

Styling (``SeriesLines``/``SeriesPoints`` colours, names, widths) is logged once as static.
Colours, widths and markers come from :mod:`corraoi.recorder.style`: each base policy has a colour;
its ``aoi-aware-`` variant uses the same colour with a thinner line plus a cross marker at
every checkpoint, since Rerun 0.41 lines cannot be dashed; a multi-source rule's curves
carry the rule's marker (:data:`RULE_SHAPES`), as in the sweep figure. Units are in the view titles
and series names (Rerun 0.41 has no axis titles).

No global Rerun state: everything goes through the ``RecordingStream`` passed in. With
``set_log_time_enabled(False)`` (done here) and an explicit recording id, two runs of the
same sweep give recordings that ``rerun rrd compare`` finds equal (the bytes differ: Rerun's
row ids and the blueprint's ids are time-based or random).
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import rerun as rr

from corraoi.errors import WriteError
from corraoi.files.partial import PartialFile, reason
from corraoi.recorder import style
from corraoi.recorder.rerun.names import TIMELINE
from corraoi.recorder.rerun.output import check_rrd, finish_recording, first_line
from corraoi.recorder.sink import Sink
from corraoi.recorder.style import (
    MARKER_AOI_AWARE,
    MARKER_RULE,
    WIDTH_AOI_AWARE,
    WIDTH_BAND,
    WIDTH_MAIN,
    arm_color,
    arm_legend,
    config_colors,
    is_aoi_aware,
    lighter,
    policy_color,
    rule_marker,
)
from corraoi.recorder.vocab import SWEEP_FLUSH_EVERY
from corraoi.stats import SweepPoint

from .layout import (
    collisions_path,
    entity_part,
    estimator_path,
    policy_names,
    pulls_path,
    regret_path,
    share_path,
    shown_arms,
    sweep_blueprint,
    sweep_recording_id,
    sweep_recording_name,
)

#: Line widths (UI points) of the mean curves (AoI-aware and band: corraoi.recorder.style).
WIDTH_BASE = WIDTH_MAIN
#: Marker of the AoI-aware variants (Rerun has no dashed lines).
AOI_AWARE_MARKER = rr.components.MarkerShape.Cross
#: Rerun's shape of each multi-source rule's marker (``style.RULE_MARKERS``, matplotlib's
#: codes): the rules of one base policy share its colour, their markers tell them apart; a
#: rule's AoI-aware form keeps the rule's marker and the thinner line.
RULE_SHAPES = {
    "s": rr.components.MarkerShape.Square,
    "^": rr.components.MarkerShape.Up,
    "o": rr.components.MarkerShape.Circle,
    "D": rr.components.MarkerShape.Diamond,
    "v": rr.components.MarkerShape.Down,
    "P": rr.components.MarkerShape.Plus,
    "X": rr.components.MarkerShape.Asterisk,
}
AOI_AWARE_MARKER_SIZE = MARKER_AOI_AWARE
#: Widths of the pull-share lines of the arms shown, first arm widest, the last one
#: thinnest: where two arms' shares coincide, the thinner line lies inside the wider one
#: and both colours show (Rerun draws the later entity on top).
SHARE_WIDEST, SHARE_THINNEST = 5.0, 1.25


def _arm_labels(config: dict[str, Any]) -> list[str]:
    inst = config.get("instance") or {}
    K = len(inst.get("Y", []))
    names = list(inst.get("arms") or [str(k + 1) for k in range(K)])
    return [arm_legend(k, names[k]) for k in range(K)]


def share_widths(n: int) -> list[float]:
    """Line widths of ``n`` pull-share lines, widest first (:data:`SHARE_WIDEST`)."""
    if n <= 1:
        return [style.WIDTH_ARM] * n
    step = (SHARE_WIDEST - SHARE_THINNEST) / (n - 1)
    return [round(SHARE_WIDEST - i * step, 3) for i in range(n)]


def open_sweep_recording(
    path: str | os.PathLike[str],
    config: dict[str, Any],
    *,
    recording_id: str | None = None,
    overwrite: bool = True,
    flush_every: int = SWEEP_FLUSH_EVERY,
) -> SweepRerunSink:
    """A sink that writes ``path`` (.rrd with the default blueprint) and owns its recording.

    The recording id defaults to :func:`sweep_recording_id`; see :meth:`SweepRerunSink.to_file`.
    """
    return SweepRerunSink.to_file(
        path, config, recording_id=recording_id, overwrite=overwrite, flush_every=flush_every
    )


class SweepRerunSink(Sink[SweepPoint]):
    """Streams :class:`~corraoi.stats.SweepPoint` rows into a Rerun recording.

    ``with SweepRerunSink(recording, config) as sink: sink.write(point)``. Points are
    buffered per policy and sent with ``send_columns`` every ``flush_every`` points, when
    the policy changes and on :meth:`close` (which also flushes the recording). The caller
    owns ``recording`` (and its ``save``/``disconnect``) unless the sink was made with
    :meth:`to_file`. Closing twice is safe.
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        config: dict[str, Any],
        *,
        flush_every: int = SWEEP_FLUSH_EVERY,
    ) -> None:
        if flush_every < 1:
            raise ValueError(f"flush_every must be >= 1, got {flush_every}")
        self.recording = recording
        self.config = config
        self.flush_every = int(flush_every)
        self.arm_labels = _arm_labels(config)
        self.K = len(self.arm_labels)
        self._lines = style.lines_for(self.K)
        #: the arms drawn as lines, and their colours and widths (widest first)
        self._shown = shown_arms(config) if self.K else []
        self._widths = dict(zip(self._shown, share_widths(len(self._shown)), strict=True))
        self._buffer: list[SweepPoint] = []
        self._styled: set[str] = set()
        self._colors = config_colors(config)  # a policy's own colour, where it has one
        #: a sweep with a cell of several sources: its collisions are drawn too
        self._many = bool(config.get("sources"))
        self._closed = False
        self._owned: PartialFile | None = None
        recording.set_log_time_enabled(False)
        for name in policy_names(config):
            self._style(name)

    @classmethod
    def to_file(
        cls,
        path: str | os.PathLike[str],
        config: dict[str, Any],
        *,
        recording_id: str | None = None,
        application_id: str = "corraoi",
        overwrite: bool = True,
        flush_every: int = SWEEP_FLUSH_EVERY,
    ) -> SweepRerunSink:
        """A sink that owns its recording: saved to ``<path>.partial`` with the default
        blueprint, disconnected and renamed to ``path`` on :meth:`close`."""
        out = PartialFile(path, overwrite=overwrite, what="sweep recording", sweep=True).create()
        rec = rr.RecordingStream(
            application_id, recording_id=recording_id or sweep_recording_id(config)
        )
        rec.set_log_time_enabled(False)
        rec.send_recording_name(sweep_recording_name(out.path, config))
        try:
            rec.save(out.partial, default_blueprint=sweep_blueprint(config))
        except (OSError, RuntimeError) as exc:
            out.discard()
            why = reason(exc) if isinstance(exc, OSError) else first_line(exc)
            raise WriteError(f"{out.partial}: cannot write: {why}") from None
        sink = cls(rec, config, flush_every=flush_every)
        sink._owned = out
        return sink

    # ------------------------------------------------------------------ styling

    def _style(self, name: str) -> None:
        """Static styling of one policy's entities, sent with ``send_columns`` (no time
        index) like the data, so it always precedes the data in the file (``rr.log`` would
        queue it in Rerun's batcher, whose timer decides when it follows)."""
        if name in self._styled:
            return
        self._styled.add(name)
        rec = self.recording
        color = self._colors.get(name) or policy_color(name)
        aware = is_aoi_aware(name)
        width = WIDTH_AOI_AWARE if aware else WIDTH_BASE

        def static(path: str, *columns: Any) -> None:
            parts = [c for group in columns for c in group.partition([1])]
            rec.send_columns(path, indexes=[], columns=parts)

        def line(rgb: Any, line_width: float, label: str) -> Any:
            return rr.SeriesLines.columns(colors=[rgb], widths=[line_width], names=[label])

        paths = [regret_path(name), estimator_path(name)]
        if self._many:  # the collisions of a sweep of several sources, policy by policy
            paths.append(collisions_path(name))
        shape, size = RULE_SHAPES.get(rule_marker(name)), MARKER_RULE
        if shape is None and aware:
            shape, size = AOI_AWARE_MARKER, AOI_AWARE_MARKER_SIZE
        for path in paths:
            parts: list[Any] = [line(color, width, name)]
            if shape is not None:
                parts.append(
                    rr.SeriesPoints.columns(
                        colors=[color],
                        markers=[shape],
                        marker_sizes=[size],
                        names=[name],
                    )
                )
            static(path, *parts)
        # Named like the mean curve: the legend shows one entry per policy (hiding it there
        # hides the band too) instead of three.
        static(f"{regret_path(name)}/lo", line(lighter(color, 0.45), WIDTH_BAND, name))
        static(f"{regret_path(name)}/hi", line(lighter(color, 0.45), WIDTH_BAND, name))
        for k, label in enumerate(self.arm_labels):
            if self._lines:
                rgb = arm_color(k)
            elif k in self._widths:
                rgb = style.focus_color(self._shown.index(k))
            else:
                rgb = style.BAR_IN_SET_COLOR
            static(pulls_path(name, k + 1), line(rgb, self._widths.get(k, style.WIDTH_ARM), label))
        if not self._lines:
            from corraoi.recorder.rerun.static import bars

            bars(rec, share_path(name), color, np.arange(1, self.K + 1, dtype=np.float64),
                 width=0.9)  # fmt: skip

    # ------------------------------------------------------------------ data

    def write(self, point: SweepPoint) -> None:
        """Buffer one point; sends when ``flush_every`` points wait or the policy changes."""
        if self._closed:
            raise ValueError("the sweep Rerun sink is closed")
        share = np.asarray(point.pull_share, dtype=np.float64).reshape(-1)
        if share.size != self.K:
            raise ValueError(
                f"sweep point {point.policy} t={point.t}: pull_share has {share.size} "
                f"entries, the instance has {self.K} arms"
            )
        if self._buffer and self._buffer[-1].policy != point.policy:
            self.flush()
        self._style(point.policy)
        self._buffer.append(point)
        if len(self._buffer) >= self.flush_every:
            self.flush()

    def flush(self) -> None:
        """Send the buffered points (all of one policy) as columns."""
        if not self._buffer:
            return
        points, self._buffer = self._buffer, []
        name = points[0].policy
        rec = self.recording
        t = np.array([p.t for p in points], dtype=np.int64)
        mean = np.array([p.regret_mean for p in points], dtype=np.float64)
        half = np.array(
            [np.nan if p.regret_ci95 is None else p.regret_ci95 for p in points], dtype=np.float64
        )
        est = np.array([p.estimator_mean for p in points], dtype=np.float64)
        share = np.array([np.asarray(p.pull_share, dtype=np.float64) for p in points])

        def send(path: str, times: np.ndarray, values: np.ndarray) -> None:
            if times.size:
                rec.send_columns(
                    path,
                    indexes=[rr.TimeColumn(TIMELINE, sequence=times)],
                    columns=rr.Scalars.columns(scalars=values),
                )

        send(regret_path(name), t, mean)
        band = np.isfinite(half)
        send(f"{regret_path(name)}/lo", t[band], (mean - half)[band])
        send(f"{regret_path(name)}/hi", t[band], (mean + half)[band])
        send(estimator_path(name), t, est)
        if points[0].collisions_mean is not None:  # a cell of several sources
            hits = np.array([p.collisions_mean for p in points], dtype=np.float64)
            send(collisions_path(name), t, hits)
        for k in range(self.K):
            send(pulls_path(name, k + 1), t, np.ascontiguousarray(share[:, k]))
        if not self._lines and t.size:
            from corraoi.recorder.rerun.static import tensor_batch

            rec.send_columns(
                share_path(name), indexes=[rr.TimeColumn(TIMELINE, sequence=t)],
                columns=[rr.ComponentColumn(rr.BarChart.descriptor_values(), tensor_batch(share))],
            )  # fmt: skip

    def mark(self, policy: str, kind: str, run: int, seed: int, t: np.ndarray,
             regret: np.ndarray) -> None:  # fmt: skip
        """One notable run's regret path (``kind``: worst, median, best) drawn over the mean
        and band of ``policy``, thin, labelled with its run and seed
        (corraoi.experiments.notable)."""
        self.flush()
        path = f"{regret_path(policy)}/{entity_part(kind)}"
        color = self._colors.get(policy) or policy_color(policy)
        label = f"{policy} {kind}: run {run}, seed {seed}"
        self.recording.send_columns(path, indexes=[], columns=[
            c for g in (rr.SeriesLines.columns(colors=[lighter(color, 0.25)], widths=[WIDTH_BAND],
                                               names=[label]),) for c in g.partition([1])
        ])  # fmt: skip
        self.recording.send_columns(
            path,
            indexes=[rr.TimeColumn(TIMELINE, sequence=np.asarray(t, dtype=np.int64))],
            columns=rr.Scalars.columns(scalars=np.asarray(regret, dtype=np.float64)),
        )

    def close(self) -> None:
        """Send what is buffered and flush the recording (an owned one is also
        disconnected and its file renamed into place). Safe to call twice."""
        self._stop(publish_file=True)

    def abort(self) -> None:
        """Like :meth:`close`, but an owned file stays at ``<path>.partial``."""
        self._stop(publish_file=False)

    def _stop(self, *, publish_file: bool) -> None:
        if self._closed:
            return
        self._closed = True
        out = self._owned
        if out is None:
            self.flush()
            self.recording.flush()
            return
        try:  # Rerun's file writer stopped (a full disk): one line, never a traceback
            self.flush()
        except RuntimeError as exc:
            problem: str | None = first_line(exc)
        else:
            problem = None
        problem = finish_recording(self.recording) or problem
        if not publish_file:
            out.leave()
            return
        try:
            check_rrd(out.partial, problem)  # never a cut-short file under the final name
        except WriteError:
            out.leave()
            raise
        out.publish()


__all__ = [
    "SweepRerunSink",
    "open_sweep_recording",
]
