"""RerunSink: one run's slots streamed into a Rerun recording, a block at a time.

Entities (timeline ``slot``, a sequence; arms and states numbered from 1), under
``runs/<label>`` (:func:`run_path`):

==================  =====================================================================
``aoi``             age of information after the slot (line)
``oracle_aoi``      age of the oracle playing the best arm on the same hidden path (dots)
``regret``          pathwise AoI regret sum (aoi - oracle_aoi) (line)
``estimator``       the paper's estimator sum aoi - t / mu* (line)
``arm/success``     the arm played, at the slots where it delivered (points)
``arm/failure``     the arm played, at the slots where it failed (points)
``override``        the arm played, at the slots where the AoI-aware rule chose it (points)
``x``               the hidden state X_t (points)
``mu_hat``          empirical mean of every arm after the slot, K series
``mu_true``         true mean of every arm (constant: two points a batch), ``mu_k (true)``
``pulls``           pulls of every arm after the slot, K series
``candidates/<k>``  the value k at the slots where arm k was in the candidate set (points)
``about``           the run configuration (static markdown)
==================  =====================================================================

Styling (names, colours, markers; :mod:`recorder.style` owns them) is logged once as
static data when the sink is made. rerun-sdk 0.41 has no axis titles: units are in the
view titles and series names.
Data go with ``send_columns``, one call per entity and batch of :data:`BATCH` slots
(blocks are gathered first): ``rr.log`` per slot would cost ~50 us a call. No global
Rerun state: the caller passes a ``RecordingStream`` (:func:`new_recording` makes one
with reproducible settings) and owns where it goes; :class:`RrdOutput` is the owner
``corraoi record`` uses (an ``.rrd`` file and/or a viewer).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from corraoi.block import RunConfig, SlotBlock
from corraoi.theory import analyse

from . import style
from .errors import ViewerError, WriteError
from .paths import (
    Sink,
    check_output,
    open_partial,
    partial_path,
    publish,
    reason,
    unlink_partial,
)

APPLICATION_ID = "corraoi"
TIMELINE = "slot"
ROOT = "runs"
#: Slots a RerunSink gathers before it sends them. One ``send_columns`` per entity has a
#: fixed cost: on this machine (benchmarks/bench_record.py, 200,000 slots) batches of 1,000
#: slots cost 3.0 us a slot, 5,000 1.2 us, 20,000 1.0 us. A viewer then sees the data in
#: steps of ~8,000 slots (30 ms at recording speed).
BATCH = 8192
#: Slots shown by the windowed views (AoI, arms, states, candidates) left of the cursor:
#: few enough that every success and failure marker stays legible.
WINDOW = 200

#: Entities of a run, relative to :func:`run_path` (``candidates`` has one child per arm).
ENTITIES = (
    "aoi",
    "oracle_aoi",
    "regret",
    "estimator",
    "arm/success",
    "arm/failure",
    "override",
    "x",
    "mu_hat",
    "mu_true",
    "pulls",
    "candidates",
    "about",
)


def run_path(label: str) -> str:
    """``runs/<label>``, the label escaped as one entity path part."""
    return f"{ROOT}/{rr.escape_entity_path_part(label)}"


def run_recording_id(config: RunConfig) -> str:
    """A recording id that depends on the run configuration only (reproducible files)."""
    digest = hashlib.sha256(json.dumps(config.to_dict(), sort_keys=True).encode()).hexdigest()
    return f"corraoi-run-{digest[:16]}"


def new_recording(
    config: RunConfig,
    *,
    recording_id: str | None = None,
    application_id: str = APPLICATION_ID,
) -> rr.RecordingStream:
    """A RecordingStream for one run: explicit id, no wall-clock timeline, named by label.

    It starts with a buffered sink: attach destinations (``set_sinks``, ``save``, ...)
    before sending data, or use :class:`RrdOutput`.
    """
    rec = rr.RecordingStream(
        application_id,
        recording_id=recording_id or run_recording_id(config),
        send_properties=False,
    )
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    rec.send_recording_name(config.label)
    return rec


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


class RerunSink(Sink):
    """Send one run's SlotBlocks to ``recording`` under ``runs/<label>``.

    ``with RerunSink(recording, label, config) as sink: sink.write(block)``. The static
    styling and the ``about`` note are logged when the sink is made. :meth:`close` flushes
    the recording (at most ``flush_timeout`` seconds); the caller keeps owning the
    recording's destinations. Closing twice is safe.
    """

    def __init__(
        self,
        recording: rr.RecordingStream,
        label: str,
        config: RunConfig,
        *,
        flush_timeout: float = 30.0,
        batch: int = BATCH,
        color: style.RGB | None = None,
    ) -> None:
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch}")
        self.recording = recording
        self.batch = int(batch)
        self._pending: list[SlotBlock] = []
        self._pending_slots = 0
        self.label = label
        self.config = config
        self.base = run_path(label)
        self.K = config.instance.K
        self.slots = 0
        self.closed = False
        self.flush_timeout = flush_timeout
        self.problem: str | None = None
        self._arm_values = np.arange(1, self.K + 1, dtype=np.float64)
        #: the run's colour: ``color`` (compare gives runs of one policy distinct shades),
        #: else the policy's own (``spec.color``) or its base policy's
        self.color = color if color is not None else style.spec_color(config.policy)
        self._mu = np.asarray(analyse(config.instance).mu, dtype=np.float64)
        self._style()

    def _style(self) -> None:
        """Log the static styling and the ``about`` note.

        They go with ``send_columns`` without a time index (static data), like the slots:
        ``rr.log`` would queue them in Rerun's batcher, whose timer could let a first
        batch of slots reach the file before them, and two recordings of one run would
        then differ in the order of their chunks.
        """
        rec, base, st = self.recording, self.base, style
        color = self.color
        names = _arm_names(self.config)
        colors = [st.arm_color(k) for k in range(self.K)]

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
        arms = range(self.K)
        lines("mu_hat", colors, [st.mean_name(k, true=False) for k in arms],
              [st.WIDTH_ARM] * self.K)
        lines("mu_true", [st.true_mean_color(k) for k in arms],
              [st.mean_name(k, true=True) for k in arms], [st.WIDTH_TRUE_MEAN] * self.K)
        lines("pulls", colors, names, [st.WIDTH_ARM] * self.K)  # fmt: skip
        for k in arms:
            points(f"candidates/{k + 1}", colors[k], names[k], shape.Square, st.MARKER_CANDIDATE)
        static("about", rr.TextDocument.columns(text=[about_markdown(self.config)],
                                                media_type=[rr.MediaType.MARKDOWN]))  # fmt: skip

    def write(self, block: SlotBlock) -> None:
        """Queue the block's slots; they are sent once ``batch`` slots wait (and by
        :meth:`send` or :meth:`close`)."""
        if self.closed:
            raise ValueError(f"RerunSink {self.label}: write() after close()")
        if len(block) == 0:
            return
        self._pending.append(block)
        self._pending_slots += len(block)
        if self._pending_slots >= self.batch:
            self.send()

    def send(self) -> None:
        """Send the queued slots now, one ``send_columns`` per entity."""
        if not self._pending:
            return
        block = self._pending[0] if len(self._pending) == 1 else SlotBlock.concat(self._pending)
        self._pending, self._pending_slots = [], 0
        self._send(block)

    def _send(self, block: SlotBlock) -> None:
        n = len(block)
        send, base = self.recording.send_columns, self.base
        t = np.ascontiguousarray(block.t, dtype=np.int64)

        def column(path: str, times: np.ndarray, values: np.ndarray) -> None:
            if times.size:
                send(
                    f"{base}/{path}",
                    indexes=[rr.TimeColumn(TIMELINE, sequence=times)],
                    columns=rr.Scalars.columns(scalars=values),
                )

        f64 = np.float64
        column("aoi", t, block.aoi.astype(f64))
        column("oracle_aoi", t, block.oracle_aoi.astype(f64))
        column("regret", t, block.regret.astype(f64))
        column("estimator", t, np.ascontiguousarray(block.estimator, dtype=f64))
        arm = (block.arm + 1).astype(f64)
        ok = np.asarray(block.success, dtype=bool)
        column("arm/success", t[ok], arm[ok])
        column("arm/failure", t[~ok], arm[~ok])
        over = np.asarray(block.override, dtype=bool)
        column("override", t[over], arm[over])
        column("x", t, (block.x + 1).astype(f64))
        column("mu_hat", t, np.ascontiguousarray(block.mu_hat, dtype=f64))
        ends = t[[0, -1]] if n > 1 else t[:1]  # a constant: two points draw the line
        column("mu_true", ends, np.tile(self._mu, (len(ends), 1)))
        column("pulls", t, block.pulls.astype(f64))
        cand = np.asarray(block.candidates, dtype=bool)
        for k in range(self.K):
            member = cand[:, k]
            column(f"candidates/{k + 1}", t[member], np.full(int(member.sum()), k + 1.0))
        self.slots += n

    def close(self) -> str | None:
        """Flush the recording (blocking up to ``flush_timeout`` s). Safe to call twice.

        Returns the problem Rerun reported while delivering the data (a viewer that
        stopped answering, a file writer that failed), or None when all went well. The
        owner of the recording's destinations (e.g. :class:`RrdOutput`) decides what it
        means.
        """
        if self.closed:
            return self.problem
        self.send()
        self.closed = True
        try:
            self.recording.flush(timeout_sec=self.flush_timeout)
        except RuntimeError as exc:
            self.problem = _first_line(exc)
        return self.problem


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


class RrdOutput(Sink):
    """Where one run's Rerun recording goes: an ``.rrd`` file and/or a viewer (gRPC URL).

    The file is written as ``<path>.partial`` (with the default blueprint embedded) and
    renamed to ``path`` by :meth:`close`; :meth:`abort` leaves the ``.partial`` file, or
    deletes it with ``discard_on_abort`` (replay and compare: their output can be made
    again). Leaving a ``with`` block through any exception, Ctrl-C included, aborts.
    ``recording`` is made here (:func:`new_recording`); hand it to :class:`RerunSink`.
    """

    def __init__(
        self,
        config: RunConfig,
        *,
        rrd_path: str | os.PathLike[str] | None = None,
        viewer_url: str | None = None,
        label: str | None = None,
        overwrite: bool = False,
        blueprint: rrb.Blueprint | None = None,
        recording_id: str | None = None,
        flush_timeout: float = 30.0,
        discard_on_abort: bool = False,
    ) -> None:
        if rrd_path is None and viewer_url is None:
            raise ValueError("RrdOutput needs an .rrd path, a viewer URL or both")
        self.config = config
        self.label = label or config.label
        self.path: Path | None = None
        self.viewer_url = viewer_url
        self.overwrite = overwrite
        self.flush_timeout = flush_timeout
        self.discard_on_abort = discard_on_abort
        self.closed = False
        self.finished = False
        self._lock: BinaryIO | None = None
        sinks: list[Any] = []
        if rrd_path is not None:
            self.path = check_output(rrd_path, overwrite=overwrite, what="Rerun recording")
            # create (or truncate) the .partial file here, so that an unwritable place is
            # one clear error now rather than a log line from Rerun's writer thread later;
            # kept open (locked) until the file is in place, so no other writer takes it
            self._lock = open_partial(self.path, overwrite=overwrite, what="Rerun recording")
            sinks.append(rr.FileSink(str(partial_path(self.path))))
        if viewer_url is not None:
            sinks.append(rr.GrpcSink(viewer_url))
        self.recording = new_recording(config, recording_id=recording_id)
        try:
            self.recording.set_sinks(
                *sinks,
                default_blueprint=blueprint or one_run_blueprint(self.label, config),
            )
        except (OSError, RuntimeError, ValueError) as exc:
            self._unlock()
            if self.path is not None:
                unlink_partial(self.path)
            raise WriteError(f"{self._where()}: cannot start the Rerun recording: {exc}") from None

    def _where(self) -> str:
        return str(partial_path(self.path)) if self.path is not None else str(self.viewer_url)

    def _finish(self) -> str | None:
        """Flush and disconnect; returns the problem Rerun reported, if any."""
        problem = None
        try:
            self.recording.flush(timeout_sec=self.flush_timeout)
        except RuntimeError as exc:
            problem = _first_line(exc)
        self.recording.disconnect()
        return problem

    def close(self) -> Path | None:
        """Deliver everything, check the file and rename it into place. Safe twice.

        Returns the .rrd path (None without a file). A file Rerun could not write
        completely raises :class:`WriteError` and stays at ``<path>.partial``; a viewer
        that could not be reached raises :class:`ViewerError` after the file is in place.
        """
        if self.closed:
            return self.path if self.finished else None
        self.closed = True
        problem = self._finish()
        if self.path is not None:
            try:
                self._check_file(problem)
                publish(self.path, overwrite=self.overwrite)
            finally:
                self._unlock()
            self.finished = True
        if problem and self.viewer_url is not None:
            raise ViewerError(f"viewer {self.viewer_url}: {problem}")
        return self.path

    def abort(self, *, discard: bool | None = None) -> Path | None:
        """Stop; the file (if any) stays at ``<path>.partial`` (deleted with ``discard``,
        which defaults to ``discard_on_abort``). After :meth:`close` it changes nothing."""
        if self.finished:
            return self.path
        if not self.closed:
            self.closed = True
            self._finish()
        self._unlock()
        if self.path is None:
            return None
        if discard is None:
            discard = self.discard_on_abort
        part = partial_path(self.path)
        if discard:
            unlink_partial(self.path)
            return None
        return part

    def _unlock(self) -> None:
        """Close the locked handle of the ``.partial`` file (safe twice)."""
        lock, self._lock = self._lock, None
        if lock is not None:
            try:
                lock.close()
            except OSError:
                pass

    def _check_file(self, problem: str | None) -> None:
        """Refuse to present a damaged .rrd as complete: its footer must read back."""
        assert self.path is not None
        part = partial_path(self.path)
        why = None
        try:
            if part.stat().st_size == 0:
                why = "the file is empty"
        except OSError as exc:
            why = f"the file is gone ({reason(exc)})"
        if why is None:
            import warnings

            from rerun.chunk import RrdReader

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                try:
                    RrdReader(str(part)).store()
                except Exception as exc:  # noqa: BLE001 - any failure means an unusable file
                    why = problem or _first_line(exc)
        if why is not None:
            raise WriteError(
                f"{part}: Rerun could not write the whole recording ({why}; disk full?); "
                f"the incomplete file is left as {part}"
            )


__all__ = [
    "APPLICATION_ID",
    "ENTITIES",
    "ROOT",
    "TIMELINE",
    "RerunSink",
    "RrdOutput",
    "about_markdown",
    "new_recording",
    "one_run_blueprint",
    "run_path",
    "run_recording_id",
]
