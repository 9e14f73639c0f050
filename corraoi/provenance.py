"""What made a number: the code and the versions a run or a sweep ran with, recorded with it.

Every slot log and sweep log carries a :class:`Provenance` (``docs/log-format.md``): the
versions that decide its numbers (corraoi, with the git commit and a dirty mark when it runs
from a checkout; a hash of the kernel sources; Python, numpy, numba, rerun-sdk), the backend
(``cpu``, ``gpu-cuda``, ``gpu-emulated``), and the exact bytes of each plug-in's source with
their sha256 -- the bytes that ran, taken from the loaded module, never read again from a
file that may have changed since (:func:`corraoi.policies.loading.file_module` executes the
bytes it hashes). A sweep folder keeps a copy of each plug-in's source beside its hash.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import subprocess
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from corraoi.policies.loading import class_source, loaded_source

from ._version import __version__
from .errors import CorraoiError

_HERE = Path(__file__).resolve().parent
#: The sources that decide what the engines compute, slot for slot (their hash is logged).
KERNEL_SOURCES = ("engine/_kernel.py", "rng.py", "engine/seeds.py", "model/candidates.py",
                  "engine/simulation.py",
                  "engine/pyengine.py", "engine/problem.py", "model/channels.py",
                  "policies/hooks.py", "policies/builtin_hooks.py", "gpu/kernel.cu",
                  "gpu/runner.py")  # fmt: skip
#: The distributions whose versions are logged (besides corraoi and Python).
PACKAGES = ("numpy", "numba", "rerun-sdk")
#: What a backend is called in a log (``RunConfig.streams`` uses the same words).
BACKENDS = ("cpu", "gpu-cuda", "gpu-emulated")


@dataclass(frozen=True)
class Source:
    """One plug-in's source file as it ran: its name, where it was loaded from, the sha256
    of its bytes and the bytes themselves."""

    policy: str
    name: str
    path: str
    sha256: str
    data: bytes = field(repr=False)

    def to_dict(self) -> dict[str, str]:
        return {"policy": self.policy, "file": self.name, "path": self.path,
                "sha256": self.sha256}  # fmt: skip


@dataclass(frozen=True)
class Provenance:
    """The versions, backend and plug-in sources of one run or sweep, and notes (a run
    recorded with code other than its sweep's, a re-recorded run that differs from it)."""

    versions: dict[str, str]
    backend: str = "cpu"
    sources: tuple[Source, ...] = ()
    notes: tuple[str, ...] = ()

    @classmethod
    def of(cls, specs: Iterable[Any], *, backend: str = "cpu",
           notes: Sequence[str] = ()) -> Provenance:  # fmt: skip
        """The provenance of a run or sweep of ``specs`` (``PolicySpec`` s) on ``backend``."""
        seen: dict[str, Source] = {}
        for spec in specs:
            for src in sources_of(spec):
                seen.setdefault(f"{src.path}\0{src.sha256}", src)
        return cls(versions(), backend, tuple(seen.values()), tuple(notes))

    def with_notes(self, *notes: str) -> Provenance:
        return Provenance(self.versions, self.backend, self.sources, (*self.notes, *notes))

    def metadata(self) -> dict[str, str]:
        """Flat strings, for an MCAP metadata record (``corraoi.provenance``)."""
        out = dict(self.versions)
        out["backend"] = self.backend
        out["plugins"] = json.dumps([s.to_dict() for s in self.sources])
        if self.notes:
            out["notes"] = json.dumps(list(self.notes))
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON (a sweep folder's manifest; the sources without their bytes)."""
        return {"versions": dict(self.versions), "backend": self.backend,
                "plugins": [s.to_dict() for s in self.sources],
                **({"notes": list(self.notes)} if self.notes else {})}  # fmt: skip

    @staticmethod
    def read(metadata: dict[str, str]) -> dict[str, Any]:
        """A ``corraoi.provenance`` record read back as :meth:`to_dict` writes it (whatever
        is malformed in a hostile file is left out, never raised)."""

        def listed(key: str) -> list[Any]:
            try:
                value = json.loads(metadata.get(key, "[]"))
            except (ValueError, TypeError, RecursionError):
                return []
            return value if isinstance(value, list) else []

        plugins = [p for p in listed("plugins") if isinstance(p, dict)
                   and all(isinstance(p.get(k), str) for k in ("file", "sha256"))]  # fmt: skip
        versions = {k: str(v) for k, v in metadata.items()
                    if k not in ("backend", "plugins", "notes")}  # fmt: skip
        return {"versions": versions, "backend": str(metadata.get("backend", "")),
                "plugins": plugins, "notes": [str(n) for n in listed("notes")]}  # fmt: skip


@functools.lru_cache(maxsize=1)
def versions() -> dict[str, str]:
    """corraoi (and its git commit, "+dirty" when the checkout has changes), the kernel
    sources' hash, Python and the packages of :data:`PACKAGES` (none imported to ask)."""
    out = {"corraoi": __version__}
    commit = git_commit()
    if commit:
        out["git"] = commit
    out["kernel_sources"] = kernel_sources_hash()
    out["python"] = platform.python_version()
    import importlib.metadata  # ~15 ms: only a command that writes provenance pays it

    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


#: The checkout's folders whose changes make a commit "+dirty" (what is imported from it).
GIT_PACKAGES = ("corraoi", "recorder", "viewer")
#: A file changed this recently (seconds) may change again within one tick of its
#: file system's clock: a dirty mark is not cached while one is (git's "racy clean").
_RACY_S = 2.0


def git_commit(root: Path | None = None) -> str | None:
    """The commit of the checkout corraoi runs from (or of ``root``), with "+dirty" when its
    packages (:data:`GIT_PACKAGES`) differ from that commit; None when it is installed (no
    checkout) or the commit cannot be read.

    The commit is read from ``.git`` (``HEAD``, the branch it names, ``packed-refs``; a
    worktree's or submodule's ``.git`` file is followed), with no process started. "Dirty"
    means what ``git status --porcelain -- corraoi recorder viewer`` says, less Python's
    bytecode (``__pycache__``, ``*.pyc``): a source file of the packages modified, staged,
    deleted, or new and not ignored (and dirty too when git cannot say). Asking git costs a
    process (tens of ms), so its answer is kept in the kernel cache folder under a
    fingerprint of everything that can change it: the commit, the index file, the ignore
    files, and the size, times and inode of every file under the packages (a walk of about a
    millisecond). git is asked again only when the fingerprint changes, and its answer is not
    kept while a file there is younger than two seconds.
    """
    root = (root if root is not None else _HERE.parent).resolve()
    gitdir = _git_dir(root)
    if gitdir is None:
        return None
    commit = _head_commit(gitdir) or _git_rev_parse(root)
    if commit is None:
        return None
    clean = _dirty(root, gitdir, commit) is False  # git cannot say: not claimed clean
    return commit + ("" if clean else "+dirty")


def _git_dir(root: Path) -> Path | None:
    """The git directory of the checkout ``root`` (its ``.git`` folder, or the folder a
    ``.git`` file names), None when there is none."""
    dot = root / ".git"
    if dot.is_dir():
        return dot
    try:
        text = dot.read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return None
    if not text.startswith("gitdir:"):
        return None
    path = Path(text.removeprefix("gitdir:").strip())
    path = path if path.is_absolute() else root / path
    return path if path.is_dir() else None


def _common_dir(gitdir: Path) -> Path:
    """Where a worktree's shared refs live (its ``commondir``), else ``gitdir`` itself."""
    try:
        rel = (gitdir / "commondir").read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return gitdir
    common = Path(rel) if Path(rel).is_absolute() else gitdir / rel
    return common if common.is_dir() else gitdir


def _is_object_id(text: str) -> bool:
    return len(text) in (40, 64) and all(c in "0123456789abcdef" for c in text)


def _head_commit(gitdir: Path) -> str | None:
    """The commit ``HEAD`` names, read from the files (a detached HEAD, a loose ref, a ref in
    ``packed-refs``); None for what only git can answer (a reftable, an unborn branch)."""
    common = _common_dir(gitdir)
    try:
        value = (gitdir / "HEAD").read_text(encoding="utf-8").strip()
        for _ in range(5):  # a symbolic ref may name another
            if not value.startswith("ref:"):
                return value if _is_object_id(value) else None
            ref = value.removeprefix("ref:").strip()
            if not ref.startswith("refs/") or ".." in ref.split("/"):
                return None
            for base in (gitdir, common):
                loose = base / ref
                if loose.is_file():
                    value = loose.read_text(encoding="utf-8").strip()
                    break
            else:
                packed = common / "packed-refs"
                if not packed.is_file():
                    return None
                for line in packed.read_text(encoding="utf-8").splitlines():
                    oid, _, name = line.partition(" ")
                    if name == ref and _is_object_id(oid):
                        return oid
                return None
    except (OSError, UnicodeDecodeError):
        return None
    return None


def _git(root: Path, *args: str) -> subprocess.CompletedProcess[str] | None:
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                              timeout=10)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return done if done.returncode == 0 else None


def _git_rev_parse(root: Path) -> str | None:
    done = _git(root, "rev-parse", "HEAD")
    commit = done.stdout.strip() if done is not None else ""
    return commit if _is_object_id(commit) else None


def _dirty(root: Path, gitdir: Path, commit: str) -> bool | None:
    """Whether the packages differ from ``commit`` (None when git cannot say): the kept
    answer when the checkout's fingerprint is the one it was kept under, else git's."""
    from corraoi.engine import kernel_cache
    from corraoi.files.partial import PartialFile

    name = f"git-{hashlib.sha256(str(root).encode()).hexdigest()[:16]}.json"
    mark, newest = _fingerprint(root, gitdir, commit)
    try:
        kept = json.loads((kernel_cache.cache_dir() / name).read_text(encoding="utf-8"))
        if kept["fingerprint"] == mark and isinstance(kept["dirty"], bool):
            return kept["dirty"]
    except (OSError, ValueError, TypeError, KeyError, RecursionError):
        pass
    asked = time.time()
    done = _git(root, "status", "--porcelain", "--", *GIT_PACKAGES)
    if done is None:
        return None
    dirty = any(
        line[3:] and "__pycache__/" not in line and not line.rstrip('"').endswith(".pyc")
        for line in done.stdout.splitlines()
    )
    mark, newest = _fingerprint(root, gitdir, commit)  # git may have refreshed its index
    if newest < asked - _RACY_S:
        data = json.dumps({"fingerprint": mark, "dirty": dirty}).encode()
        try:
            PartialFile.write_bytes(kernel_cache.folder() / name, data, what="git state",
                                    sync=False)  # fmt: skip
        except (OSError, CorraoiError):
            pass  # not kept: git is asked again next time
    return dirty


def _fingerprint(root: Path, gitdir: Path, commit: str) -> tuple[str, float]:
    """A hash of what decides ``git status`` of the packages, and the newest time a file
    under them was changed (seconds since the epoch)."""
    digest = hashlib.sha256(f"{root}\0{commit}\0".encode())
    newest = 0.0
    common = _common_dir(gitdir)
    for path in (gitdir / "index", root / ".gitignore", common / "info" / "exclude"):
        try:
            st = path.stat()
            digest.update(f"{path}\0{st.st_size}\0{st.st_mtime_ns}\0{st.st_ctime_ns}\0"
                          f"{st.st_ino}\0".encode())  # fmt: skip
        except OSError:
            digest.update(f"{path}\0-\0".encode())
    stack = [root / pkg for pkg in reversed(GIT_PACKAGES)]
    while stack:
        folder = stack.pop()
        try:
            with os.scandir(folder) as it:
                entries = sorted(it, key=lambda e: e.name)
        except OSError:
            digest.update(f"{folder}\0-\0".encode())
            continue
        subfolders = []
        for entry in entries:
            try:
                if entry.is_dir(follow_symlinks=False):
                    if entry.name != "__pycache__":
                        subfolders.append(Path(entry.path))
                    continue
                st = entry.stat(follow_symlinks=False)
            except OSError:
                continue
            digest.update(f"{entry.path}\0{st.st_size}\0{st.st_mtime_ns}\0{st.st_ctime_ns}"
                          f"\0{st.st_ino}\0".encode())  # fmt: skip
            newest = max(newest, st.st_mtime)
        stack.extend(reversed(subfolders))
    return digest.hexdigest(), newest


def kernel_sources_hash() -> str:
    """sha256 over :data:`KERNEL_SOURCES` (each file's name and bytes, in that order)."""
    digest = hashlib.sha256()
    for rel in KERNEL_SOURCES:
        digest.update(rel.encode() + b"\0")
        try:
            digest.update((_HERE / rel).read_bytes())
        except OSError:
            digest.update(b"(missing)")
    return f"sha256:{digest.hexdigest()}"


def sources_of(spec: Any) -> list[Source]:
    """The plug-in sources a policy ran with: the file of its class and of its compiled
    hooks that live outside corraoi, as loaded (none for a built-in)."""
    if spec.builtin:
        return []
    cls = spec.resolve()
    modules = [cls.__module__]
    for hook in ("forced", "score", "update"):
        ref = getattr(cls, hook, None)
        name = ref.partition(":")[0] if isinstance(ref, str) else getattr(
            getattr(ref, "py_func", ref), "__module__", None)  # fmt: skip
        if name and name not in modules:
            modules.append(name)
    out = []
    for name in modules:
        if name.split(".")[0] == "corraoi":
            continue
        # the class's own module: a session without a file gives the class's text instead,
        # and a class without a text its code (policies.loading.class_source)
        loaded = class_source(cls) if name == cls.__module__ else loaded_source(name)
        if loaded is not None:
            path, data = loaded
            file = Path(path).name if not path.startswith("<") else (
                f"{cls.__qualname__}.code.txt" if path.endswith("#code") else
                f"{cls.__qualname__}.py")  # fmt: skip
            out.append(Source(spec.name, file, path, hashlib.sha256(data).hexdigest(),
                              data))  # fmt: skip
    return out


def short(sha256: str) -> str:
    """A hash as people read it in one line: ``sha256:`` and its first 16 hex digits."""
    hexa = sha256.removeprefix("sha256:")
    return f"sha256:{hexa[:16]}"


__all__ = ["BACKENDS", "GIT_PACKAGES", "KERNEL_SOURCES", "Provenance", "Source", "git_commit",
           "kernel_sources_hash", "short", "sources_of", "versions"]  # fmt: skip
