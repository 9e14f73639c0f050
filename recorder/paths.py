"""Output files that are never presented as complete before they are, and never shared.

A writer writes ``<path>.partial`` and renames it to ``<path>`` only once the file is
finished (footer written, data on disk). A writer that is killed leaves the ``.partial``
file, which the reader opens and reports as cut short.

The ``.partial`` file itself carries an exclusive lock (``flock``) for as long as its
writer has it open: no lock file beside it, and the lock dies with the process. A second
writer of the same path, with or without ``--force``, is refused at once with one line
that names the process holding it (:func:`lock_holder`); ``--force`` only ever replaces
files nobody is writing.

Output names made from data (instance, policy, plug-in names) go through
:func:`safe_name` first, so that they cannot leave the output folder.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, BinaryIO

if TYPE_CHECKING:
    from typing_extensions import Self

from corraoi.errors import OutputError, WriteError
from corraoi.locks import fcntl, is_regular, lock_holder, pid_of_lock
from corraoi.text import safe_name

PARTIAL_SUFFIX = ".partial"


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
    "PARTIAL_SUFFIX",
    "Sink",
    "check_output",
    "lock_holder",
    "open_partial",
    "partial_path",
    "publish",
    "reason",
    "safe_name",
    "unlink_partial",
]


def partial_path(path: str | os.PathLike[str]) -> Path:
    """Where the file for ``path`` lives while it is being written."""
    p = Path(path)
    return p.with_name(p.name + PARTIAL_SUFFIX)


def check_output(path: str | os.PathLike[str], *, overwrite: bool, what: str = "output") -> Path:
    """Refuse an output path that cannot or must not be written; returns it as a Path."""
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputError(f"{path!s}: not a file name for the {what}")
    if "\0" in str(path):
        raise OutputError(f"{path!r}: a NUL byte in the path of the {what}")
    if p.is_dir():
        raise OutputError(f"{p}: is a directory; give a file path for the {what}")
    _no_dangling_link(p, what)
    if p.exists() and not p.is_file():
        raise OutputError(f"{p}: is not a regular file (a device, FIFO or socket); give a "
                          f"file path for the {what}")  # fmt: skip
    parent = p.parent
    for up in (parent, *parent.parents):
        if up.exists():
            if not up.is_dir():
                raise OutputError(f"{p}: {up} is not a directory")
            if not os.access(up, os.W_OK | os.X_OK):
                raise OutputError(f"{p}: the folder {up} is not writable")
            break
    part = partial_path(p)
    holder = lock_holder(part)
    if holder is not None:
        raise OutputError(_busy(part, holder))
    if p.exists() and not overwrite:
        raise OutputError(f"{p}: already exists (use --force to overwrite it)")
    if part.is_dir():
        raise OutputError(f"{part}: is a directory; cannot write the {what} there")
    _no_dangling_link(part, what)
    if part.exists() and not overwrite:
        raise OutputError(
            f"{part}: a partial file of an earlier run that did not finish is in the way "
            "(open it with `corraoi info`, move it, or use --force to overwrite it)"
        )
    return p


def _no_dangling_link(p: Path, what: str) -> None:
    if p.is_symlink() and not p.exists():
        try:
            target = os.readlink(p)
        except OSError:
            target = "?"
        raise OutputError(
            f"{p}: is a symbolic link to {target}, which does not exist; remove the link "
            f"or give another path for the {what}"
        )


def _busy(part: Path, holder: int) -> str:
    who = f"process {holder}" if holder > 0 else "another process"
    return (
        f"{part}: is being written by {who} right now; not touched (wait for it, stop it, "
        "or give another output path)"
    )


def _fdopen(fd: int) -> BinaryIO:
    """The file object of a locked ``.partial`` (a seam: tests inject faults here)."""
    return os.fdopen(fd, "wb")


def open_partial(path: Path, *, overwrite: bool, what: str = "output") -> BinaryIO:
    """Create the parent directories and open ``<path>.partial`` for writing, locked.

    The exclusive lock lives as long as the returned file is open: keep it open until the
    file is renamed into place (:func:`publish`). A ``.partial`` that another process
    holds is refused, even with ``overwrite``; it is truncated only once it is ours.
    """
    part = partial_path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC
    if not overwrite:
        flags |= os.O_EXCL
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(10):
            fd = os.open(part, flags, 0o666)
            try:
                if not is_regular(os.fstat(fd).st_mode):
                    raise OutputError(f"{part}: is not a regular file; cannot write the {what}")
                if fcntl is not None:
                    try:
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    except BlockingIOError:
                        st = os.fstat(fd)
                        raise OutputError(_busy(part, pid_of_lock(st.st_dev, st.st_ino))) from None
                    # the file we locked may have been renamed or removed by its last owner
                    # between our open and our lock: then lock the one at the path now
                    try:
                        same = os.path.samestat(os.fstat(fd), os.stat(part, follow_symlinks=False))
                    except FileNotFoundError:
                        same = False
                    if not same:
                        os.close(fd)
                        flags &= ~os.O_EXCL
                        continue
                os.ftruncate(fd, 0)
                return _fdopen(fd)
            except BaseException:
                try:
                    os.close(fd)
                except OSError:
                    pass
                raise
        raise OutputError(f"{part}: keeps being replaced by another process; not written")
    except FileExistsError:
        holder = lock_holder(part)
        if holder is not None:
            raise OutputError(_busy(part, holder)) from None
        raise OutputError(
            f"{part}: appeared while starting (another corraoi writing the same file?); "
            "use --force to overwrite it"
        ) from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputError(f"{part}: is a symbolic link; not followed for the {what}") from None
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


def unlink_partial(path: Path) -> None:
    """Remove ``<path>.partial`` unless another process holds it (an abort with nothing
    written: never delete what someone else is writing)."""
    part = partial_path(path)
    if lock_holder(part) is None:
        part.unlink(missing_ok=True)


def reason(exc: OSError) -> str:
    """The short text of an OS error ("No space left on device")."""
    return exc.strerror or str(exc)
