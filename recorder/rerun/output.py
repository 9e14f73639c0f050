"""Where one run's Rerun recording goes: :class:`RrdOutput`, an ``.rrd`` file (written as
``.partial``, checked and renamed into place) and/or a viewer (gRPC URL)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import NoReturn

import rerun as rr
import rerun.blueprint as rrb

from corraoi.engine.block import RunConfig
from corraoi.errors import ViewerError, WriteError
from corraoi.files.partial import PartialFile, reason
from corraoi.recorder.sink import Sink, made_again

from .layout import run_blueprint
from .names import new_recording


def first_line(exc: BaseException) -> str:
    """The first line of what an exception says (Rerun's errors run to many lines)."""
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


class RrdOutput(Sink[NoReturn]):  # a file or viewer: RerunSink writes, nothing is written here
    """Where one run's Rerun recording goes: an ``.rrd`` file and/or a viewer (gRPC URL).

    The file is written as ``<path>.partial`` (with the default blueprint embedded) and
    renamed to ``path`` by :meth:`close`; :meth:`abort` leaves the ``.partial`` file, or
    deletes it with ``discard_on_abort`` (replay and compare: their output can be made
    again). Leaving a ``with`` block through any exception, Ctrl-C included, aborts.
    ``recording`` is made here (:func:`new_recording`); hand it to :class:`RerunSink`.

    The default blueprint (``blueprint``, else the one-run layout) goes first; with
    ``blueprint_at_end`` none is sent then, and :meth:`close` sends the one given to
    :meth:`set_blueprint` after the data (a layout made from what was sent: ``compare``'s
    shared y-scales). ``name``: what the viewer lists the recording as (the run's label).
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
        blueprint_at_end: bool = False,
        name: str | None = None,
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
        self._out: PartialFile | None = None
        self._final_blueprint: rrb.Blueprint | None = None
        sinks: list[rr.FileSink | rr.GrpcSink] = []
        if rrd_path is not None:
            # create (or truncate) the .partial file here, so that an unwritable place is
            # one clear error now rather than a log line from Rerun's writer thread later;
            # kept open (locked) until the file is in place, so no other writer takes it
            self._out = PartialFile(rrd_path, overwrite=overwrite, what="Rerun recording",
                                    replaceable=made_again)  # fmt: skip
            self.path = self._out.path
            self._out.create()
            sinks.append(rr.FileSink(str(self._out.partial)))
        if viewer_url is not None:
            sinks.append(rr.GrpcSink(viewer_url))
        self.recording = new_recording(config, recording_id=recording_id, name=name)
        first = None if blueprint_at_end else blueprint or run_blueprint(self.label, config)
        try:
            self.recording.set_sinks(*sinks, default_blueprint=first)
        except (OSError, RuntimeError, ValueError) as exc:
            if self._out is not None:
                self._out.discard()
            raise WriteError(f"{self._where()}: cannot start the Rerun recording: {exc}") from None

    def set_blueprint(self, blueprint: rrb.Blueprint) -> None:
        """The blueprint :meth:`close` sends after the data (made with ``blueprint_at_end``)."""
        self._final_blueprint = blueprint

    def _where(self) -> str:
        return str(self._out.partial) if self._out is not None else str(self.viewer_url)

    def _finish(self) -> str | None:
        """Flush and disconnect; returns the problem Rerun reported, if any."""
        if self._final_blueprint is not None:
            self.recording.send_blueprint(self._final_blueprint, make_active=True,
                                          make_default=True)  # fmt: skip
        return finish_recording(self.recording, self.flush_timeout)

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
        if self._out is not None:
            try:
                check_rrd(self._out.partial, problem)
            except WriteError:
                self._out.leave()
                raise
            self._out.publish()
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
        if self._out is None:
            return None
        if discard is None:
            discard = self.discard_on_abort
        if discard:
            self._out.discard()
            return None
        return self._out.leave()


def finish_recording(recording: rr.RecordingStream, timeout: float = 30.0) -> str | None:
    """Flush and disconnect a recording; returns the problem Rerun reported, if any (its
    file writer stopped by a full disk, say), instead of raising it."""
    problem = None
    try:
        recording.flush(timeout_sec=timeout)
    except RuntimeError as exc:
        problem = first_line(exc)
    try:
        recording.disconnect()
    except RuntimeError as exc:
        problem = problem or first_line(exc)
    return problem


def check_rrd(part: Path, problem: str | None = None) -> None:
    """Refuse to present a damaged .rrd as complete: it must be non-empty and read back to
    its footer. ``problem``: what Rerun said while finishing it, if anything."""
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
                why = problem or first_line(exc)
    if why is not None:
        raise WriteError(
            f"{part}: Rerun could not write the whole recording ({why}; disk full?); "
            f"the incomplete file is left as {part}"
        )


__all__ = ["RrdOutput", "check_rrd", "finish_recording", "first_line"]
