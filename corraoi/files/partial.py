"""The one protocol every writer of corraoi follows: :class:`PartialFile`.

A writer writes ``<path>.partial`` and renames it to ``<path>`` only once the file is
finished (footer written, data on disk). A writer that is killed leaves the ``.partial``
file, which a reader opens and reports as cut short. The ``.partial`` file carries the
writer's exclusive lock (:mod:`corraoi.files.locks`) for as long as it is open: a second writer of
the same path, with or without ``--force``, is refused at once with one line that names the
process holding it; ``--force`` only ever replaces files nobody is writing.

The sweep folder's own files (manifest, parts, summaries, plug-in copies), the recorder's
writers (``recorder/sink.py`` re-exports these names), the figures and ``recover`` all go
through it: check the target, create the ``.partial`` with its lock, publish it, or discard
it (or leave it, for a log finished as failed or interrupted).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from corraoi.errors import OutputError, WriteError

from .locks import fcntl, is_regular, lock_holder, pid_of_lock

#: What a file's name ends with while it is being written.
PARTIAL_SUFFIX = ".partial"


def partial_path(path: str | os.PathLike[str], suffix: str = PARTIAL_SUFFIX) -> Path:
    """Where the file for ``path`` lives while it is being written."""
    p = Path(path)
    return p.with_name(p.name + suffix)


def reason(exc: OSError) -> str:
    """The short text of an OS error ("No space left on device")."""
    return exc.strerror or str(exc)  # fmt: skip


def check_target(path: str | os.PathLike[str], *, overwrite: bool, what: str = "output",
                 replaceable: Callable[[Path], bool] | None = None, folder: bool = False,
                 suffix: str = PARTIAL_SUFFIX, sweep: bool = False) -> Path:  # fmt: skip
    """Refuse an output path that cannot or must not be written (one line: what, where, what
    to do); returns it as a Path. Nothing is created.

    Refused: no file name, a NUL byte, a directory (a regular file, for a ``folder`` target),
    a device, FIFO or socket, a dangling symbolic link, a folder on the way that is not one
    or not writable, a ``.partial`` that another process is writing (even with
    ``overwrite``), an existing target without ``overwrite``, and a ``.partial`` left by an
    earlier writer that stopped, unless ``overwrite`` or ``replaceable(partial)`` says that
    nothing is lost by writing over it (the same run, recorded again); and one of a sweep
    folder's own files unless ``sweep`` (the sweep's writers; :mod:`corraoi.files.guard`).
    """
    p = Path(path)
    if str(path) == "" or p.name in ("", ".", ".."):
        raise OutputError(f"{path!s}: not a file name for the {what}")
    if "\0" in str(path):
        raise OutputError(f"{path!r}: a NUL byte in the path of the {what}")
    if not sweep:
        from .guard import refuse_sweep_file

        refuse_sweep_file(p, what)
    _no_dangling_link(p, what)
    if folder and p.exists() and not p.is_dir():
        raise OutputError(f"{p}: exists and is not a directory; cannot write the {what} there")
    if not folder and p.is_dir():
        raise OutputError(f"{p}: is a directory; give a file path for the {what}")
    if not folder and p.exists() and not p.is_file():
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
    part = partial_path(p, suffix)
    holder = lock_holder(part)
    if holder is not None:
        raise OutputError(_busy(part, holder))
    if p.exists() and not overwrite:
        raise OutputError(f"{p}: already exists (use --force to overwrite it)")
    _no_dangling_link(part, what)
    if part.is_symlink():
        raise OutputError(f"{part}: is a symbolic link; not followed for the {what}")
    if part.exists() and (not part.is_dir() if folder else not part.is_file()):
        kind = "a directory" if part.is_dir() else "not a " + ("directory" if folder else
                                                               "regular file")  # fmt: skip
        raise OutputError(f"{part}: is {kind}; cannot write the {what} there")
    if part.exists() and not overwrite and not (replaceable is not None and replaceable(part)):
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
    return (f"{part}: is being written by {who} right now; not touched (wait for it, stop it, "
            "or give another output path)")  # fmt: skip


def fdopen(fd: int) -> BinaryIO:
    """The file object of a locked ``.partial`` (a seam: tests inject faults here)."""
    return os.fdopen(fd, "wb")  # noqa: SIM115 - PartialFile closes it


class PartialFile:
    """One output written as ``<path>.partial`` under its writer's lock, then published.

    The protocol, in four steps, each once::

        out = PartialFile(path, overwrite=force, what="MCAP log")  # 1. the target checked
        out.create()                     # 2. <path>.partial made (or taken over), locked
        out.file.write(...)              #    (or a library writes to out.partial by name)
        out.publish()                    # 3. synced, renamed into place while locked
        # or out.discard()               # 4. removed (ours only), or out.leave(): kept

    As a context manager, ``with PartialFile(...) as out:`` creates it, publishes it when the
    block ends normally and discards it when it ends through an exception (an OSError, a
    write that failed, becomes one WriteError line naming the file). ``folder=True``
    makes ``<path>.partial/`` a directory (``results.parquet``); ``suffix`` another name than
    ``.partial`` (``recover``, whose source is often that name). Every failure is one
    OutputError or WriteError line naming the file.
    """

    def __init__(self, path: str | os.PathLike[str], *, overwrite: bool = False,
                 what: str = "output", replaceable: Callable[[Path], bool] | None = None,
                 folder: bool = False, suffix: str = PARTIAL_SUFFIX, sweep: bool = False) -> None:
        self.path: Path = check_target(path, overwrite=overwrite, what=what, sweep=sweep,
                                       replaceable=replaceable, folder=folder, suffix=suffix)
        self.partial: Path = partial_path(self.path, suffix)
        self.overwrite, self.what, self.folder = overwrite, what, folder
        self._replaceable = replaceable
        self._fd: int | None = None
        self._file: BinaryIO | None = None
        self.state = "checked"  # then "open", and "published", "left" or "discarded"

    @property
    def file(self) -> BinaryIO:
        """The open ``.partial`` file (binary, locked)."""
        if self._file is None:
            raise ValueError(f"{self.partial}: not open (create() it first; not for a folder)")
        return self._file

    def create(self) -> PartialFile:
        """Make ``<path>.partial`` and take its lock; returns self. A ``.partial`` another
        process holds is refused, even with ``overwrite``; one left by a writer that stopped
        is taken over (truncated) only with ``overwrite`` or when ``replaceable``."""
        if self.state != "checked":
            raise ValueError(f"{self.partial}: create() twice")
        take_over = self.overwrite or (
            self._replaceable is not None and self.partial.exists()
            and self._replaceable(self.partial)
        )  # fmt: skip
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.folder:
                self._fd = self._create_folder(take_over)
            else:
                self._fd = self._create_file(take_over)
                self._file = fdopen(self._fd)
        except FileExistsError:
            holder = lock_holder(self.partial)
            if holder is not None:
                raise OutputError(_busy(self.partial, holder)) from None
            raise OutputError(
                f"{self.partial}: appeared while starting (another corraoi writing the same "
                "file?); use --force to overwrite it"
            ) from None
        except OSError as exc:
            why = {errno.ELOOP: f"is a symbolic link; not followed for the {self.what}",
                   errno.ENXIO: f"is not a regular file; cannot write the {self.what}"}.get(
                exc.errno or 0, f"cannot create the {self.what}: {reason(exc)}")  # fmt: skip
            raise OutputError(f"{self.partial}: {why}") from None
        self.state = "open"
        return self

    def _create_file(self, take_over: bool) -> int:
        part = self.partial
        # O_NONBLOCK: a FIFO under the .partial name fails (ENXIO) instead of waiting
        flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK
        if not take_over:
            flags |= os.O_EXCL
        for _ in range(10):
            fd = os.open(part, flags, 0o666)
            try:
                if not is_regular(os.fstat(fd).st_mode):
                    raise OutputError(f"{part}: is not a regular file; cannot write the "
                                      f"{self.what}")  # fmt: skip
                if fcntl is not None:
                    fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
                    if not self._lock(fd):
                        os.close(fd)
                        flags &= ~os.O_EXCL
                        continue
                os.ftruncate(fd, 0)
                return fd
            except BaseException:
                with contextlib.suppress(OSError):
                    os.close(fd)
                raise
        raise OutputError(f"{part}: keeps being replaced by another process; not written")

    def _create_folder(self, take_over: bool) -> int:
        part = self.partial
        if part.exists():
            if not take_over:
                raise FileExistsError(part)
            holder = lock_holder(part)
            if holder is not None:
                raise OutputError(_busy(part, holder))
            shutil.rmtree(part)
        part.mkdir()
        fd = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        try:
            if fcntl is not None and not self._lock(fd):
                raise FileExistsError(part)
        except BaseException:
            os.close(fd)
            raise
        return fd

    def _lock(self, fd: int) -> bool:
        """Take the exclusive lock on ``fd``; False when the file at the name is no longer
        the one locked (its last owner renamed or removed it meanwhile: try again)."""
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            st = os.fstat(fd)
            raise OutputError(_busy(self.partial, pid_of_lock(st.st_dev, st.st_ino))) from None
        try:
            return os.path.samestat(os.fstat(fd), os.stat(self.partial, follow_symlinks=False))
        except FileNotFoundError:
            return False

    def sync(self) -> None:
        """Flush and fsync what was written (raises OSError as the write would)."""
        if self._file is not None:
            self._file.flush()
        if self._fd is not None and not self.folder:
            os.fsync(self._fd)

    def publish(self, *, sync: bool = True) -> Path:
        """Sync the finished ``.partial`` and rename it to the target while its lock is held
        (without ``overwrite`` an existing target is never clobbered); returns the path.
        A failure is a WriteError (or OutputError: the target appeared meanwhile) and
        leaves the ``.partial`` where it is."""
        if self.state != "open":
            raise ValueError(f"{self.partial}: publish() when {self.state}")
        try:
            try:
                self.sync() if sync else self._file.flush() if self._file is not None else None
            except OSError as exc:
                raise WriteError(f"{self.partial}: cannot finish the {self.what}: "
                                 f"{reason(exc)} (the unfinished file is left as "
                                 f"{self.partial})") from None  # fmt: skip
            if self.folder:
                self._rename_folder()
            else:
                self._rename_file()
        except BaseException:
            self._close()
            self.state = "left"
            raise
        self._close()
        self.state = "published"
        return self.path

    def _rename_file(self) -> None:
        part, path = self.partial, self.path
        appeared = (f"{path}: appeared while the {self.what} was being written; the finished "
                    f"file was left as {part}")  # fmt: skip
        try:
            if self.overwrite:
                os.replace(part, path)
                return
            try:
                os.link(part, path)  # fails if path appeared meanwhile: never clobber
            except FileExistsError:
                raise OutputError(appeared) from None
            except OSError as exc:
                if exc.errno not in (errno.EPERM, errno.EXDEV, errno.ENOTSUP, errno.EOPNOTSUPP):
                    raise
                if path.exists() or path.is_symlink():
                    raise OutputError(appeared) from None
                os.replace(part, path)
                return
            os.unlink(part)
        except OSError as exc:
            raise WriteError(f"{path}: cannot rename {part} into place: {reason(exc)}") from None

    def _rename_folder(self) -> None:
        part, path = self.partial, self.path
        aside = path.with_name(f"{path.name}{PARTIAL_SUFFIX}.old-{os.getpid()}")
        try:
            moved = False
            if path.is_symlink() or path.exists():
                if not self.overwrite:
                    raise OutputError(f"{path}: appeared while the {self.what} was being "
                                      f"written; the finished folder was left as {part}")
                os.rename(path, aside)
                moved = True
            try:
                os.rename(part, path)
            except OSError:
                if moved:
                    os.rename(aside, path)
                raise
            if moved and aside.is_dir() and not aside.is_symlink():
                shutil.rmtree(aside, ignore_errors=True)
            elif moved:
                aside.unlink(missing_ok=True)
        except OSError as exc:
            raise WriteError(f"{path}: cannot rename {part} into place: {reason(exc)}") from None

    def leave(self) -> Path:
        """Stop writing and keep ``<path>.partial`` as it is (a log finished as failed or
        interrupted, or cut short): its lock is released. Returns the ``.partial`` path."""
        if self.state == "open":
            self._close()
            self.state = "left"
        return self.partial

    def discard(self) -> None:
        """Remove ``<path>.partial`` (ours: never one another process has taken since) and
        release its lock. Safe after publish (then it does nothing)."""
        if self.state != "open":
            return
        try:
            if self.folder:
                shutil.rmtree(self.partial, ignore_errors=True)
            elif self._fd is not None:
                with contextlib.suppress(OSError):
                    if os.path.samestat(os.fstat(self._fd),
                                        os.stat(self.partial, follow_symlinks=False)):
                        os.unlink(self.partial)  # fmt: skip
        finally:
            self._close()
            self.state = "discarded"

    def _close(self) -> None:
        f, self._file = self._file, None
        fd, self._fd = self._fd, None
        if f is not None:
            with contextlib.suppress(OSError, ValueError):
                f.close()
        elif fd is not None:
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> PartialFile:
        if self.state == "checked":
            self.create()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: object, tb: object) -> None:
        if self.state != "open":
            return
        if exc_type is None:
            self.publish()
            return
        self.discard()
        interrupt = masked_interrupt(exc)
        if interrupt is not None:
            raise interrupt
        if isinstance(exc, OSError):  # a write failed (disk full, ...): one line, the file named
            raise WriteError(f"{self.partial}: cannot write the {self.what}: {reason(exc)}")

    @classmethod
    def write_bytes(cls, path: str | os.PathLike[str], data: bytes, *, overwrite: bool = True,
                    what: str = "file", sync: bool = True, sweep: bool = False) -> Path:
        """Write ``data`` to ``path`` through the protocol (a small file in one go)."""
        with cls(path, overwrite=overwrite, what=what, sweep=sweep) as out:
            out.file.write(data)
            if not sync:
                out.publish(sync=False)
        return out.path


def masked_interrupt(exc: object) -> BaseException | None:
    """The Ctrl-C (or SIGTERM, SIGHUP: :mod:`corraoi._signals`) that ``exc`` replaced, if
    any: an error a library raised while cleaning up after a KeyboardInterrupt landed inside
    it. numpy's ``savez`` is one: interrupted between ``ZipFile.open(name, "w")`` and the
    block that closes the member, its ``finally`` calls ``ZipFile.close()``, which raises
    ValueError ("an open writing handle"). A writer then re-raises the interrupt, so that
    Ctrl-C stays Ctrl-C."""
    if not isinstance(exc, BaseException) or isinstance(exc, (KeyboardInterrupt, SystemExit)):
        return None
    seen: set[int] = set()
    cause = exc.__context__
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return cause
        seen.add(id(cause))
        cause = cause.__context__
    return None


__all__ = ["PARTIAL_SUFFIX", "PartialFile", "check_target", "fdopen", "masked_interrupt",
           "partial_path", "reason"]  # fmt: skip
