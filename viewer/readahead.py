"""Reading a log ahead of the consumer: in a forked reader process, or in a thread.

Replaying a log is two jobs of about the same size: reading and decoding the messages,
and sending the blocks to Rerun. :func:`read_ahead` runs the first in a forked child
process (Linux) that pickles the blocks down a pipe, so the two use two cores; elsewhere,
or with ``CORRAOI_READ_AHEAD=thread``, it falls back to :func:`prefetch`, a reader thread
(which overlaps only the parts that release the GIL). Either way an exception in the
reader is raised in the consumer, and leaving the loop early stops the reader.
"""

from __future__ import annotations

import os
import queue
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

from corraoi.errors import ReaderStopped

T = TypeVar("T")

#: ``fork`` (default on Linux with 2+ cores) or ``thread``.
ENV = "CORRAOI_READ_AHEAD"


class _Raised:
    def __init__(self, exc: BaseException) -> None:
        self.exc = exc


class _Done:
    pass


def read_ahead(make_items: Callable[[], Iterable[T]], *, depth: int = 8) -> Iterator[T]:
    """Iterate ``make_items()`` produced ``depth`` items ahead, in a reader process if
    possible. ``make_items`` is called in the reader; the items must pickle."""
    if _can_fork():
        return _forked(make_items, depth)
    return prefetch(make_items(), depth=depth)


def _can_fork() -> bool:
    choice = os.environ.get(ENV, "").strip().lower()
    if choice == "thread":
        return False
    if not sys.platform.startswith("linux") or (os.cpu_count() or 1) < 2:
        return False
    import multiprocessing

    return "fork" in multiprocessing.get_all_start_methods()


def _die_with_parent(parent: int) -> None:
    """Linux: have the kernel send SIGKILL to this process when its parent dies (even by
    SIGKILL), so that a killed replay or compare never leaves its reader behind."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux/glibc: the pipe's EOF still ends us
        pass
    if os.getppid() != parent:  # the parent died before the line above took effect
        os._exit(1)


_PR_SET_PDEATHSIG = 1


def _produce(make_items: Callable[[], Iterable[Any]], conn: Any, parent: int = 0) -> None:
    """The reader process: send every item, then _Done (or _Raised)."""
    if parent:
        _die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # terminate() from the parent ends us
    try:
        for item in make_items():
            conn.send(item)
        conn.send(_Done())
    except (BrokenPipeError, EOFError):
        pass  # the consumer stopped early
    except BaseException as exc:  # noqa: BLE001 - handed to the consumer
        try:
            conn.send(_Raised(exc))
        except Exception:  # noqa: BLE001 - an exception that does not pickle
            conn.send(_Raised(RuntimeError(f"{type(exc).__name__}: {exc}")))
    finally:
        conn.close()


def _forked(make_items: Callable[[], Iterable[T]], depth: int) -> Iterator[T]:
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_produce, args=(make_items, send, os.getpid()), daemon=True)
    for stream in (sys.stdout, sys.stderr):  # the child must not repeat buffered output
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    with warnings.catch_warnings():  # Python 3.12+: fork with threads: the child only reads
        warnings.simplefilter("ignore", DeprecationWarning)
        proc.start()
    send.close()

    def items() -> Iterator[T]:
        try:
            while True:
                try:
                    item = receive.recv()
                except (EOFError, OSError):
                    proc.join(timeout=5)
                    raise ReaderStopped(proc.exitcode) from None
                if isinstance(item, _Done):
                    return
                if isinstance(item, _Raised):
                    raise item.exc
                yield item
        finally:
            receive.close()
            if proc.is_alive():
                proc.terminate()
            proc.join(timeout=5)

    return items()


def prefetch(items: Iterable[T], *, depth: int = 4) -> Iterator[T]:
    """Iterate ``items`` in a background thread, ``depth`` items ahead of the consumer."""
    q: queue.Queue[object] = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(item: object) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def work() -> None:
        try:
            for item in items:
                if not put(item):
                    return
            put(_Done())
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer
            put(_Raised(exc))

    thread = threading.Thread(target=work, name="corraoi-log-reader", daemon=True)
    thread.start()
    try:
        while True:
            item = q.get()
            if isinstance(item, _Done):
                return
            if isinstance(item, _Raised):
                raise item.exc
            yield item  # type: ignore[misc]
    finally:
        stop.set()
        thread.join(timeout=5)
