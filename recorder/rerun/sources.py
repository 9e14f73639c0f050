"""SourcesSink: one run of several sources (issue 43) streamed into a Rerun recording.

A run of M >= 2 sources sharing the channels is drawn apart from a single source's
(:class:`~corraoi.recorder.rerun.sink.RerunSink`, which stays as it is): each source has its
colour (:func:`corraoi.recorder.style.source_color`); its entities, under ``runs/<label>``
(timeline ``slot``):

=========================  ==============================================================
``sources/<m>/aoi``        source m's age after the slot (line, its colour)
``sources/<m>/oracle_aoi`` the age of its oracle (the m-th best arm on the same hidden
                           path; near-black dots)
``sources/<m>/regret``     source m's pathwise regret (line, its colour)
``regret``                 the run's regret, the sum over the sources (thick, near-black)
``occupancy/<m>``          the channel source m played, at every slot (points, its colour,
                           a little above or below the channel's line: :func:`lane_offsets`)
``occupancy/collided``     the channel at the slots where sources collided on it (red
                           crosses over the points)
``x``                      the hidden state X_t (points)
``means/<m>``              up to ``style.SOURCE_BARS_UP_TO`` arms: source m's empirical means of
                           every arm at slot 1, every
                           :func:`~corraoi.recorder.rerun.names.snapshot_every`-th slot and
                           the last (a bar chart, its bars beside the other sources')
``means``                  beyond: every source's means at those slots as one sources x
                           arms tensor (a heatmap, 0..1)
``true_means``             the true means (a static bar chart, dark grey, right of the
                           sources' bars of each arm)
``about``                  the run card (markdown)
=========================  ==============================================================

:func:`corraoi.recorder.rerun.layout.sources_blueprint` arranges them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import rerun as rr

from corraoi.engine.block import RunConfig, SlotBlock, SourcesBlock
from corraoi.policies import RGB
from corraoi.recorder import style
from corraoi.recorder.sink import Sink

from .names import TIMELINE, run_path, snapshot_every
from .output import first_line
from .static import about_markdown, bars, tensor_batch

#: Slots gathered before they are sent (as RerunSink's BATCH).
BATCH = 8192
#: The collisions' markers: red crosses, over the sources' points.
COLLISION_COLOR: RGB = style.FAILURE_COLOR
COLLISION_NAME = "collision"
MARKER_COLLISION = 8.0
MARKER_OCCUPANCY = 3.5
#: The run's regret (the sum over the sources): near-black, thicker than a source's.
TOTAL_COLOR: RGB = style.ORACLE_COLOR
WIDTH_TOTAL = 3.0
#: Share of a unit on the arm axis the bars of all the sources of an arm take together.
GROUP_WIDTH = 0.8
#: Share of a channel's row the sources' points spread over in the channel view.
LANES = 0.6


def bar_offsets(M: int) -> np.ndarray:
    """Where the bars of an arm stand beside it, side by side, each GROUP_WIDTH / (M + 1)
    wide: source m's at [m - 1], the true mean's last, at [M]."""
    w = GROUP_WIDTH / (M + 1)
    return (np.arange(M + 1) - M / 2) * w


def lane_offsets(M: int) -> np.ndarray:
    """Source m's points in the channel view stand ``[m - 1]`` above or below the channel's
    line, so that sources on one channel are seen side by side (the collisions' crosses
    sit on the line)."""
    return (np.arange(M) - (M - 1) / 2) * (LANES / M)


def log_sources_static(rec: rr.RecordingStream, base: str, config: RunConfig) -> None:
    """The static styling of a run of several sources, and its card (static data sent with
    ``send_columns``, as :func:`~corraoi.recorder.rerun.static.log_static` does)."""
    M, K = config.sources, config.K
    shape = rr.components.MarkerShape

    def static(path: str, columns: Any, count: int = 1) -> None:
        rec.send_columns(f"{base}/{path}", indexes=[], columns=columns.partition([count]))

    def line(path: str, rgb: RGB, name: str, width: float) -> None:
        static(path, rr.SeriesLines.columns(colors=[rgb], widths=[width], names=[name]))

    def points(path: str, rgb: RGB, name: str, marker: rr.components.MarkerShape,
               size: float) -> None:  # fmt: skip
        static(path, rr.SeriesPoints.columns(colors=[rgb], names=[name], markers=[marker],
                                             marker_sizes=[size]))  # fmt: skip

    line("regret", TOTAL_COLOR, f"all sources {style.REGRET_UNIT}", WIDTH_TOTAL)
    arm = np.arange(1, K + 1, dtype=np.float64)
    width = GROUP_WIDTH / (M + 1)
    for m in range(1, M + 1):
        rgb, name = style.source_color(m), style.source_name(m)
        line(f"sources/{m}/aoi", rgb, f"{name} {style.AOI_UNIT}", style.WIDTH_MAIN)
        points(f"sources/{m}/oracle_aoi", style.ORACLE_COLOR, f"{name}'s oracle",
               shape.Circle, style.MARKER_ORACLE)  # fmt: skip
        line(f"sources/{m}/regret", rgb, name, style.WIDTH_SECONDARY * 1.5)
        points(f"occupancy/{m}", rgb, name, shape.Circle, MARKER_OCCUPANCY)
        if K <= style.SOURCE_BARS_UP_TO:
            bars(rec, f"{base}/means/{m}", rgb, arm + bar_offsets(M)[m - 1], width=width)
    points("occupancy/collided", COLLISION_COLOR, COLLISION_NAME, shape.Cross, MARKER_COLLISION)
    points("x", style.STATE_COLOR, style.STATE_NAME, shape.Square, style.MARKER_STATE)
    theory = config.theory
    if K > style.SOURCE_BARS_UP_TO:
        static("means", rr.Tensor.columns(value_range=[[0.0, 1.0]]))
    if (
        theory is not None and K <= style.SOURCE_BARS_UP_TO
    ):  # the true means right of the sources' bars
        bars(rec, f"{base}/true_means", style.BAR_TRUE_COLOR, arm + bar_offsets(M)[M],
             values=np.asarray(theory.mu, dtype=np.float64), width=width)  # fmt: skip
    static("about", rr.TextDocument.columns(text=[sources_markdown(config)],
                                            media_type=[rr.MediaType.MARKDOWN]))  # fmt: skip


def sources_markdown(config: RunConfig) -> str:
    """The run card of a run of several sources: a single source's, and what the views of
    several show."""
    M = config.sources
    colours = ", ".join(
        f"{style.source_name(m)} {_hex(style.source_color(m))}" for m in range(1, M + 1)
    )
    return (
        about_markdown(config)
        + f"\n\n**{M} sources** share the channels (colours: {colours}). Two sources on one "
        "channel collide and neither delivers (red crosses in the channel view). Source m's "
        "oracle plays the m-th best arm; the run's regret is the sum of the sources'.\n"
    )


def _hex(rgb: RGB) -> str:
    r, g, b = rgb
    return f"#{r:02x}{g:02x}{b:02x}"


class SourcesSink(Sink[SourcesBlock]):
    """Send the :class:`SourcesBlock` s of one run of several sources to ``recording`` under
    ``runs/<label>`` (the interface of :class:`~corraoi.recorder.rerun.sink.RerunSink`)."""

    def __init__(self, recording: rr.RecordingStream, label: str, config: RunConfig, *,
                 flush_timeout: float = 30.0, batch: int = BATCH,
                 color: RGB | None = None) -> None:  # fmt: skip
        if batch < 1:
            raise ValueError(f"batch must be >= 1, got {batch}")
        self.recording = recording
        self.label = label
        self.config = config
        self.base = run_path(label)
        self.M, self.K = config.sources, config.K
        self.batch = int(batch)
        self.flush_timeout = flush_timeout
        self.color = color if color is not None else style.spec_color(config.policy)
        self.slots = 0
        self.closed = False
        self.problem: str | None = None
        self._pending: list[SourcesBlock] = []
        self._pending_slots = 0
        self._every = snapshot_every(config.horizon)
        self._lanes = lane_offsets(self.M)
        self._snapped = 0
        self._last: tuple[int, np.ndarray] | None = None
        log_sources_static(recording, self.base, config)

    def write(self, block: SourcesBlock) -> None:
        if self.closed:
            raise ValueError(f"SourcesSink {self.label}: write() after close()")
        if not isinstance(block, SourcesBlock) or block.M != self.M:
            got = block.M if isinstance(block, SourcesBlock) else 1
            raise ValueError(f"block has {got} source(s), the run has {self.M}")
        if len(block) == 0:
            return
        self._pending.append(block)
        self._pending_slots += len(block)
        if self._pending_slots >= self.batch:
            self.send()

    def send(self) -> None:
        if not self._pending:
            return
        block = self._pending[0] if len(self._pending) == 1 else SourcesBlock.concat(self._pending)
        self._pending, self._pending_slots = [], 0
        self._send(block)

    def _column(self, path: str, t: np.ndarray, values: np.ndarray) -> None:
        if t.size:
            self.recording.send_columns(
                f"{self.base}/{path}",
                indexes=[rr.TimeColumn(TIMELINE, sequence=np.ascontiguousarray(t, np.int64))],
                columns=rr.Scalars.columns(scalars=np.ascontiguousarray(values, np.float64)),
            )

    def _send(self, block: SourcesBlock) -> None:
        t = np.ascontiguousarray(block.t, dtype=np.int64)
        first: SlotBlock = block.sources[0]
        absent = first.absent
        if "x" not in absent:
            self._column("x", t, block.x + 1.0)
        if "regret" not in absent:
            self._column("regret", t, np.sum([s.regret for s in block.sources], axis=0))
        for m, s in enumerate(block.sources, start=1):
            self._column(f"sources/{m}/aoi", t, s.aoi)
            if "oracle_aoi" not in absent:
                self._column(f"sources/{m}/oracle_aoi", t, s.oracle_aoi)
            if "regret" not in absent:
                self._column(f"sources/{m}/regret", t, s.regret)
            self._column(f"occupancy/{m}", t, s.arm + 1.0 + self._lanes[m - 1])
        arms = np.stack([s.arm for s in block.sources])  # (M, n)
        clash = np.zeros(arms.shape, dtype=bool)
        for s_i, s in enumerate(block.sources):
            if s.collided is not None:
                clash[s_i] = s.collided
        hit = clash.any(axis=0)  # one cross per slot and channel collided on
        for ch in np.unique(arms[clash]) if hit.any() else ():
            at = (clash & (arms == ch)).any(axis=0)
            self._column("occupancy/collided", t[at], np.full(int(at.sum()), ch + 1.0))
        at = np.flatnonzero((t % self._every == 0) | (t == 1))
        means = np.stack([s.mu_hat for s in block.sources])  # (M, n, K)
        if len(at):
            self._bars(t[at], means[:, at])
        self._last = (int(t[-1]), means[:, -1])
        self.slots += len(block)

    def _bars(self, t: np.ndarray, means: np.ndarray) -> None:
        """Each source's means at the slots ``t`` (``means``: M x len(t) x K)."""
        times = [rr.TimeColumn(TIMELINE, sequence=np.ascontiguousarray(t, dtype=np.int64))]
        if self.K > style.SOURCE_BARS_UP_TO:  # one sources x arms heatmap a slot
            table = np.nan_to_num(np.moveaxis(means, 0, 1))  # (len(t), M, K)
            self.recording.send_columns(
                f"{self.base}/means", indexes=times,
                columns=[rr.ComponentColumn(rr.Tensor.descriptor_data(), tensor_batch(table))],
            )  # fmt: skip
            self._snapped = int(t[-1])
            return
        descriptor = rr.BarChart.descriptor_values()
        for m in range(self.M):
            self.recording.send_columns(
                f"{self.base}/means/{m + 1}", indexes=times,
                columns=[rr.ComponentColumn(descriptor, tensor_batch(means[m]))],
            )  # fmt: skip
        self._snapped = int(t[-1])

    def finish(self) -> None:
        """Send the queued slots, and the means at the last slot when it was not a
        snapshot slot."""
        self.send()
        if self._last is not None and self._last[0] != self._snapped:
            t, means = self._last
            self._bars(np.array([t]), means[:, None, :])

    def close(self) -> str | None:
        if self.closed:
            return self.problem
        self.finish()
        self.closed = True
        try:
            self.recording.flush(timeout_sec=self.flush_timeout)
        except RuntimeError as exc:
            self.problem = first_line(exc)
        return self.problem


__all__ = [
    "COLLISION_COLOR",
    "SourcesSink",
    "bar_offsets",
    "log_sources_static",
    "sources_markdown",
]
