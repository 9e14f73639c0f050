"""A Rerun recording written by a forked worker process while the engine runs.

Why a process: on the 2-core machine of our benchmarks ``import rerun`` takes 0.6 s, as
long as numba's import and the first kernel load together, and a one-run ``corraoi record``
would otherwise pay the two one after the other (issue 22). Forked before the parent
imports numba, the worker imports Rerun on the other core, then receives the run's
:class:`~corraoi.engine.block.SlotBlock` s over a pipe and feeds them to the same
:class:`~recorder.rerun.output.RrdOutput` and :class:`~recorder.rerun.sink.RerunSink` that an
in-process recording uses: the file is the same, only the process differs.
``benchmarks/bench_start.py`` measures the gain (the "record --policy cucb" row).

``with RerunWorker.start() as worker: rec = worker.open(config, rrd_path=...)``, then
``rec.write(block)`` for each block and ``rec.close()`` (or ``rec.abort()``) with
:class:`RrdOutput`'s meaning: the file is renamed into place only when complete; a
problem raises the same :class:`~corraoi.errors.WriteError` or
:class:`~corraoi.errors.ViewerError`. :meth:`RerunWorker.start` returns None where
``fork`` is not available (then record in-process).

The worker ignores Ctrl-C, SIGTERM and SIGHUP (the terminal sends them to the whole
process group): the parent decides, and tells it to finish or to abort. A parent that
dies without a word (SIGKILL) takes the worker with it (:func:`die_with_parent`; elsewhere
the closed pipe makes it abort), leaving the ``.partial`` file, as an in-process recording
killed at that moment would.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import Any

from corraoi.errors import ViewerError, WriteError
from corraoi.files.partial import check_target
from recorder.sink import Sink, made_again

#: seconds the parent waits for the worker's answer to close or abort: Rerun's own flush
#: timeout (30 s; on a full disk its flush waits for it now and then) and some to spare. A
#: worker that does not answer is killed and the recording reported as not written (its
#: .partial file left).
_ANSWER = 60.0
#: Seconds an abort (after the run failed) may take before the worker is killed.
_ABORT_WAIT = 10.0


def fork_context() -> Any:
    """multiprocessing's ``fork`` context, or None where forking this process now is not
    safe: no ``fork`` (Windows), or other threads running (one may hold a lock, the import
    lock or a logger's, that the child would wait on for ever: a test runner's, a Dask
    client's or an application's threads)."""
    import threading

    if "fork" not in multiprocessing.get_all_start_methods():
        return None
    if threading.active_count() > 1:
        return None
    return multiprocessing.get_context("fork")


def die_with_parent(parent: int) -> None:
    """Have the kernel kill this forked worker when its parent dies (Linux's
    ``PR_SET_PDEATHSIG``); leave now if the parent ``parent`` is gone already.

    Without it a worker whose parent was SIGKILLed finishes what it is doing first: a
    figure it was drawing then lands in a sweep folder that a resumed sweep is writing, and
    the locks it inherited (the folder's) outlive the parent. Elsewhere the closed pipe
    still ends the worker, after its current task. (The signal follows the thread that
    forked; the workers fork only a process with one thread, :func:`fork_context`.)"""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux
    if os.getppid() != parent:  # it died before the line above
        os._exit(0)


class RerunWorker:
    """A worker process that imports Rerun now and writes recordings when asked."""

    def __init__(self, before_import: Callable[[], None] | None = None) -> None:
        ctx = multiprocessing.get_context("fork")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve,
                                 args=(child, self._conn, before_import, os.getpid()),
                                 daemon=True, name="corraoi-rerun")  # fmt: skip
        self._proc.start()
        child.close()
        self._busy: RemoteRecording | None = None

    @classmethod
    def start(cls, before_import: Callable[[], None] | None = None) -> RerunWorker | None:
        """A worker, or None where a process cannot be forked safely (:func:`fork_context`)."""
        return cls(before_import) if fork_context() is not None else None

    def open(
        self,
        config: Any,
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
                self._proc.kill()
                raise WriteError(f"the Rerun writer process did not answer in {wait:.0f} s"
                                 + _left(path))  # fmt: skip
            return self._conn.recv()
        except (ConnectionError, EOFError) as exc:
            raise WriteError(self._gone(exc) + _left(path)) from None

    def _gone(self, exc: BaseException) -> str:
        self._proc.join(1.0)
        code = self._proc.exitcode
        how = f"exit code {code}" if code is not None else type(exc).__name__
        return f"the Rerun writer process ended unexpectedly ({how})"

    def stop(self) -> None:
        """Let the worker go (aborting a recording still open). Safe twice."""
        if self._busy is not None and not self._busy.closed:
            try:
                self._busy.abort()
            except WriteError:
                pass
        if self._proc.is_alive():
            try:
                self._conn.send(("quit",))
            except (OSError, EOFError):
                pass
            self._proc.join(5.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(1.0)
        self._conn.close()

    def __enter__(self) -> RerunWorker:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


class RemoteRecording(Sink):
    """One run's recording in a :class:`RerunWorker`: ``write``, then ``close`` or
    ``abort``, with :class:`~recorder.rerun.output.RrdOutput`'s meaning."""

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

    def write(self, block: Any) -> None:
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


def _serve(
    conn: Any, parents_end: Any, before_import: Callable[[], None] | None, parent: int
) -> None:
    """The worker's loop: import Rerun, then carry out the parent's messages."""
    die_with_parent(parent)
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    parents_end.close()  # else the pipe would stay open here when the parent dies
    if before_import is not None:
        before_import()
    from .output import RrdOutput
    from .sink import RerunSink

    output: RrdOutput | None = None
    sink: RerunSink | None = None
    failure: BaseException | None = None  # what went wrong since "open"

    def reply(value: Any) -> None:
        try:
            conn.send(value)
        except (pickle.PicklingError, TypeError, AttributeError):
            conn.send(WriteError(f"{type(value).__name__}: {value}"))

    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the parent is gone: leave the .partial file
            if output is not None:
                output.abort()
            return
        op = message[0]
        if op == "open":
            config, path, viewer_url, overwrite = message[1:]
            output, sink, failure = None, None, None
            try:
                output = RrdOutput(config, rrd_path=path, viewer_url=viewer_url,
                                   overwrite=overwrite)  # fmt: skip
                sink = RerunSink(output.recording, config.label, config)
            except Exception as exc:  # noqa: BLE001 - reported to the parent at close
                failure = exc
        elif op == "write":
            if sink is not None and failure is None:
                try:
                    sink.write(message[1])
                except Exception as exc:  # noqa: BLE001 - reported to the parent at close
                    failure = exc
        elif op == "close":
            if failure is not None or output is None or sink is None:
                if output is not None:
                    output.abort()
                if not isinstance(failure, (WriteError, ViewerError)):
                    failure = WriteError(str(failure or "no recording was open"))
                reply(failure)
            else:
                try:
                    sink.finish()  # the slots it holds; output.close() flushes them, once
                    reply(output.close())
                except Exception as exc:  # noqa: BLE001 - WriteError, ViewerError
                    reply(exc)
            output, sink = None, None
        elif op == "abort":
            reply(output.abort(discard=message[1]) if output is not None else None)
            output, sink = None, None
        elif op == "quit":
            if output is not None:
                output.abort()
            return


__all__ = ["RemoteRecording", "RerunWorker", "fork_context"]
