"""A Rerun recording written by a forked worker process while the engine runs.

Why a process: on the 2-core machine of our benchmarks ``import rerun`` takes 0.6 s, as
long as numba's import and the first kernel load together, and a one-run ``corraoi record``
would otherwise pay the two one after the other (issue 22). Forked before the parent
imports numba, the worker imports Rerun on the other core, then receives the run's
:class:`~corraoi.engine.block.SlotBlock` s over a pipe and feeds them to the same
:class:`~corraoi.recorder.rerun.output.RrdOutput` and
:class:`~corraoi.recorder.rerun.sink.RerunSink` that an in-process recording uses: the file is
the same, only the process differs.
``benchmarks/bench_start.py`` measures the gain (the "record --policy cucb" row).

``with RerunWorker.start() as worker: rec = worker.open(config, rrd_path=...)``, then
``rec.write(block)`` for each block and ``rec.close()`` (or ``rec.abort()``) with
:class:`~corraoi.recorder.sink.RunRecording`'s meaning: the file is renamed into place only when
complete; a problem raises the same :class:`~corraoi.errors.WriteError` or
:class:`~corraoi.errors.ViewerError`. :meth:`RerunWorker.start` returns None where
a process cannot be forked safely (:func:`corraoi.forked.can_fork`; then record in this
process, :class:`~corraoi.recorder.rerun.sink.LocalRecording`).

The worker is a :class:`corraoi.forked.ForkedWorker`: it ignores Ctrl-C, SIGTERM and
SIGHUP (the terminal sends them to the whole process group): the parent decides, and tells
it to finish or to abort. A parent that dies without a word (SIGKILL) takes the worker
with it (elsewhere the closed pipe makes it abort), leaving the ``.partial`` file, as an
in-process recording killed at that moment would.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable
from functools import partial
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

from corraoi.errors import ViewerError, WriteError
from corraoi.files.partial import check_target
from corraoi.forked import ForkedWorker, can_fork
from corraoi.recorder.sink import RunRecording, made_again

if TYPE_CHECKING:
    from multiprocessing.connection import Connection
    from multiprocessing.process import BaseProcess

    from corraoi.engine.block import RunBlock, RunConfig

#: seconds the parent waits for the worker's answer to close or abort: Rerun's own flush
#: timeout (30 s; on a full disk its flush waits for it now and then) and some to spare. A
#: worker that does not answer is killed and the recording reported as not written (its
#: .partial file left).
_ANSWER = 60.0
#: Seconds an abort (after the run failed) may take before the worker is killed.
_ABORT_WAIT = 10.0


class RerunWorker:
    """A worker process that imports Rerun now and writes recordings when asked."""

    def __init__(self, before_import: Callable[[], None] | None = None) -> None:
        self._worker = ForkedWorker(partial(serve, before_import), "corraoi-rerun")
        self._conn = self._worker.conn
        self._busy: RemoteRecording | None = None

    @property
    def process(self) -> BaseProcess:
        """The worker's process (``pid``, ``is_alive()``, ``join()``)."""
        return self._worker.proc

    @classmethod
    def start(cls, before_import: Callable[[], None] | None = None) -> RerunWorker | None:
        """A worker (``before_import()`` runs in it first), or None where a process cannot
        be forked safely (:func:`corraoi.forked.can_fork`)."""
        return cls(before_import) if can_fork() else None

    def open(
        self,
        config: RunConfig,
        *,
        rrd_path: str | os.PathLike[str] | None = None,
        viewer_url: str | None = None,
        overwrite: bool = False,
    ) -> RemoteRecording:
        """Start one run's recording in the worker (one at a time). The output path is
        checked here, so that a bad one is a clear error before the run starts."""
        if self._busy is not None and not self._busy.closed:
            raise RuntimeError("RerunWorker: one recording at a time")
        if rrd_path is None and viewer_url is None:
            raise ValueError("a Rerun recording needs an .rrd path, a viewer URL or both")
        path = None
        if rrd_path is not None:
            path = check_target(rrd_path, overwrite=overwrite, what="Rerun recording",
                                replaceable=made_again)  # fmt: skip
        self._busy = RemoteRecording(self, path)
        self._busy._send(("open", config, path, viewer_url, overwrite))
        return self._busy

    def _send(self, message: tuple[Any, ...]) -> None:
        try:
            self._conn.send(message)
        except (BrokenPipeError, ConnectionError, EOFError) as exc:
            raise WriteError(self._gone(exc)) from None

    def _ask(self, message: tuple[Any, ...], path: Path | None, wait: float = 0.0) -> Any:
        self._send(message)
        wait = wait or _ANSWER
        try:
            if not self._conn.poll(wait):
                self._worker.kill()
                raise WriteError(f"the Rerun writer process did not answer in {wait:.0f} s"
                                 + _left(path))  # fmt: skip
            return self._conn.recv()
        except (ConnectionError, EOFError) as exc:
            raise WriteError(self._gone(exc) + _left(path)) from None

    def _gone(self, exc: BaseException) -> str:
        code = self._worker.exitcode()
        how = f"exit code {code}" if code is not None else type(exc).__name__
        return f"the Rerun writer process ended unexpectedly ({how})"

    def stop(self) -> None:
        """Let the worker go (aborting a recording still open). Safe twice."""
        if self._busy is not None and not self._busy.closed:
            try:
                self._busy.abort()
            except WriteError:
                pass
        self._worker.stop(goodbye=("quit",))

    def __enter__(self) -> RerunWorker:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


class RemoteRecording(RunRecording):
    """One run's recording in a :class:`RerunWorker`: ``write``, then ``close`` or
    ``abort``, with :class:`~corraoi.recorder.sink.RunRecording`'s meaning."""

    def __init__(self, worker: RerunWorker, path: Path | None) -> None:
        self._worker = worker
        self.path = path
        self.closed = False
        self._result: Path | None = None
        #: a worker gone before the run ended: reported by close(), so that the run and
        #: its MCAP log go on to the end
        self._lost: WriteError | None = None

    def _send(self, message: tuple[Any, ...]) -> None:
        if self._lost is None:
            try:
                self._worker._send(message)
            except WriteError as exc:
                self._lost = exc

    def _write(self, block: RunBlock) -> None:
        if self.closed:
            raise ValueError("RemoteRecording: write() after close()")
        self._send(("write", block))

    def close(self) -> Path | None:
        """Deliver everything; returns the ``.rrd`` path (None without a file) or raises
        the worker's WriteError or ViewerError. Safe twice."""
        if self.closed:
            return self._result
        self.closed = True
        if self._lost is not None:
            raise WriteError(f"{self._lost}{_left(self.path)}")
        answer = self._worker._ask(("close",), self.path)
        if isinstance(answer, BaseException):
            raise answer
        self._result = answer
        return self._result

    def abort(self, *, discard: bool | None = None) -> Path | None:
        """Stop; the file stays at ``<path>.partial`` (deleted with ``discard``)."""
        if self.closed:
            return self._result
        self.closed = True
        if self._lost is not None:
            return None
        # an abort follows a failure (often a full disk, where Rerun's writer can block for
        # good): the .partial is all it leaves, so it is not worth the full wait
        answer = self._worker._ask(("abort", discard), self.path, wait=_ABORT_WAIT)
        return None if isinstance(answer, BaseException) else answer


def _left(path: Path | None) -> str:
    from corraoi.files.partial import partial_path

    if path is None or not partial_path(path).exists():
        return ""
    return f"; the incomplete file is left as {partial_path(path)}"


def serve(before_import: Callable[[], None] | None, conn: Connection) -> None:
    """The worker's loop: import Rerun, then carry out the parent's messages."""
    if before_import is not None:
        before_import()
    from .sink import LocalRecording

    rec: LocalRecording | None = None
    failure: BaseException | None = None  # what went wrong since "open"

    def reply(value: object) -> None:
        try:
            conn.send(value)
        except (pickle.PicklingError, TypeError, AttributeError):
            conn.send(WriteError(f"{type(value).__name__}: {value}"))

    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the parent is gone: leave the .partial file
            if rec is not None:
                rec.abort()
            return
        op = message[0]
        if op == "open":
            config, path, viewer_url, overwrite = message[1:]
            rec, failure = None, None
            try:
                rec = LocalRecording(config, rrd_path=path, viewer_url=viewer_url,
                                     overwrite=overwrite)  # fmt: skip
            except Exception as exc:  # noqa: BLE001 - reported to the parent at close
                failure = exc
        elif op == "write":
            if rec is not None and failure is None:
                try:
                    rec.write(message[1])
                except Exception as exc:  # noqa: BLE001 - reported to the parent at close
                    failure = exc
        elif op == "close":
            if failure is not None or rec is None:
                if rec is not None:
                    rec.abort()
                if not isinstance(failure, (WriteError, ViewerError)):
                    failure = WriteError(str(failure or "no recording was open"))
                reply(failure)
            else:
                try:
                    reply(rec.close())
                except Exception as exc:  # noqa: BLE001 - WriteError, ViewerError
                    reply(exc)
            rec = None
        elif op == "abort":
            reply(rec.abort(discard=message[1]) if rec is not None else None)
            rec = None
        elif op == "quit":
            if rec is not None:
                rec.abort()
            return


__all__ = ["RemoteRecording", "RerunWorker", "serve"]
