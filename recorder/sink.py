"""The protocol every writer of the recorder shares: :class:`Sink` (``write``, ``close``,
``abort``, a context manager), handed a run's slot blocks or a sweep's points.

A sink writes its file through :class:`~corraoi.files.partial.PartialFile` (the target
checked, ``<path>.partial`` created under its writer's lock, then published, discarded or
left, readable by ``corraoi info`` and ``recover``).
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, ClassVar, Generic, TypeVar

if TYPE_CHECKING:
    from typing_extensions import Self

    from corraoi.engine.block import RunBlock

#: What a sink is handed: a run's slot block, or a sweep's point.
Item = TypeVar("Item", contravariant=True)


def made_again(part: Path) -> bool:
    """A file made from another (a Rerun recording from its run's log, an export from its
    source) cut short at its ``.partial`` is made again whole: nothing is lost by writing
    over it, so it never blocks the next attempt (their ``replaceable``)."""
    return True


class Sink(Generic[Item]):
    """The context-manager protocol of every writer in ``recorder``: a ``Sink[SlotBlock]``
    takes a run's blocks, a ``Sink[SweepPoint]`` a sweep's points.

    Leaving the ``with`` block normally calls :meth:`close` (the file is finished and moved
    into place); leaving it through an exception calls :meth:`abort` (the file is finished
    as far as it got and left at its ``.partial`` name). Both are safe to call twice.
    Writers that treat Ctrl-C differently override ``__exit__``.

    A run of several sources is handed as :class:`~corraoi.engine.block.SourcesBlock` s, to
    the sinks that say they take them (:attr:`takes_sources`) only.
    """

    #: Whether ``write`` also takes a run of several sources' ``SourcesBlock`` (the MCAP log,
    #: the Rerun recording and Foxglove live do); a run refuses, before it starts, a sink
    #: that does not.
    takes_sources: ClassVar[bool] = False

    def write(self, item: Item, /) -> object:
        """Take the next item: a block of slots, or a sweep's point."""
        raise NotImplementedError

    def close(self) -> object:
        raise NotImplementedError

    def abort(self) -> object:
        return self.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class RunRecording(Sink["RunBlock"]):
    """One run's Rerun recording (an ``.rrd`` file and/or a viewer), whoever writes it:
    this process (:class:`corraoi.recorder.rerun.sink.LocalRecording`) or a forked worker
    (:class:`corraoi.recorder.rerun.worker.RemoteRecording`). ``record_run`` hands either the run's
    blocks like any other sink.

    :meth:`close` returns the ``.rrd`` path (None without a file) once the file is complete
    and in place, or raises :class:`~corraoi.errors.WriteError` (the file left at its
    ``.partial`` name) or :class:`~corraoi.errors.ViewerError`; :meth:`abort` stops, leaving
    the ``.partial`` (deleted with ``discard``). As a context manager: a normal exit closes,
    keeping a viewer's failure in :attr:`problem` (the file is complete) instead of raising
    it; Ctrl-C closes with the slots so far; any other exception aborts (discarding a file
    that holds no slot) and is the one raised, not the abort's own.
    """

    takes_sources = True  # a run of several sources too (Sink.takes_sources)

    #: the ``.rrd`` file's final path, None without one
    path: Path | None = None
    #: what close() returned: the file's path once it is in place
    result: Path | None = None
    #: a viewer that could not be reached (the file, if any, is complete)
    problem: str | None = None
    #: whether any block was written
    written: bool = False
    #: the WriteError close() raised on a normal exit (the file left at ``.partial``)
    error: Exception | None = None

    def write(self, block: RunBlock, /) -> None:
        self._write(block)
        self.written = True

    def _write(self, block: RunBlock) -> None:
        raise NotImplementedError

    def close(self) -> Path | None:
        raise NotImplementedError

    def abort(self, *, discard: bool | None = None) -> Path | None:
        raise NotImplementedError

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        from corraoi.errors import ViewerError, WriteError

        if exc_type is None:
            try:
                self.result = self.close()
            except ViewerError as err:
                self.result, self.problem = self.path, str(err)
            except WriteError as err:
                self.error = err
                raise
        elif issubclass(exc_type, (KeyboardInterrupt, SystemExit)):
            try:
                self.result = self.close()  # the slots so far, in a complete file
            except (ViewerError, WriteError):
                pass
        else:
            try:  # the run's own error is the one to report, not the abort's
                self.abort(discard=not self.written)
            except (ViewerError, WriteError):
                pass


__all__ = [
    "RunRecording",
    "Sink",
    "made_again",
]
