"""Sweep figures drawn by a forked worker process while the sweep runs.

Why a process: a sweep folder's ``figure.png`` costs about 1.3 s on the 2-core machine of
our benchmarks, 0.9 s of it importing matplotlib, more than a small sweep's simulation,
and the parent then still imports Rerun (0.6 s) for ``sweep.rrd``. Forked when the sweep
starts, the worker imports matplotlib on the other core while the engine loads and runs;
then it draws each group's figure from its finished sweep log while this process writes
the group's Rerun recording (``benchmarks/bench_start.py``, the ``sweep -o`` row). The
figure is the one :func:`corraoi.viewer.figure.draw_figure` draws in-process: only the process
differs.

``FigureWorker.start()`` returns None where a process cannot be forked safely
(:func:`corraoi.forked.can_fork`); :class:`corraoi.face.outputs.FolderOutputs` then draws
in-process. Nothing is lost when the worker fails: a figure it did not deliver (it died,
did not answer, or its answer could not be read) is drawn in this process instead. The
worker is a :class:`corraoi.forked.ForkedWorker`: it ignores Ctrl-C, SIGTERM and SIGHUP
(the parent decides), and a parent that dies without a word takes it with it, mid-figure
if need be.
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import Any

from corraoi.forked import ForkedWorker, can_fork

#: Seconds the parent waits for one figure before drawing it itself.
_ANSWER = 120.0


class FigureWorker:
    """A worker process that imports matplotlib now and draws sweep figures when asked."""

    def __init__(self) -> None:
        self._worker = ForkedWorker(_serve, "corraoi-figures")
        self._conn = self._worker.conn
        self._pending: list[tuple[Path, Path]] = []
        self._alive = True

    @property
    def process(self) -> Any:
        """The worker's process (``pid``, ``is_alive()``, ``join()``)."""
        return self._worker.proc

    @classmethod
    def start(cls) -> FigureWorker | None:
        """A worker, or None where one cannot be forked safely."""
        return cls() if can_fork() else None

    def draw(self, log: Path, out: Path) -> None:
        """Ask for ``out`` drawn from the sweep log ``log``; :meth:`results` delivers it."""
        self._pending.append((log, out))
        if self._alive:
            try:
                self._conn.send(("draw", str(log), str(out)))
            except OSError:
                self._alive = False

    def results(self) -> list[tuple[Path, BaseException | None]]:
        """Wait for every figure asked for: ``(out, None)`` when written, ``(out, exc)`` with
        the exception ``draw_figure`` raised (FigureUnavailable, UsageError, OSError...).
        A figure the worker did not deliver is drawn here."""
        done: list[tuple[Path, BaseException | None]] = []
        pending, self._pending = self._pending, []
        for log, out in pending:
            answer: Any = _LOST
            if self._alive:
                try:
                    if self._conn.poll(_ANSWER):
                        answer = self._conn.recv()
                except (OSError, EOFError, ImportError, AttributeError, TypeError):
                    pass
                if answer is _LOST:  # dead, silent or unreadable: no more asking it
                    self._alive = False
                    self._kill(out)
            if answer is _LOST:
                answer = draw_from_log(str(log), str(out))
            done.append((out, answer))
        return done

    def _kill(self, out: Path) -> None:
        self._worker.kill()
        from corraoi.files.partial import partial_path

        partial_path(out).unlink(missing_ok=True)  # a drawing cut short

    def stop(self) -> None:
        """Let the worker go, at once: by now every figure asked for was delivered
        (:meth:`results`) or is abandoned (an error or Ctrl-C ended the sweep), and the worker
        holds nothing else. It is killed rather than asked to quit, which it would hear only
        after importing matplotlib (about a second): an interrupted sweep still ends within
        one (issue 19). Safe twice."""
        self._worker.stop()
        from corraoi.files.partial import partial_path

        for _, out in self._pending:  # a drawing cut short
            partial_path(out).unlink(missing_ok=True)
        self._pending = []

    def __enter__(self) -> FigureWorker:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()


_LOST = object()


def draw_from_log(log: str, out: str) -> BaseException | None:
    """draw_figure(read_sweep(log), out): None, or the exception it raised."""
    from corraoi.recorder.sweeplog.read import read_sweep

    from .figure import draw_figure

    try:
        draw_figure(read_sweep(Path(log)), Path(out))
    except Exception as exc:  # noqa: BLE001 - the caller reports it as the in-process path does
        return exc
    return None


def _serve(conn: Any) -> None:
    """The worker's loop: import matplotlib, then draw what the parent asks for."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: F401
        from matplotlib.figure import Figure  # noqa: F401
    except ImportError:
        pass  # draw_figure says so, per figure
    while True:
        try:
            message = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            return
        if message[0] != "draw":
            return
        failure = draw_from_log(message[1], message[2])
        try:
            conn.send(failure)
        except Exception:  # noqa: BLE001 - an exception that cannot be pickled: say so
            conn.send(RuntimeError(f"{type(failure).__name__}: {failure}"))


__all__ = ["FigureWorker", "draw_from_log"]
