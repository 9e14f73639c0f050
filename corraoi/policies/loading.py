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
import importlib.util
import os
import sys
import tempfile
import threading
from collections.abc import Iterator, Mapping
from pathlib import Path
from types import CodeType, ModuleType
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


#: Plug-in sources handed over as data while a ``with handed_over(...)`` block runs, by
#: resolved path and sha256: a Dask worker's chunk from a client whose file it lacks, or a
#: sweep's kept copy run instead of a file edited since. Only a spec that names a source's
#: sha256 loads it, under a module name of its own (:func:`file_module`); after the block,
#: nothing of it is left to find: a call that names the file runs the file.
_SOURCES: dict[str, dict[str, bytes]] = {}
#: Plug-in files pinned to a source (``handed_over(..., pin=True)``: ``corraoi sweep
#: --resume --kept-code``, where ``-p FILE.py:Class`` means the sweep's copy).
_PINNED: dict[str, str] = {}


def has_source(path: Path, expect: str = "") -> bool:
    """Whether a copy of a plug-in file's source with the sha256 ``expect`` (hex, or a prefix)
    is handed over now (the file need not exist here)."""
    return bool(expect) and any(h.startswith(expect)
                                for h in _SOURCES.get(str(path.resolve()), {}))  # fmt: skip


#: How many ``handed_over`` blocks hold each (path, sha256) and each pin: blocks may nest,
#: and run at once in the threads of one Dask worker.
_HOLDERS: dict[tuple[str, str], int] = {}
_PIN_HOLDERS: dict[tuple[str, str], int] = {}
_LOCK = threading.Lock()


@contextlib.contextmanager
def handed_over(sources: Mapping[str, bytes], *, pin: bool = False) -> Iterator[list[str]]:
    """Within the block, a spec that names the sha256 of one of ``sources`` (path: bytes)
    loads those bytes, under a module name of its own, where the file holds other code now;
    with ``pin``, so does a plug-in file named without a hash. The user's modules, classes
    and registrations are left alone, and after the block the files are what load. Yields
    the sha256 (hex) of each source."""
    held: list[tuple[str, str]] = []
    with _LOCK:
        for path, data in sources.items():
            item = (str(Path(path).resolve()), hashlib.sha256(data).hexdigest())
            _SOURCES.setdefault(item[0], {})[item[1]] = bytes(data)
            _HOLDERS[item] = _HOLDERS.get(item, 0) + 1
            if pin:
                _PINNED[item[0]] = item[1]
                _PIN_HOLDERS[item] = _PIN_HOLDERS.get(item, 0) + 1
            held.append(item)
    try:
        yield [digest for _, digest in held]
    finally:
        with _LOCK:
            for item in held:
                _HOLDERS[item] -= 1
                if not _HOLDERS[item]:
                    del _HOLDERS[item]
                    _SOURCES.get(item[0], {}).pop(item[1], None)
                    if not _SOURCES.get(item[0], True):
                        del _SOURCES[item[0]]
                if pin:
                    _PIN_HOLDERS[item] -= 1
                    if not _PIN_HOLDERS[item]:
                        del _PIN_HOLDERS[item]
                        if _PINNED.get(item[0]) == item[1]:
                            del _PINNED[item[0]]


#: A module attribute: the module is a copy of a plug-in file's source other than the file's
#: (a sweep's kept code, a worker's copy); classes it registers leave the registry alone.
COPY_MARK = "__corraoi_copy__"


def is_copy(module_name: str) -> bool:
    """Whether the module ``module_name`` is a handed-over copy of a plug-in's source."""
    return bool(getattr(sys.modules.get(module_name), COPY_MARK, False))


def file_module(path: Path, where: str, expect: str = "") -> tuple[ModuleType, str]:
    """Import a plug-in file under a name derived from its path; returns the module and its
    version (a hash of the source).

    The module executes exactly the bytes it hashed (kept as ``__corraoi_source__``, for the
    logs' provenance). Without ``expect`` it is the file as it is now (executed again when
    its bytes changed). ``expect``: the sha256 (hex, or a prefix of it) a run recorded: the
    file's module loaded with it, or the file when it hashes to it, or a copy handed over with
    it (:func:`install_plugin_source`, loaded under a module name of its own, so that it never
    replaces the file's module); otherwise :class:`~corraoi.errors.CodeChanged`."""
    key = str(path.resolve())
    expect = expect or _PINNED.get(key, "")
    modname = f"{PLUGIN_MODULE_PREFIX}{hashlib.sha256(key.encode()).hexdigest()[:16]}"
    module = sys.modules.get(modname)
    loaded = getattr(module, "__corraoi_digest__", "") if module is not None else ""
    if expect and loaded.startswith(expect):  # the code the run recorded is loaded: keep it
        return module, f"sha256:{loaded[:16]}"  # type: ignore[return-value]
    copy = next((d for h, d in _SOURCES.get(key, {}).items()
                 if expect and h.startswith(expect)), None)  # fmt: skip
    try:
        source: bytes | None = path.read_bytes()
    except OSError as exc:
        if copy is None:
            raise PolicyError(f"{where}: cannot read {path}: {exc.strerror or exc}") from None
        source = None
    digest = hashlib.sha256(source).hexdigest() if source is not None else ""
    if expect and not digest.startswith(expect):
        if copy is None:
            raise CodeChanged(str(path), expect, digest)
        # a copy of other code than the file's: a module of its own, the file's left alone
        copied = hashlib.sha256(copy).hexdigest()
        return _execute(f"{modname}_{copied[:16]}", path, copy, copied, where, copy=True), (
            f"sha256:{copied[:16]}")  # fmt: skip
    assert source is not None
    if module is not None and loaded == digest:
        return module, f"sha256:{digest[:16]}"
    return _execute(modname, path, source, digest, where), f"sha256:{digest[:16]}"


def _execute(modname: str, path: Path, source: bytes, digest: str, where: str, *,
             copy: bool = False) -> ModuleType:  # fmt: skip
    """The module ``modname`` executing ``source`` (the bytes hashed to ``digest``) as the
    file ``path``; one already loaded with that digest is kept."""
    module = sys.modules.get(modname)
    if module is not None and getattr(module, "__corraoi_digest__", "") == digest:
        return module
    spec = importlib.util.spec_from_file_location(modname, path)
    if spec is None:
        raise PolicyError(f"{where}: {path} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    module.__corraoi_digest__ = digest  # type: ignore[attr-defined]
    module.__corraoi_source__ = source  # type: ignore[attr-defined]
    if copy:
        setattr(module, COPY_MARK, True)
    sys.modules[modname] = module
    try:
        with guarded_load(where, str(path)):
            exec(compile(source, str(path), "exec"), module.__dict__)  # the bytes hashed
    except BaseException:
        sys.modules.pop(modname, None)
        raise
    return module


def loaded_source(modname: str) -> tuple[str, bytes] | None:
    """(path, bytes) of the module ``modname`` as it was loaded: a plug-in file's exact
    bytes; for another module, its file as it is now (None without one)."""
    module = sys.modules.get(modname)
    if module is None:
        return None
    data = getattr(module, "__corraoi_source__", None)
    path = getattr(module, "__file__", None)
    if isinstance(data, bytes) and path:
        return str(path), data
    if not path:
        return None
    try:
        return str(path), Path(path).read_bytes()
    except OSError:
        return None


def class_source(cls: type) -> tuple[str, bytes]:
    """(where, bytes) of the code a policy class runs, what its hash names:

    * a plug-in file's module: the exact bytes it executed;
    * a class of a module file (a package, a test module), when that file holds the class's
      code as it runs (compiled again and compared): the file's bytes, read now;
    * a class defined without a file, or in code the file no longer holds (a notebook cell,
      ``python -c``, a module edited since it was imported): the text of the class itself
      (the cell the interpreter keeps in ``linecache``, ``inspect.getsource``), named
      ``<module>:<qualname>``, when it compiles to the class's code;
    * otherwise (defined through ``exec``, no text anywhere): its methods' code
      (:func:`code_text`), named ``<module>:<qualname>#code``.

    Nothing is remembered between calls but compilations keyed by the bytes compiled: a class
    edited and defined again gets the hash of its new code."""
    module = sys.modules.get(cls.__module__)
    path = getattr(module, "__file__", None)
    data = getattr(module, "__corraoi_source__", None)
    if isinstance(data, bytes) and path:
        return str(path), data
    if path and _defined_in(cls, str(path)):
        loaded = loaded_source(cls.__module__)
        if loaded is not None and _compiles_to(cls, loaded[1], loaded[0], whole=True):
            return loaded[0], loaded[1] + _bases_code(cls, cls.__module__)
    text = _class_text(cls)
    if text is not None and _compiles_to(cls, text.encode(), "<class>", whole=False):
        return f"<{cls.__module__}>:{cls.__qualname__}", text.encode() + _bases_code(cls)
    return f"<{cls.__module__}>:{cls.__qualname__}#code", code_text(cls) + _bases_code(cls)


_NOT_USERS = ("corraoi", "builtins", "abc", "typing")


def _bases_code(cls: type, covered: str | None = None) -> bytes:
    """The code of the classes a policy class inherits from, outside corraoi and the module
    file ``covered`` already hashed (another cell's base class), appended to its own: they
    run too."""
    out = b""
    for base in cls.__bases__:
        if base.__module__ == covered or base.__module__.split(".")[0] in _NOT_USERS:
            continue
        where, data = class_source(base)
        out += f"\n# inherited from {where}\n".encode() + data
    return out


def _codes(cls: type) -> dict[str, CodeType]:
    """The code of each function a class defines (methods, static and class methods,
    properties), by name; a nested function's with its path (``select.inner``)."""
    out: dict[str, CodeType] = {}
    for name, value in vars(cls).items():
        funcs = [value.fget, value.fset, value.fdel] if isinstance(value, property) else [
            getattr(value, "__func__", value)]  # fmt: skip
        for i, func in enumerate(funcs):
            code = getattr(func, "__code__", None)
            if isinstance(code, CodeType):
                out[name if i == 0 else f"{name}#{i}"] = code
    return out


def _defined_in(cls: type, path: str) -> bool:
    """Whether the class's functions were compiled from ``path`` (True when it has none)."""
    files = {os.path.abspath(c.co_filename) for c in _codes(cls).values()}
    return not files or files == {os.path.abspath(path)}


def _compiles_to(cls: type, source: bytes, filename: str, *, whole: bool) -> bool:
    """Whether ``source`` (a module file, ``whole``, or the text of the class alone) compiles
    to the code the class runs: each of its functions, by name, to the same code."""
    found = _compiled(source, filename)
    if found is None:
        return False
    for code in _codes(cls).values():
        qual = getattr(code, "co_qualname", f"{cls.__qualname__}.{code.co_name}")
        if not whole and qual.startswith(f"{cls.__qualname__}."):  # as the text compiles alone
            qual = cls.__name__ + qual[len(cls.__qualname__) :]
        if found.get(qual) != _code_digest(code):
            return False
    return True


@functools.lru_cache(maxsize=64)
def _compiled(source: bytes, filename: str) -> dict[str, str] | None:
    """Every function compiled from ``source``, by qualified name: the digest of its code
    (cached by the bytes compiled: the same bytes always compile to the same code)."""
    import textwrap

    try:
        text = source.decode("utf-8")
        code = compile(textwrap.dedent(text), filename, "exec", dont_inherit=True)
    except (SyntaxError, ValueError, UnicodeDecodeError):
        return None
    out: dict[str, str] = {}

    def walk(c: CodeType, outer: str) -> None:
        for const in c.co_consts:
            if isinstance(const, CodeType):
                qual = getattr(const, "co_qualname", None) or (
                    f"{outer}.{const.co_name}" if outer else const.co_name)  # fmt: skip
                out.setdefault(qual, _code_digest(const))
                walk(const, qual)

    walk(code, "")
    return out


def _code_digest(code: CodeType) -> str:
    return hashlib.sha256(_code_bytes(code)).hexdigest()


def _code_bytes(code: CodeType) -> bytes:
    """What decides what a code object does, and nothing of where it sits (no line
    numbers, no file name): its bytecode, its names and its constants, code recursively."""
    parts = [code.co_name.encode(), code.co_code, repr(code.co_names).encode(),
             repr(code.co_varnames).encode(), repr(code.co_freevars).encode()]  # fmt: skip
    for const in code.co_consts:
        parts.append(_code_bytes(const) if isinstance(const, CodeType) else _const_repr(const))
    return b"\0".join(hashlib.sha256(p).digest() for p in parts)


def _const_repr(value: Any) -> bytes:
    if isinstance(value, frozenset):  # its order follows string hashing: sorted
        return b"frozenset(" + b",".join(sorted(_const_repr(v) for v in value)) + b")"
    if isinstance(value, tuple):
        return b"(" + b",".join(_const_repr(v) for v in value) + b")"
    return repr(value).encode()


def code_text(cls: type) -> bytes:
    """A class known by its code alone (no source text anywhere): one line per function it
    defines with the sha256 of its code (:func:`_code_bytes`), and each plain value it
    sets, sorted; the same in every process of the same Python."""
    import platform

    lines = [f"# {cls.__module__}:{cls.__qualname__}: no source text; the code it ran "
             f"(Python {platform.python_version()})"]  # fmt: skip
    for name, code in sorted(_codes(cls).items()):
        lines.append(f"def {name}: sha256:{_code_digest(code)}")
    for name, value in sorted(vars(cls).items()):
        if name.startswith("__") or name in _codes(cls):
            continue
        text = repr(value)
        if isinstance(value, (str, int, float, bool, tuple, type(None))) or (
            " at 0x" not in text and not callable(value)
        ):
            lines.append(f"{name} = {text}")
    return ("\n".join(lines) + "\n").encode()


def _class_text(cls: type) -> str | None:
    """The text of a class: the ``class`` block found above one of its methods in the file
    the interpreter keeps for its code (``linecache``: a notebook's cell, a module's file),
    else ``inspect.getsource``."""
    import inspect
    import linecache
    import re

    header = re.compile(rf"\s*class\s+{re.escape(cls.__name__)}\b")
    for code in _codes(cls).values():
        linecache.checkcache(code.co_filename)
        lines = linecache.getlines(code.co_filename)
        for start in range(min(code.co_firstlineno, len(lines)) - 1, -1, -1):
            if header.match(lines[start]):
                return "".join(inspect.getblock(lines[start:]))
    try:
        return inspect.getsource(cls)
    except (OSError, TypeError):
        return None


def module_version(modname: str) -> str:
    import importlib.metadata  # ~15 ms: only when a plug-in's version is asked

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
