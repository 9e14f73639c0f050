"""Output files that are never presented as complete before they are.

A writer writes ``<path>.partial`` and renames it to ``<path>`` only once the file is
finished (footer written, data on disk). A writer that is killed leaves the ``.partial``
file, which the reader opens and reports as cut short.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, BinaryIO

if TYPE_CHECKING:
    from typing_extensions import Self

from .errors import OutputError, WriteError

PARTIAL_SUFFIX = ".partial"


class Sink:
    """The context-manager protocol of every writer in ``recorder``.

    Leaving the ``with`` block normally calls :meth:`close` (the file is finished and moved
    into place); leaving it through an exception calls :meth:`abort` (the file is finished
    as far as it got and left at its ``.partial`` name). Both are safe to call twice.
    Writers that treat Ctrl-C differently override ``__exit__``.
    """

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


def partial_path(path: str | os.PathLike[str]) -> Path:
    """Where the file for ``path`` lives while it is being written."""
    p = Path(path)
    return p.with_name(p.name + PARTIAL_SUFFIX)


def check_output(path: str | os.PathLike[str], *, overwrite: bool, what: str = "output") -> Path:
    """Refuse an output path that cannot or must not be written; returns it as a Path."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputError(f"{path!s}: not a file name for the {what}")
    if p.is_dir():
        raise OutputError(f"{p}: is a directory; give a file path for the {what}")
    parent = p.parent
    for up in (parent, *parent.parents):
        if up.exists():
            if not up.is_dir():
                raise OutputError(f"{p}: {up} is not a directory")
            break
    if p.exists() and not overwrite:
        raise OutputError(f"{p}: already exists (use --force to overwrite it)")
    part = partial_path(p)
    if part.is_dir():
        raise OutputError(f"{part}: is a directory; cannot write the {what} there")
    if part.exists() and not overwrite:
        raise OutputError(
            f"{part}: a partial file of an earlier run that did not finish is in the way "
            "(open it with `corraoi info`, move it, or use --force to overwrite it)"
        )
    return p


def open_partial(path: Path, *, overwrite: bool, what: str = "output") -> BinaryIO:
    """Create the parent directories and open ``<path>.partial`` for writing."""
    part = partial_path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        return open(part, "wb" if overwrite else "xb")  # noqa: SIM115 - the sink owns it
    except FileExistsError:
        raise OutputError(
            f"{part}: appeared while starting (another corraoi writing the same file?); "
            "use --force to overwrite it"
        ) from None
    except OSError as exc:
        raise OutputError(f"{part}: cannot create the {what}: {reason(exc)}") from None


def publish(path: Path, *, overwrite: bool) -> None:
    """Rename the finished ``<path>.partial`` to ``path`` (atomically where possible)."""
    part = partial_path(path)
    try:
        if overwrite:
            os.replace(part, path)
            return
        try:
            os.link(part, path)  # fails if path appeared meanwhile: never clobber
        except FileExistsError:
            raise OutputError(
                f"{path}: appeared while the run was being written; the finished file "
                f"was left as {part}"
            ) from None
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.EXDEV, errno.ENOTSUP, errno.EOPNOTSUPP):
                raise
            if path.exists():
                raise OutputError(
                    f"{path}: appeared while the run was being written; the finished file "
                    f"was left as {part}"
                ) from None
            os.replace(part, path)
            return
        os.unlink(part)
    except OSError as exc:
        raise WriteError(f"{path}: cannot rename {part} into place: {reason(exc)}") from None


def reason(exc: OSError) -> str:
    """The short text of an OS error ("No space left on device")."""
    return exc.strerror or str(exc)
