"""Forked worker processes: one object and one safety rule for every process corraoi forks.

corraoi forks two workers, each to put a slow import on the other core while this process
goes on (``docs/performance.md`` has what each buys, measured with ``CORRAOI_WORKERS=0``):
the Rerun writer of ``corraoi record`` (:mod:`corraoi.recorder.rerun.worker`) and the figure
drawer of ``corraoi sweep -o`` (:mod:`corraoi.viewer.figure_worker`). Each is a
:class:`ForkedWorker`: a process serving one end of a pipe.

The rule, :func:`can_fork`: fork only where ``fork`` exists and this process runs one
thread. A lock another thread holds at the fork (the import lock, a logger's, a test
runner's or a Dask client's) is never released in the child, which would wait on it for
ever; with other threads running, the callers do the job in this process instead. And the
child never outlives its parent: the kernel kills it when the parent dies, even by SIGKILL
(:func:`die_with_parent`), and it ignores Ctrl-C, SIGTERM and SIGHUP, which a terminal
sends to the whole process group: the parent decides, and asks it to finish or kills it.

``CORRAOI_WORKERS=0`` in the environment forks nothing (every job in this process):
``benchmarks/bench_start.py --no-workers`` times the commands so. (A third worker, the log
reader of ``replay`` and ``compare``, bought at most 5% and was retired for a thread.)
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable
from typing import Any

#: ``0`` (or ``off``): fork no worker, do every job in this process.
ENV = "CORRAOI_WORKERS"
#: The signals a terminal sends to the whole process group: the parent's to handle.
_TERMINAL = frozenset({signal.SIGINT, signal.SIGTERM, signal.SIGHUP})


def can_fork() -> bool:
    """Whether a worker may be forked now: ``fork`` exists, ``CORRAOI_WORKERS`` does not say
    ``0``, and this process runs one thread (see the module's note)."""
    if os.environ.get(ENV, "").strip().lower() in ("0", "off", "no", "false"):
        return False
    if not hasattr(os, "fork") or sys.platform == "win32":
        return False
    return threading.active_count() == 1


def die_with_parent(parent: int) -> None:
    """In a forked child: have the kernel kill it when its parent dies (Linux's
    ``PR_SET_PDEATHSIG``), and leave now if the parent ``parent`` is gone already.

    Without it a worker whose parent was SIGKILLed finishes what it is doing first: a
    figure it was drawing then lands in a sweep folder that a resumed sweep is writing, and
    the locks it inherited outlive the parent. Elsewhere the closed pipe still ends the
    worker, after its current task. (The signal follows the thread that forked: a worker is
    forked only from a process of one thread, :func:`can_fork`.)"""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux
    if os.getppid() != parent:  # it died before the line above
        os._exit(1)


def death_signal(sig: int = signal.SIGTERM) -> Callable[[], None] | None:
    """A ``preexec_fn`` for ``subprocess.Popen`` that has the kernel send ``sig`` to the
    child when this process dies (Linux; None elsewhere): a server started for the user (a
    Rerun viewer) never outlives the command. The libc symbol is looked up here, in the
    parent: the child only makes one system call."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None

    def set_death_signal() -> None:
        prctl(1, sig, 0, 0, 0)  # PR_SET_PDEATHSIG

    return set_death_signal


class ForkedWorker:
    """A forked process running ``serve(conn)`` on its end of a pipe; ``.conn`` is this
    process's end. Its users ask :func:`can_fork` first, and do the job in this process
    where the rule forbids a fork.

    In the child, before ``serve``: :func:`die_with_parent`, Ctrl-C, SIGTERM and SIGHUP
    ignored, this process's end of the pipe closed (so the child sees EOF when the parent
    is gone). The child exits when ``serve`` returns.
    """

    def __init__(self, serve: Callable[[Any], None], name: str) -> None:
        import multiprocessing

        ctx = multiprocessing.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_child, args=(serve, child, self.conn, os.getpid()),
                                daemon=True, name=name)  # fmt: skip
        for stream in (sys.stdout, sys.stderr):  # the child must not repeat buffered output
            try:
                stream.flush()
            except (OSError, ValueError, AttributeError):
                pass
        # a signal that came during the fork would be raised inside the fork's own hooks
        # (logging's lock release), where Python can only print it and lose it: it waits
        # until the fork is done, then the parent's handler takes it
        held = signal.pthread_sigmask(signal.SIG_BLOCK, _TERMINAL)
        try:
            with warnings.catch_warnings():  # Python 3.12+ warns of a fork with threads
                warnings.simplefilter("ignore", DeprecationWarning)
                self.proc.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)
        child.close()

    def alive(self) -> bool:
        return self.proc.is_alive()

    def exitcode(self, wait: float = 1.0) -> int | None:
        """The child's exit code once it ended (waiting up to ``wait`` s), else None."""
        self.proc.join(wait)
        return self.proc.exitcode

    def kill(self) -> None:
        """End the child now (SIGKILL; it ignores the polite signals). Safe twice."""
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join(1.0)

    def stop(self, goodbye: Any = None, wait: float = 5.0) -> None:
        """Let the child go: send ``goodbye`` (a message its ``serve`` ends on) and wait up
        to ``wait`` s, then kill it; close this end of the pipe. Safe twice."""
        if goodbye is not None and self.proc.is_alive():
            try:
                self.conn.send(goodbye)
            except (OSError, EOFError):
                pass
            self.proc.join(wait)
        self.kill()
        self.conn.close()


def _child(serve: Callable[[Any], None], conn: Any, parents_end: Any, parent: int) -> None:
    die_with_parent(parent)
    for sig in _TERMINAL:
        signal.signal(sig, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _TERMINAL)  # blocked over the fork
    parents_end.close()  # else the pipe would stay open here when the parent dies
    try:
        serve(conn)
    finally:
        conn.close()


__all__ = ["ENV", "ForkedWorker", "can_fork", "death_signal", "die_with_parent"]
