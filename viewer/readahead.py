"""Reading a log ahead of the consumer, in a thread.

Replaying a log is two jobs of about the same size: reading and decoding the messages, and
sending the blocks to Rerun. :func:`read_ahead` reads in a thread a few blocks ahead, which
overlaps the parts that release the GIL (zstd, file reads); an exception in the reader is
raised in the consumer, and leaving the loop early stops the reader. (A forked reader
process, which overlapped all of it, made ``replay`` and ``compare`` at most 5% faster as
whole processes: not the 15% a forked process must earn, ``docs/performance.md``.)
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")


class _Raised:
    def __init__(self, exc: BaseException) -> None:
        self.exc = exc


class _Done:
    pass


def read_ahead(items: Iterable[T], *, depth: int = 8) -> Iterator[T]:
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


__all__ = ["read_ahead"]
