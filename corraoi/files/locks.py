"""Locks that die with their process: ``flock`` on the file or folder being written, no lock
file beside it. A second writer is refused at once, naming the holder's PID (from
``/proc/locks``). Used by :class:`corraoi.files.partial.PartialFile` (every writer's
``.partial`` file) and by a sweep for its folder (``corraoi/experiments/sweeps.py``).
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterator
from pathlib import Path

from corraoi.errors import OutputError

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no locks
    fcntl = None  # type: ignore[assignment]

def lock_holder(part: str | os.PathLike[str]) -> int | None:
    """Who holds the writer's lock on ``part`` (a file or a folder): its PID, 0 if the PID is
    unknown, or None when nobody writes it (or it does not exist)."""
    if fcntl is None:
        return None
    try:
        fd = os.open(part, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not (is_regular(st.st_mode) or stat.S_ISDIR(st.st_mode)):
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return pid_of_lock(st.st_dev, st.st_ino)
        except OSError:
            return None
        return None
    finally:
        os.close(fd)  # also drops the shared lock taken to test


@contextlib.contextmanager
def folder_lock(folder: Path, what: str = "folder") -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` itself (flock on the directory: no lock file)
    while a writer fills it; a second writer is refused at once, naming the holder's PID."""
    if fcntl is None:  # pragma: no cover - not Linux
        yield
        return
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            st = os.fstat(fd)
            holder = pid_of_lock(st.st_dev, st.st_ino)
            who = f"process {holder}" if holder > 0 else "another process"
            raise OutputError(
                f"{folder}: {who} is writing this {what} right now; not touched (wait for it, "
                "stop it, or give another folder)"
            ) from None
        yield
    finally:
        os.close(fd)


def is_regular(mode: int) -> bool:
    return stat.S_ISREG(mode)


def pid_of_lock(dev: int, ino: int) -> int:
    """The PID holding a flock on (dev, ino), from /proc/locks (Linux); 0 if unknown."""
    want = f"{os.major(dev):02x}:{os.minor(dev):02x}:{ino}"
    try:
        with open("/proc/locks", encoding="ascii", errors="replace") as f:
            for line in f:
                parts = line.split()
                # "1: FLOCK  ADVISORY  WRITE 1234 00:2e:5678 0 EOF" ("->" marks waiters)
                if "->" in parts or len(parts) < 6 or parts[1] != "FLOCK":
                    continue
                if parts[5] == want and parts[3] == "WRITE":
                    return int(parts[4])
    except (OSError, ValueError):
        pass
    return 0


__all__ = ["fcntl", "folder_lock", "is_regular", "lock_holder", "pid_of_lock"]
