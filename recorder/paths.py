"""Output files that are never presented as complete before they are, and never shared.

Every writer of the recorder goes through :class:`~corraoi.files.locks.PartialFile` (the core's,
since the sweep folder's own files use it too): the target checked, ``<path>.partial``
created under its writer's lock, then published (renamed into place), discarded or left
(a log finished as failed or interrupted, readable by ``corraoi info`` and ``recover``).
A second writer of the same path is refused at once with one line that names the process
holding it; ``--force`` only ever replaces files nobody is writing.

:class:`Sink` is the context-manager protocol of every writer here. Output names made
from data (instance, policy, plug-in names) go through :func:`safe_name` first, so that
they cannot leave the output folder.
"""

from __future__ import annotations

from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from typing_extensions import Self

from corraoi.files.partial import check_target

#: The check of an output path before anything runs (the first step of PartialFile).
check_output = check_target


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
    "check_output",
    "made_again",
]
