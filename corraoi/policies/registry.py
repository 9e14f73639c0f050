"""Finding policies: built-ins, entry points, ``FILE.py:Class`` and ``package.module:Class``.

``--policy`` takes a built-in name (``cucb``), a path to a Python file and a class in it
(``eps_greedy.py:EpsilonGreedy``), a module and a class (``mypkg.policies:EpsilonGreedy``),
or the name of an entry point in the group ``corraoi.policies``. ``all`` is the paper's
twelve. A broken entry point is reported (``corraoi policies``) and does not stop the rest.
"""

from __future__ import annotations

import contextlib
import difflib
import hashlib
import importlib
import importlib.metadata
import importlib.util
import os
import sys
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Any

from .._version import __version__
from ..errors import PolicyError
from .api import BUILTIN_PREFIX, CompiledPolicy, Policy, PolicyBase, PolicySpec

ENTRY_POINT_GROUP = "corraoi.policies"
PLUGIN_MODULE_PREFIX = "corraoi_plugin_"


@lru_cache(maxsize=1)
def builtins() -> dict[str, type[PolicyBase]]:
    """Every built-in policy by name: the paper's twelve first, in their table order."""
    from . import drifting, forced_exploration, paper

    out: dict[str, type[PolicyBase]] = {}
    for module in (paper, forced_exploration, drifting):
        out.update(module.POLICIES)
    return out


def paper_names() -> list[str]:
    """The twelve policies of the paper (``--policy all``)."""
    return [n for n, cls in builtins().items() if cls.paper]


def _entry_points() -> list[importlib.metadata.EntryPoint]:
    return sorted(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name)


@dataclass(frozen=True)
class Available:
    """One line of ``corraoi policies``."""

    name: str
    source: str  # "built-in" or "entry point <dist>"
    cls: type[PolicyBase] | None
    error: str | None = None


def available() -> list[Available]:
    """Built-ins, then entry-point plug-ins (a broken one listed with its error)."""
    out = [Available(n, "built-in", cls) for n, cls in builtins().items()]
    for ep in _entry_points():
        dist = ep.dist.name if ep.dist is not None else "?"
        try:
            with _guarded_load(f"entry point {ep.name}", ep.value):
                loaded = ep.load()
            cls = _check_class(loaded, f"entry point {ep.name} ({ep.value})")
        except PolicyError as exc:  # a broken plug-in must not break the listing
            out.append(Available(ep.name, f"entry point of {dist}", None, _one_line(exc)))
            continue
        out.append(Available(ep.name, f"entry point of {dist}", cls))
    return out


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return f"{type(exc).__name__}: {text}" if not isinstance(exc, PolicyError) else text


def _check_class(obj: Any, where: str) -> type[PolicyBase]:
    if not (isinstance(obj, type) and issubclass(obj, (CompiledPolicy, Policy))):
        raise PolicyError(
            f"{where}: {obj!r} is not a policy class (expected a subclass of "
            "corraoi.policies.Policy or corraoi.policies.CompiledPolicy)"
        )
    if not isinstance(obj.params, Mapping):
        raise PolicyError(f"{where}: params must be a dict of name -> Param")
    if issubclass(obj, CompiledPolicy) and obj.score is None and obj.forced is None:
        raise PolicyError(f"{where}: a compiled policy needs a score (or forced) hook")
    if issubclass(obj, Policy) and obj.select is Policy.select:
        raise PolicyError(f"{where}: a Python policy must define select(t, state)")
    return obj


#: A plug-in's output while it loads is passed on up to this many bytes; beyond, one line.
_LOAD_OUTPUT_LIMIT = 4096


@contextlib.contextmanager
def _guarded_load(where: str, what: str, failed: str = "") -> Iterator[None]:
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
        problem = f"{where}: {failed or f'importing {what} failed'}: {_one_line(exc)}"
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


#: Plug-in sources handed over as data (a Dask worker that lacks the client's files).
_SOURCES: dict[str, bytes] = {}


def install_plugin_source(path: str, source: str) -> None:
    """Make ``FILE.py:Class`` plug-ins at ``path`` importable from ``source`` (on a worker
    that does not have the file: plug-ins travel with the chunks as data)."""
    _SOURCES[str(Path(path).resolve())] = source.encode("utf-8")


def _file_module(path: Path, where: str) -> tuple[ModuleType, str]:
    """Import a plug-in file once per process under a name derived from its path; returns
    the module and its version (a hash of the source)."""
    installed = _SOURCES.get(str(path.resolve()))
    try:
        source = installed if installed is not None else path.read_bytes()
    except OSError as exc:
        raise PolicyError(f"{where}: cannot read {path}: {exc.strerror or exc}") from None
    digest = hashlib.sha256(source).hexdigest()
    key = hashlib.sha256(str(path.resolve()).encode()).hexdigest()[:16]
    modname = f"{PLUGIN_MODULE_PREFIX}{key}"
    module = sys.modules.get(modname)
    if module is not None and getattr(module, "__corraoi_digest__", None) == digest:
        return module, f"sha256:{digest[:16]}"
    spec = importlib.util.spec_from_file_location(modname, path)
    if spec is None or spec.loader is None:
        raise PolicyError(f"{where}: {path} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    module.__corraoi_digest__ = digest  # type: ignore[attr-defined]
    sys.modules[modname] = module
    try:
        with _guarded_load(where, str(path)):
            if installed is not None:
                exec(compile(source, str(path), "exec"), module.__dict__)
            else:
                spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(modname, None)
        raise
    return module, f"sha256:{digest[:16]}"


def _module_version(modname: str) -> str:
    top = modname.split(".")[0]
    for dist in importlib.metadata.packages_distributions().get(top, []):
        try:
            return importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue
    mod = sys.modules.get(modname)
    file = getattr(mod, "__file__", None)
    if file:
        return "sha256:" + hashlib.sha256(Path(file).read_bytes()).hexdigest()[:16]
    return ""


def _is_file_ref(left: str) -> bool:
    return left.endswith(".py") or os.sep in left or "/" in left


@dataclass(frozen=True)
class Resolved:
    cls: type[PolicyBase]
    qualname: str  # "corraoi:cucb", "file:/abs/eps.py:EpsilonGreedy", "pkg.mod:Class"
    version: str


def resolve(token: str) -> Resolved:
    """The policy class a ``--policy`` word names (PolicyError with a hint if none)."""
    raw = token.strip()
    if not raw:
        raise PolicyError("empty policy name (expected a name, FILE.py:Class or module:Class)")
    name = raw.lower()
    table = builtins()
    if name in table:
        return Resolved(table[name], BUILTIN_PREFIX + name, __version__)
    if ":" in raw:
        left, _, attr = raw.rpartition(":")
        if not left or not attr.isidentifier():
            raise PolicyError(f"policy {raw!r}: expected FILE.py:Class or package.module:Class")
        if _is_file_ref(left):
            path = Path(left).expanduser()
            if not path.is_file() and str(path.resolve()) not in _SOURCES:
                raise PolicyError(f"policy {raw!r}: no such file {left}")
            module, version = _file_module(path, f"policy {raw!r}")
            qual = f"file:{path.resolve()}:{attr}"
        else:
            with _guarded_load(f"policy {raw!r}", f"module {left}", f"cannot import module {left}"):
                module = importlib.import_module(left)
            version = _module_version(left)
            qual = f"{left}:{attr}"
        if not hasattr(module, attr):
            raise PolicyError(f"policy {raw!r}: {left} has no class {attr}")
        return Resolved(_check_class(getattr(module, attr), f"policy {raw!r}"), qual, version)
    for ep in _entry_points():
        if ep.name == raw or ep.name.lower() == name:
            broken = f"its entry point {ep.value} is broken"
            with _guarded_load(f"policy {raw!r}", f"entry point {ep.value}", broken):
                loaded = ep.load()
            cls = _check_class(loaded, f"policy {raw!r} (entry point {ep.value})")
            modname = ep.value.split(":")[0]
            return Resolved(cls, f"{modname}:{cls.__name__}", _module_version(modname))
    raise PolicyError(unknown_policy_message(raw))


def unknown_policy_message(name: str) -> str:
    known = list(builtins()) + [ep.name for ep in _entry_points()]
    close = difflib.get_close_matches(name.lower(), known, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]}?" if close else ""
    return (
        f"unknown policy {name!r}{hint} (see 'corraoi policies'; a plug-in is FILE.py:Class "
        "or package.module:Class)"
    )


def resolve_spec(spec: PolicySpec) -> type[PolicyBase]:
    """The class of a spec (from a log or made here)."""
    if spec.builtin:
        cls = builtins().get(spec.name)
        if cls is None:
            raise PolicyError(f"policy {spec.name}: not a built-in of corraoi {__version__}")
        return cls
    qual = spec.qualname
    if qual.startswith("file:"):
        body = qual[len("file:") :]
        return resolve(body).cls
    if ":" in qual and not qual.startswith("plugin:"):
        return resolve(qual).cls
    return resolve(spec.name).cls


def policy_name(cls: type[PolicyBase]) -> str:
    return cls.name or cls.__name__.lower()


def make_policy(token: str, **params: float | None) -> PolicySpec:
    """A validated spec for one ``--policy`` word; ``None`` values take defaults."""
    res = resolve(token)
    cls = res.cls
    unknown = sorted(set(k for k, v in params.items() if v is not None) - set(cls.params))
    if unknown:
        known = ", ".join(cls.params) or "none"
        raise PolicyError(
            f"policy {policy_name(cls)}: unknown parameter {unknown[0]!r} (it declares: {known})"
        )
    values: dict[str, float] = {}
    for pname, decl in cls.params.items():
        given = params.get(pname)
        value = float(decl.default if given is None else given)
        problem = decl.check(value)
        if problem is not None:
            raise PolicyError(f"policy {policy_name(cls)}: parameter {pname}={value:g} {problem}")
        values[pname] = value
    return PolicySpec(
        name=policy_name(cls),
        params=values,
        qualname=res.qualname,
        version=res.version,
        tier=cls.tier,
        label=cls.label or policy_name(cls),
        color=cls.color,
    )


def parse_policy_names(values: Iterable[str]) -> list[str]:
    """Words from ``--policy`` given as a name, a comma list, repeated, or ``all`` (the
    paper's twelve). Keeps first-seen order and drops repeats; checks each one resolves."""
    names: list[str] = []
    for value in values:
        for part in value.split(","):
            token = part.strip()
            if not token:
                continue
            expanded = paper_names() if token.lower() == "all" else [token]
            for n in expanded:
                key = n.lower() if n.lower() in builtins() else n
                resolve(key)
                if key not in names:
                    names.append(key)
    if not names:
        raise PolicyError("no policy given (expected a name, a comma list or all)")
    return names


def parse_param_assignments(items: Iterable[str]) -> dict[str, float]:
    """``--param NAME=VALUE`` words into a dict (later ones win); one clear line if malformed."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name.isidentifier():
            raise PolicyError(f"--param {item!r}: expected NAME=VALUE (e.g. --param c=1.5)")
        try:
            value = float(text)
        except ValueError:
            raise PolicyError(f"--param {item!r}: {text.strip()!r} is not a number") from None
        out[name] = value
    return out


def make_policies(
    values: Iterable[str],
    params: Mapping[str, float] | None = None,
    *,
    c: float | None = None,
    beta: float | None = None,
) -> list[PolicySpec]:
    """Specs for ``--policy`` values; each parameter goes to every listed policy that declares
    it, and is an error if none does (so that a typo is never silently ignored). ``c`` and
    ``beta`` are the shorthands ``--c`` and ``--beta``."""
    given = dict(params or {})
    for key, value in (("c", c), ("beta", beta)):
        if value is not None:
            given[key] = float(value)
    tokens = parse_policy_names(values)
    classes = {t: resolve(t).cls for t in tokens}
    for pname in given:
        if not any(pname in cls.params for cls in classes.values()):
            users = sorted(n for n, cls in builtins().items() if pname in cls.params)
            read_by = f" (it is read by {', '.join(users)})" if users else ""
            raise PolicyError(
                f"parameter {pname} does not apply to "
                f"{', '.join(policy_name(c) for c in classes.values())}{read_by}"
            )
    return [
        make_policy(t, **{k: v for k, v in given.items() if k in classes[t].params}) for t in tokens
    ]
