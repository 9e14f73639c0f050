"""RerunSink: one run's slots streamed into a Rerun recording, a block at a time.

The entities and their paths are :mod:`corraoi.recorder.rerun.names`'s, their static styling and
the ``about`` note :mod:`corraoi.recorder.rerun.static`'s (logged when the sink is made), the
layout :mod:`corraoi.recorder.rerun.layout`'s. Besides the slots' own values the sink draws the
presentation entities (``names.PRESENTATION``): the best arm's line, the true means
as dots, and beyond ``style.LINES_UP_TO`` arms the per-arm bars at every
``snapshot_every``-th slot and the lines of the arms that matter. Data go with
``send_columns``, one call per entity and batch of :data:`BATCH` slots (blocks are
gathered first): ``rr.log`` per slot would cost ~50 us a call. No global Rerun state: the
caller passes a ``RecordingStream`` (:func:`~corraoi.recorder.rerun.names.new_recording` makes one
with reproducible settings) and owns where it goes;
:class:`~corraoi.recorder.rerun.output.RrdOutput` is the owner ``corraoi record`` uses (an
``.rrd`` file and/or a viewer).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import rerun as rr

from corraoi.engine.block import RunBlock, RunConfig, SlotBlock, SourcesBlock
from corraoi.recorder import style
from corraoi.recorder.sink import RunRecording, Sink

from .names import (
    TIMELINE,
    TRUE_DOTS,
    run_path,
    snapshot_every,
)
from .output import RrdOutput, first_line
from .sources import SourcesSink
from .static import log_focus, log_static, log_why_focus, log_why_static, tensor_batch

if TYPE_CHECKING:
    from corraoi.policies import RGB

#: Slots a RerunSink gathers before it sends them. One ``send_columns`` per entity has a
#: fixed cost: on this machine (benchmarks/bench_record.py, 200,000 slots) batches of 1,000
#: slots cost 3.0 us a slot, 5,000 1.2 us, 20,000 1.0 us. A viewer then sees the data in
#: steps of ~8,000 slots (30 ms at recording speed).
BATCH = 8192


class RerunSink(Sink[SlotBlock]):
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
        color: RGB | None = None,
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
        self.K = config.K
        self.slots = 0
        self.closed = False
        self.flush_timeout = flush_timeout
        self.problem: str | None = None
        self._arm_values = np.arange(1, self.K + 1, dtype=np.float64)
        #: the run's colour: ``color`` (compare gives runs of one policy distinct shades),
        #: else the policy's own (``spec.color``) or its base policy's
        self.color = color if color is not None else style.spec_color(config.policy)
        theory = config.theory  # None for a run without an instance: no means, no best arm
        self._mu = None if theory is None else np.asarray(theory.mu, dtype=np.float64)
        self._best = None if theory is None else int(theory.best_arm)
        self._lines = style.lines_for(self.K)
        #: true-mean dots: every ``_dot`` slots, arm k's shifted by ``_phase[k]``
        shown = self.K if self._lines else style.FOCUS_MAX
        self._dot = max(1, int(config.horizon) // max(8, TRUE_DOTS // shown))
        self._phase = (np.arange(self.K) * self._dot) // self.K
        self._every = snapshot_every(config.horizon)
        #: beyond LINES_UP_TO arms: the arms drawn as lines, each with its first slot
        self.focus: dict[int, int] = {}
        self._last: tuple[int, np.ndarray, np.ndarray, np.ndarray] | None = None
        #: the "why this arm" entities are styled (at the first block with scores), and
        #: the score and arm at the last slot sent (for the bars at the end)
        self._why = False
        self._why_last: tuple[int, np.ndarray, int] | None = None
        self._snapped = 0
        log_static(recording, self.base, config, self.color)
        # the references are known before any slot: the best arm's line and the true
        # means' dots over the whole horizon, sent once (not a batch at a time)
        horizon = max(int(config.horizon), 1)
        if self._best is not None:
            self._reference("arm/best", np.array([1, horizon]), self._best + 1.0)
        if self._lines:
            for k in range(self.K):
                self._true_dots(k, 1)
        else:
            first = (
                range(min(self.K, style.FOCUS_START))
                if theory is None
                else style.arms_that_matter(theory.mu, int(theory.best_arm), theory.competitive)
            )
            for k in first:  # fmt: skip
                self._join(k, 1)

    def _reference(self, path: str, t: np.ndarray, value: float) -> None:
        self.recording.send_columns(
            f"{self.base}/{path}",
            indexes=[rr.TimeColumn(TIMELINE, sequence=np.ascontiguousarray(t, dtype=np.int64))],
            columns=rr.Scalars.columns(scalars=np.full(len(t), value)),
        )

    def _true_dots(self, k: int, first: int) -> None:
        """Arm k's true mean as dots from slot ``first`` to the horizon (none without an
        instance)."""
        if self._mu is None:
            return
        t = np.arange(1 + self._phase[k], int(self.config.horizon) + 1, self._dot)
        t = t[t >= first]
        if len(t):
            self._reference(f"true_means/{k + 1}", t, float(self._mu[k]))

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
        absent = block.absent  # columns the run does not give: not drawn

        def column(path: str, times: np.ndarray, values: np.ndarray) -> None:
            if times.size and path.partition("/")[0] not in absent:
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
        if self._mu is not None:
            column("mu_true", ends, np.tile(self._mu, (len(ends), 1)))
        column("pulls", t, block.pulls.astype(f64))
        cand = np.asarray(block.candidates, dtype=bool)
        for k in range(self.K):
            member = cand[:, k]
            column(f"candidates/{k + 1}", t[member], np.full(int(member.sum()), k + 1.0))
        if block.score is not None and not self._why:
            self._why = True
            log_why_static(self.recording, self.base, self.config, self.color,
                           threshold=block.override_threshold is not None)  # fmt: skip
            for k in self.focus:
                log_why_focus(self.recording, self.base, self.config, k,
                              style.focus_color(list(self.focus).index(k)))  # fmt: skip
        # the presentation entities (names.PRESENTATION) beyond LINES_UP_TO arms
        if not self._lines:
            self._snapshots(block, t, cand)
        for k, first in self.focus.items():
            keep = t >= first
            mean = np.ascontiguousarray(block.mu_hat[keep, k], dtype=f64)
            column(f"focus/{k + 1}", t[keep], mean)
        if block.score is not None:
            self._send_why(block, t, column)
        self.slots += n

    def _send_why(
        self, block: SlotBlock, t: np.ndarray, column: Callable[[str, np.ndarray, np.ndarray], None]
    ) -> None:
        """The "why this arm" entities of a block that has scores: every arm's score (up to
        LINES_UP_TO arms; beyond, those of the arms that matter), the played arm's score
        (up to LINES_UP_TO arms only where it was below the top score; beyond, wherever it
        has one), the forced slots, the override's threshold."""
        assert block.score is not None
        f64 = np.float64
        # NaN is never sent: `rerun rrd compare` tells NaN from NaN, so two equal
        # recordings would differ
        score = np.asarray(block.score, dtype=f64)
        fin = np.isfinite(score)
        if self._lines:  # one entity of K series, a row a slot scored (not a row per arm
            # and slot: 0.1 us a slot less at K = 4, a third fewer .rrd bytes for ucb); an
            # arm without a finite score there is -inf, which draws no point (its line
            # joins the points on either side, as it did across slots without a row)
            rows = fin.any(axis=1)
            column("why/score", t[rows], np.where(fin[rows], score[rows], -np.inf))
        for k, first in self.focus.items():  # only the finite scores
            keep = (t >= first) & fin[:, k]
            column(f"why/focus/{k + 1}", t[keep], np.ascontiguousarray(score[keep, k]))
        chosen = score[np.arange(len(t)), block.arm]
        ok = np.isfinite(chosen)
        if self._lines:  # every arm's line is drawn, and where the score chose the arm it
            # is the top line: a dot only where the arm played was below the top (the
            # override chose it), not a row a slot (0.1-0.15 us a slot at K = 4)
            ok &= chosen < np.fmax.reduce(score, axis=1)
        column("why/chosen", t[ok], np.ascontiguousarray(chosen[ok]))
        if block.forced is not None:
            forced = np.asarray(block.forced, dtype=bool)
            column("why/forced", t[forced], (block.arm[forced] + 1).astype(f64))
        if block.override_threshold is not None:
            thr = np.asarray(block.override_threshold, dtype=f64)
            fin = np.isfinite(thr)
            column("why/threshold", t[fin], np.ascontiguousarray(thr[fin]))

    def _join(self, k: int, slot: int) -> None:
        """Arm k matters from ``slot`` on: its line and true-mean dots are drawn."""
        color = style.focus_color(len(self.focus))
        log_focus(self.recording, self.base, self.config, k, color)
        if self._why:
            log_why_focus(self.recording, self.base, self.config, k, color)
        self.focus[k] = slot
        self._true_dots(k, slot)

    def _snapshots(self, block: SlotBlock, t: np.ndarray, cand: np.ndarray) -> None:
        """The per-arm bars at the snapshot slots of ``block``; an arm that became the most
        played, or is in a candidate set of at most FOCUS_MAX arms, joins the lines."""
        at = np.flatnonzero((t % self._every == 0) | (t == 1))
        pulls = block.pulls
        for i in at[t[at] > self.K]:  # not while every arm is being tried once
            if len(self.focus) >= style.FOCUS_MAX:
                break
            top2 = np.partition(pulls[i], -2)[-2:]
            joining = [int(np.argmax(pulls[i]))] if top2[1] > top2[0] else []
            members = np.flatnonzero(cand[i])
            if len(members) <= style.FOCUS_MAX:
                joining += [int(k) for k in members]
            for k in joining:
                if k not in self.focus and len(self.focus) < style.FOCUS_MAX:
                    self._join(k, int(t[i]))
        last = len(t) - 1
        self._last = (int(t[last]), block.mu_hat[last], pulls[last], cand[last])
        if len(at):
            self._bars(t[at], block.mu_hat[at], pulls[at], cand[at])
        if block.score is not None:
            self._why_last = (int(t[last]), block.score[last], int(block.arm[last]))
            if len(at):
                self._why_bars(t[at], block.score[at], block.arm[at])

    def _why_bars(self, t: np.ndarray, score: np.ndarray, arm: np.ndarray) -> None:
        """The scores at the bars' slots ``t``: the candidates' in grey, the arm played's in
        the policy's colour (0 where an arm has none)."""
        send, base = self.recording.send_columns, self.base
        descriptor = rr.BarChart.descriptor_values()
        values = np.where(np.isfinite(score), np.asarray(score, dtype=np.float64), 0.0)
        mine = np.zeros_like(values)
        rows = np.arange(len(t))
        mine[rows, arm] = values[rows, arm]
        values[rows, arm] = 0.0
        times = [rr.TimeColumn(TIMELINE, sequence=np.ascontiguousarray(t, dtype=np.int64))]
        for path, v in (("why/bars/score", values), ("why/bars/chosen", mine)):
            send(f"{base}/{path}", indexes=times,
                 columns=[rr.ComponentColumn(descriptor, tensor_batch(v))])  # fmt: skip

    def _bars(self, t: np.ndarray, mu_hat: np.ndarray, pulls: np.ndarray, cand: np.ndarray) -> None:
        """The bars at the snapshot slots ``t``: an arm that matters (at that slot) in its
        own colour, the others grey (the means: darker while in the candidate set)."""
        send, base = self.recording.send_columns, self.base
        mu_hat = np.asarray(mu_hat, dtype=np.float64)
        pulls = np.asarray(pulls, dtype=np.float64)
        descriptor = rr.BarChart.descriptor_values()

        def bars(path: str, times: np.ndarray, values: np.ndarray) -> None:
            if len(times):
                send(f"{base}/{path}",
                     indexes=[rr.TimeColumn(TIMELINE, sequence=np.ascontiguousarray(times))],
                     columns=[rr.ComponentColumn(descriptor, tensor_batch(values))])  # fmt: skip

        joined = np.full(self.K, np.iinfo(np.int64).max, dtype=np.int64)
        for k, first in self.focus.items():
            joined[k] = first
        shown = joined[None, :] <= t[:, None]  # drawn in its colour at that slot
        t = np.asarray(t, dtype=np.int64)
        bars("bars/mean", t, np.where(cand & ~shown, mu_hat, 0.0))
        bars("bars/mean_other", t, np.where(~cand & ~shown, mu_hat, 0.0))
        bars("bars/pulls", t, np.where(shown, 0.0, pulls))
        for k, first in self.focus.items():
            rows = t >= first
            bars(f"bars/mean_arm/{k + 1}", t[rows], mu_hat[rows, k : k + 1])
            bars(f"bars/pulls_arm/{k + 1}", t[rows], pulls[rows, k : k + 1])
        self._snapped = int(t[-1])

    def finish(self) -> None:
        """Send the queued slots, and the bars at the last slot when it was not a snapshot
        slot (so the bars at the end show the end). :meth:`close` calls it."""
        self.send()
        if self._last is not None and self._last[0] != self._snapped:
            t, mu_hat, pulls, cand = self._last
            self._bars(np.array([t]), mu_hat[None, :], pulls[None, :], cand[None, :])
            if self._why_last is not None:
                t, score, arm = self._why_last
                self._why_bars(np.array([t]), score[None, :], np.array([arm]))

    def close(self) -> str | None:
        """Flush the recording (blocking up to ``flush_timeout`` s). Safe to call twice.

        Returns the problem Rerun reported while delivering the data (a viewer that
        stopped answering, a file writer that failed), or None when all went well. The
        owner of the recording's destinations (e.g. :class:`RrdOutput`) decides what it
        means.
        """
        if self.closed:
            return self.problem
        self.finish()
        self.closed = True
        try:
            self.recording.flush(timeout_sec=self.flush_timeout)
        except RuntimeError as exc:
            self.problem = first_line(exc)
        return self.problem


def run_sink(recording: rr.RecordingStream, label: str, config: RunConfig, *,
             color: RGB | None = None) -> RerunSink | SourcesSink:  # fmt: skip
    """The sink of one run: a :class:`RerunSink`, or for a run of several sources a
    :class:`corraoi.recorder.rerun.sources.SourcesSink` (the same interface)."""
    if config.sources > 1:
        return SourcesSink(recording, label, config, color=color)
    return RerunSink(recording, label, config, color=color)


class LocalRecording(RunRecording):
    """One run's recording written in this process: an :class:`RrdOutput` (the file and/or
    viewer) fed by a :class:`RerunSink` (:class:`~corraoi.recorder.sink.RunRecording`'s meaning).
    A forked worker writes its recordings with this class too."""

    def __init__(
        self,
        config: RunConfig,
        *,
        rrd_path: str | os.PathLike[str] | None = None,
        viewer_url: str | None = None,
        overwrite: bool = False,
    ) -> None:
        self.output = RrdOutput(config, rrd_path=rrd_path, viewer_url=viewer_url,
                                overwrite=overwrite)  # fmt: skip
        self.path = self.output.path
        self.sink = run_sink(self.output.recording, config.label, config)

    def _write(self, block: RunBlock) -> None:
        if isinstance(self.sink, SourcesSink):
            if not isinstance(block, SourcesBlock):
                raise ValueError(f"{self.sink.label}: a single source's block for a run of "
                                 f"{self.sink.M} sources")  # fmt: skip
            self.sink.write(block)
        elif isinstance(block, SlotBlock):
            self.sink.write(block)
        else:
            raise ValueError(f"{self.sink.label}: a block of {block.M} sources for a run of one")

    def close(self) -> Path | None:
        """Send what the sink holds, then :meth:`RrdOutput.close` (which flushes, once)."""
        if not self.output.closed:
            self.sink.finish()
        return self.output.close()

    def abort(self, *, discard: bool | None = None) -> Path | None:
        return self.output.abort(discard=discard)


__all__ = [
    "BATCH",
    "LocalRecording",
    "RerunSink",
    "run_sink",
]
