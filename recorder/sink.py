"""The protocol every writer of the recorder shares: :class:`Sink` (``write``, ``close``,
``abort``, a context manager), handed a run's slot blocks or a sweep's points.

A sink writes its file through :class:`~corraoi.files.partial.PartialFile` (the target
checked, ``<path>.partial`` created under its writer's lock, then published, discarded or
left, readable by ``corraoi info`` and ``recover``).
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from typing_extensions import Self


def made_again(part: Path) -> bool:
    """A file made from another (a Rerun recording from its run's log, an export from its
    source) cut short at its ``.partial`` is made again whole: nothing is lost by writing
    over it, so it never blocks the next attempt (their ``replaceable``)."""
    return True


class Sink:
    """The context-manager protocol of every writer in ``recorder``.

    Leaving the ``with`` block normally calls :meth:`close` (the file is finished and moved
    into place); leaving it through an exception calls :meth:`abort` (the file is finished
    as far as it got and left at its ``.partial`` name). Both are safe to call twice.
    Writers that treat Ctrl-C differently override ``__exit__``.
    """

    def write(self, *args: Any, **kwargs: Any) -> Any:
        """Take the next item: a block of slots, or a sweep's point."""
        raise NotImplementedError

    def close(self) -> Any:
        raise NotImplementedError

    def abort(self) -> Any:
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


__all__ = [
    "Sink",
    "made_again",
]
