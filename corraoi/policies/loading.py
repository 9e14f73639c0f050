"""Loading plug-in code safely: a ``FILE.py`` or module imported so that whatever it does
while loading (an exception, ``sys.exit``, ``os._exit``, megabytes of output) ends as one
:class:`~corraoi.errors.PolicyError` line, and the check that what it gave is a policy class.

The registry (``registry.py``) decides *which* class a ``--policy`` word names; this module
only loads code and checks classes.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.metadata
import importlib.util
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

from corraoi.errors import CodeChanged, PolicyError, PolicyTypeError

from .api import CompiledPolicy, Policy, PolicyBase, check_declaration

PLUGIN_MODULE_PREFIX = "corraoi_plugin_"


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return f"{type(exc).__name__}: {text}" if not isinstance(exc, PolicyError) else text


def check_class(obj: Any, where: str) -> type[PolicyBase]:
    if not (isinstance(obj, type) and issubclass(obj, (CompiledPolicy, Policy))):
        raise PolicyTypeError(
            f"{where}: {obj!r} is not a policy class (expected a subclass of "
            "corraoi.policies.Policy or corraoi.policies.CompiledPolicy)"
        )
    check_declaration(obj)  # again: a class attribute may have changed since it was declared
    if issubclass(obj, CompiledPolicy) and obj.score is None and obj.forced is None:
        raise PolicyError(f"{where}: a compiled policy needs a score (or forced) hook")
    if issubclass(obj, Policy) and obj.select is Policy.select:
        raise PolicyError(f"{where}: a Python policy must define select(t, state)")
    return obj


#: A plug-in's output while it loads is passed on up to this many bytes; beyond, one line.
_LOAD_OUTPUT_LIMIT = 4096


@contextlib.contextmanager
def guarded_load(where: str, what: str, failed: str = "") -> Iterator[None]:
    """Run a plug-in's import so that whatever it does there ends as one PolicyError line:
    an exception, ``sys.exit``, ``os._exit`` (Python's, replaced while it loads) or
    megabytes of output (the process's stdout and stderr go to a temporary file meanwhile;
    up to a few KiB are passed on). Ctrl-C during a hang still interrupts (exit 130)."""
    real_exit = os._exit

    def no_exit(code: int = 0) -> None:
        raise _PluginExit(code)

    for stream in (sys.stdout, sys.stderr):
        _flush(stream)
    saved = [os.dup(1), os.dup(2)]
    sink = tempfile.TemporaryFile()
    os.dup2(sink.fileno(), 1)
    os.dup2(sink.fileno(), 2)
    os._exit = no_exit  # type: ignore[assignment]
    problem: str | None = None
    try:
        yield
    except _PluginExit as exc:
        problem = f"{where}: {what} called os._exit({exc.code}) while loading"
    except SystemExit as exc:
        problem = f"{where}: {what} called sys.exit({exc.code!r}) while loading"
    except KeyboardInterrupt:
        raise
    except PolicyError:
        raise
    except BaseException as exc:  # noqa: BLE001 - anything a plug-in raises at import
        problem = f"{where}: {failed or f'importing {what} failed'}: {one_line(exc)}"
    finally:
        os._exit = real_exit
        for stream in (sys.stdout, sys.stderr):
            _flush(stream)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)
        size = sink.seek(0, os.SEEK_END)
        if 0 < size <= _LOAD_OUTPUT_LIMIT:
            sink.seek(0)
            _write_err(sink.read())
        elif size > _LOAD_OUTPUT_LIMIT:
            _write_err(
                f"corraoi: {what} printed {size:,} bytes while loading (not shown)\n".encode()
            )
        sink.close()
    if problem is not None:
        raise PolicyError(problem)


class _PluginExit(Exception):
    """``os._exit`` called by a plug-in while it loads (raised instead of ending us)."""

    def __init__(self, code: int) -> None:
        super().__init__(code)
        self.code = code


def _flush(stream: Any) -> None:
    try:
        stream.flush()
    except (OSError, ValueError, AttributeError):
        pass


def _write_err(data: bytes) -> None:
    try:
        os.write(2, data)
    except OSError:
        pass


#: Plug-in sources handed over as data, by resolved path and sha256: a Dask worker that lacks
#: the client's files, or a sweep's kept copy run instead of a file edited since.
_SOURCES: dict[str, dict[str, bytes]] = {}


def has_source(path: Path) -> bool:
    """Whether a plug-in file's source was handed over as data (it need not exist here)."""
    return bool(_SOURCES.get(str(path.resolve())))


def install_plugin_source(path: str | Path, source: str | bytes) -> str:
    """Make ``FILE.py:Class`` plug-ins at ``path`` importable from ``source`` (on a worker
    that does not have the file, or a sweep's kept copy): a spec that names this source's
    sha256 loads it rather than the file. Returns the sha256 (hex)."""
    data = source.encode("utf-8") if isinstance(source, str) else bytes(source)
    digest = hashlib.sha256(data).hexdigest()
    _SOURCES.setdefault(str(Path(path).resolve()), {})[digest] = data
    return digest


#: Plug-in files pinned to a source in this process (a sweep's kept copy, ``--kept-code``).
_PINNED: dict[str, str] = {}


def pin_plugin_source(path: str | Path, source: bytes) -> str:
    """Load the plug-in file ``path`` from ``source`` in this process, whatever the file
    holds now (``--kept-code``: the sweep's copy). Returns the sha256 (hex)."""
    digest = install_plugin_source(path, source)
    _PINNED[str(Path(path).resolve())] = digest
    return digest


def file_module(path: Path, where: str, expect: str = "") -> tuple[ModuleType, str]:
    """Import a plug-in file once per process under a name derived from its path; returns
    the module and its version (a hash of the source).

    The module executes exactly the bytes it hashed (kept as ``__corraoi_source__``, for the
    logs' provenance). ``expect``: the sha256 (hex, or a prefix of it) a run recorded: the
    module already loaded with it, or a source handed over with it, is used; otherwise the
    file, which must hash to it (:class:`~corraoi.errors.CodeChanged` if not)."""
    key = str(path.resolve())
    expect = expect or _PINNED.get(key, "")
    modname = f"{PLUGIN_MODULE_PREFIX}{hashlib.sha256(key.encode()).hexdigest()[:16]}"
    module = sys.modules.get(modname)
    loaded = getattr(module, "__corraoi_digest__", "") if module is not None else ""
    if expect and loaded.startswith(expect):  # the code the run recorded is loaded: keep it
        return module, f"sha256:{loaded[:16]}"  # type: ignore[return-value]
    installed = _SOURCES.get(key, {})
    source = next((d for h, d in installed.items() if expect and h.startswith(expect)), None)
    if source is None:
        try:
            source = path.read_bytes()
        except OSError as exc:
            if not installed or expect:
                raise PolicyError(f"{where}: cannot read {path}: {exc.strerror or exc}") from None
            source = next(iter(installed.values()))
    digest = hashlib.sha256(source).hexdigest()
    if expect and not digest.startswith(expect):
        raise CodeChanged(str(path), expect, digest)
    if module is not None and loaded == digest:
        return module, f"sha256:{digest[:16]}"
    spec = importlib.util.spec_from_file_location(modname, path)
    if spec is None:
        raise PolicyError(f"{where}: {path} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    module.__corraoi_digest__ = digest  # type: ignore[attr-defined]
    module.__corraoi_source__ = source  # type: ignore[attr-defined]
    sys.modules[modname] = module
    try:
        with guarded_load(where, str(path)):
            exec(compile(source, str(path), "exec"), module.__dict__)  # the bytes hashed
    except BaseException:
        sys.modules.pop(modname, None)
        raise
    return module, f"sha256:{digest[:16]}"


def module_digest(modname: str) -> str:
    """The sha256 (hex) of the source module ``modname`` was loaded from ("" if unknown)."""
    loaded = loaded_source(modname)
    return hashlib.sha256(loaded[1]).hexdigest() if loaded is not None else ""


def loaded_source(modname: str) -> tuple[str, bytes] | None:
    """(path, bytes) of the module ``modname`` as it was loaded: a plug-in file's exact
    bytes; for another module, its file read once, when first asked (None without one)."""
    module = sys.modules.get(modname)
    if module is None:
        return None
    data = getattr(module, "__corraoi_source__", None)
    path = getattr(module, "__file__", None)
    if isinstance(data, bytes) and path:
        return str(path), data
    if not path:
        return None
    return _read_once(str(path))


@functools.lru_cache(maxsize=256)
def _read_once(path: str) -> tuple[str, bytes] | None:
    try:
        return path, Path(path).read_bytes()
    except OSError:
        return None


def class_source(cls: type) -> tuple[str, bytes] | None:
    """(where, bytes) of the source a policy class ran from: its module's file as loaded, or,
    for a class defined in a session without one (a notebook cell, ``python -c``), the text
    of the class itself (``inspect.getsource``), named ``<module>:<qualname>``."""
    loaded = loaded_source(cls.__module__)
    if loaded is not None:
        return loaded
    text = _class_text(cls)
    return None if text is None else (f"<{cls.__module__}>:{cls.__qualname__}", text.encode())


def _class_text(cls: type) -> str | None:
    """The text of a class defined without a file: ``inspect.getsource``, or, where that
    needs the module's file (a notebook's ``__main__`` has none), the ``class`` block found
    above one of its methods in the cell the interpreter keeps (``linecache``)."""
    import inspect
    import linecache
    import re

    try:
        return inspect.getsource(cls)
    except (OSError, TypeError):
        pass
    header = re.compile(rf"\s*class\s+{re.escape(cls.__name__)}\b")
    for value in vars(cls).values():
        code = getattr(getattr(value, "__func__", value), "__code__", None)
        if code is None:
            continue
        lines = linecache.getlines(code.co_filename)
        for start in range(min(code.co_firstlineno, len(lines)) - 1, -1, -1):
            if header.match(lines[start]):
                return "".join(inspect.getblock(lines[start:]))
    return None


def module_version(modname: str) -> str:
    top = modname.split(".")[0]
    for dist in importlib.metadata.packages_distributions().get(top, []):
        try:
            return importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue
    loaded = loaded_source(modname)
    if loaded is not None:
        return "sha256:" + hashlib.sha256(loaded[1]).hexdigest()[:16]
    return ""


def is_file_ref(left: str) -> bool:
    return left.endswith(".py") or os.sep in left or "/" in left
