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
import importlib.metadata
import json
import platform
import subprocess
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from corraoi.policies.loading import class_source, loaded_source

from ._version import __version__

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
    for name in PACKAGES:
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def git_commit() -> str | None:
    """The commit of the checkout corraoi runs from, with "+dirty" when its packages have
    uncommitted changes; None when it is installed (no checkout) or git is not there."""
    root = _HERE.parent
    if not (root / ".git").exists():
        return None
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=10)  # fmt: skip
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--",
                                "corraoi", "recorder", "viewer"], capture_output=True,
                               text=True, timeout=10)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    commit = head.stdout.strip()
    return commit + ("+dirty" if dirty.returncode != 0 or dirty.stdout.strip() else "")


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
        if name.split(".")[0] in ("corraoi", "recorder", "viewer"):
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


__all__ = ["BACKENDS", "KERNEL_SOURCES", "Provenance", "Source", "git_commit",
           "kernel_sources_hash", "short", "sources_of", "versions"]  # fmt: skip
