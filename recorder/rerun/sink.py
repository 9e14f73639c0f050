"""RerunSink: one run's slots streamed into a Rerun recording, a block at a time.

The entities and their paths are :mod:`recorder.rerun.names`'s, their static styling and
the ``about`` note :mod:`recorder.rerun.static`'s (logged when the sink is made), the
layout :mod:`recorder.rerun.layout`'s. Data go with ``send_columns``, one call per entity
and batch of :data:`BATCH` slots (blocks are gathered first): ``rr.log`` per slot would
cost ~50 us a call. No global Rerun state: the caller passes a ``RecordingStream``
(:func:`~recorder.rerun.names.new_recording` makes one with reproducible settings) and owns
where it goes; :class:`~recorder.rerun.output.RrdOutput` is the owner ``corraoi record`` uses
(an ``.rrd`` file and/or a viewer).
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from corraoi.engine.block import RunConfig, SlotBlock
from corraoi.model.theory import analyse
from recorder import style
from recorder.sink import Sink

from .names import (
    TIMELINE,
    run_path,
)
from .output import first_line
from .static import log_static

#: Slots a RerunSink gathers before it sends them. One ``send_columns`` per entity has a
#: fixed cost: on this machine (benchmarks/bench_record.py, 200,000 slots) batches of 1,000
#: slots cost 3.0 us a slot, 5,000 1.2 us, 20,000 1.0 us. A viewer then sees the data in
#: steps of ~8,000 slots (30 ms at recording speed).
BATCH = 8192


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
        log_static(recording, self.base, config, self.color)

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
            self.problem = first_line(exc)
        return self.problem


__all__ = [
    "BATCH",
    "RerunSink",
]
