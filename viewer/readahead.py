"""Reading a log ahead of the consumer: in a forked reader process, or in a thread.

Replaying a log is two jobs of about the same size: reading and decoding the messages,
and sending the blocks to Rerun. :func:`read_ahead` runs the first in a forked child
process (Linux, :class:`corraoi.forked.ForkedWorker`) that pickles the blocks down a pipe,
so the two use two cores. Elsewhere, where the fork rule forbids it (other threads running,
``CORRAOI_WORKERS=0``), or with ``CORRAOI_READ_AHEAD=thread``, it falls back to
:func:`prefetch`, a reader thread (which overlaps only the parts that release the GIL).
Either way an exception in the reader is raised in the consumer, and leaving the loop
early stops the reader.
"""

from __future__ import annotations

import os
import queue
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from functools import partial
from typing import Any, TypeVar

from corraoi.errors import ReaderStopped
from corraoi.forked import ForkedWorker, can_fork

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
    return can_fork()


def _produce(make_items: Callable[[], Iterable[Any]], conn: Any) -> None:
    """The reader process: send every item, then _Done (or _Raised)."""
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


def _forked(make_items: Callable[[], Iterable[T]], depth: int) -> Iterator[T]:
    reader = ForkedWorker(partial(_produce, make_items), name="corraoi-log-reader")

    def items() -> Iterator[T]:
        try:
            while True:
                try:
                    item = reader.conn.recv()
                except (EOFError, OSError):
                    raise ReaderStopped(reader.exitcode(5.0)) from None
                if isinstance(item, _Done):
                    return
                if isinstance(item, _Raised):
                    raise item.exc
                yield item
        finally:
            reader.stop()

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
