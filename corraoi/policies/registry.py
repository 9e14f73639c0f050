"""Finding policies: the registered ones, ``FILE.py:Class``, ``package.module:Class`` and
entry points.

``--policy`` takes a registered name (``cucb``, or a user's class passed to :func:`register`),
a path to a Python file and a class in it (``eps_greedy.py:EpsilonGreedy``), a module and a
class (``mypkg.policies:EpsilonGreedy``), or the name of an entry point in the group
``corraoi.policies``. ``all`` is the paper's twelve. A broken entry point is reported
(``corraoi policies``) and does not stop the rest.

The built-in families register themselves with the same :func:`register` a user calls
(``paper.py``, ``forced_exploration.py``, ``drifting.py``, imported by the package's
``__init__``), as Gymnasium's environments do in ``envs/__init__.py``.
"""

from __future__ import annotations

import difflib
import hashlib
import importlib
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

from corraoi._version import __version__
from corraoi.errors import PolicyError, PolicyValueError

from .api import BUILTIN_PREFIX, PolicyBase
from .loading import (
    PLUGIN_MODULE_PREFIX,
    check_class,
    class_source,
    file_module,
    guarded_load,
    has_source,
    is_copy,
    is_file_ref,
    module_version,
    one_line,
)

if TYPE_CHECKING:  # importlib.metadata costs ~15 ms to import: only when plug-ins are listed
    from importlib.metadata import EntryPoint


ENTRY_POINT_GROUP = "corraoi.policies"
#: what a registered name may look like: a word of the command line (no ``:`` or ``,``)
_NAME = re.compile(r"[a-z0-9][a-z0-9_.+-]*")
_BUILTIN_MODULE = "corraoi.policies."

#: every registered policy by name, in the order of registration (the paper's twelve first)
TABLE: dict[str, type[PolicyBase]] = {}

P = TypeVar("P", bound=type[PolicyBase])


def policy_name(cls: type[PolicyBase]) -> str:
    return cls.name or cls.__name__.lower()


def _qualname(cls: type[PolicyBase]) -> str:
    """Where a registered class can be found again (what its logs record)."""
    module = cls.__module__
    if module.startswith(_BUILTIN_MODULE):
        return BUILTIN_PREFIX + policy_name(cls)
    if module.startswith(PLUGIN_MODULE_PREFIX):  # a FILE.py plug-in that registers itself
        file = getattr(sys.modules.get(module), "__file__", None) or ""
        return f"file:{Path(file).resolve() if file else ''}:{cls.__name__}"
    return f"{module}:{cls.__qualname__}"


def register(cls: P) -> P:
    """Make a policy class known by its ``name``: ``--policy NAME``, ``make_policy``,
    ``corraoi policies`` and every log reader find it. Usable as a class decorator::

        @register
        class EpsilonGreedy(Policy):
            name = "eps-greedy"
            ...

    The class is checked as a plug-in is (PolicyError if it is not a policy). Registering the
    same class again (a module imported twice) is allowed; another class under a name that is
    taken is refused, and so is a built-in's name. A class defined again where it was (a
    notebook cell run again, a module reloaded) takes its name over. A copy of a plug-in's
    source loaded to run a sweep's kept code registers nothing: the name stays the user's.
    """
    checked = check_class(cls, f"register({getattr(cls, '__name__', cls)!r})")
    if is_copy(checked.__module__):
        return cls
    key = policy_name(checked)
    if not _NAME.fullmatch(key) or key == "all":
        raise PolicyError(
            f"register: policy name {key!r} is not usable on the command line (expected "
            "lower-case letters, digits and - _ . +, not 'all')"
        )
    held = TABLE.get(key)
    if held is not None and held is not checked:
        if _qualname(held) != _qualname(checked) or held.__module__.startswith(_BUILTIN_MODULE):
            raise PolicyError(
                f"register: policy name {key!r} is taken by {_qualname(held)} "
                f"(registering {_qualname(checked)})"
            )
    TABLE[key] = checked
    return cls


def builtins(*, multi: bool = False) -> dict[str, type[PolicyBase]]:
    """Every built-in single-source policy by name: the paper's twelve first, in their table
    order; with ``multi``, their multi-source forms too (``rhorand-ucb``, ...: a run of one
    source of them is the base policy's run)."""
    return {n: c for n, c in TABLE.items() if c.__module__.startswith(_BUILTIN_MODULE)
            and (multi or not getattr(c, "multi_source", ""))}  # fmt: skip


def registered() -> dict[str, type[PolicyBase]]:
    """Every registered policy by name: the built-ins, then users' in registration order."""
    return dict(TABLE)


def paper_names() -> list[str]:
    """The twelve policies of the paper (``--policy all``)."""
    return [n for n, cls in builtins().items() if cls.paper]


def _entry_points() -> list[EntryPoint]:
    import importlib.metadata

    return sorted(importlib.metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name)


@dataclass(frozen=True)
class Available:
    """One line of ``corraoi policies``."""

    name: str
    source: str  # "built-in", "registered by <module>" or "entry point of <dist>"
    cls: type[PolicyBase] | None
    error: str | None = None


def available() -> list[Available]:
    """Registered policies (built-ins first), then entry-point plug-ins (a broken one listed
    with its error)."""
    out = [
        Available(n, "built-in" if n in builtins(multi=True)
                  else f"registered by {cls.__module__}", cls)  # fmt: skip
        for n, cls in TABLE.items()
    ]
    for ep in _entry_points():
        if ep.name.lower() in TABLE:
            continue  # a registered name wins (as resolve does)
        dist = ep.dist.name if ep.dist is not None else "?"
        try:
            with guarded_load(f"entry point {ep.name}", ep.value):
                loaded = ep.load()
            cls = check_class(loaded, f"entry point {ep.name} ({ep.value})")
        except PolicyError as exc:  # a broken plug-in must not break the listing
            out.append(Available(ep.name, f"entry point of {dist}", None, one_line(exc)))
            continue
        out.append(Available(ep.name, f"entry point of {dist}", cls))
    return out


@dataclass(frozen=True)
class Resolved:
    cls: type[PolicyBase]
    qualname: str  # "corraoi:cucb", "file:/abs/eps.py:EpsilonGreedy", "pkg.mod:Class"
    version: str
    #: sha256 (hex) of the source the class was loaded from ("" for a built-in or unknown)
    sha256: str = ""


def _registered(cls: type[PolicyBase]) -> Resolved:
    qual = _qualname(cls)
    if qual.startswith(BUILTIN_PREFIX):
        return Resolved(cls, qual, __version__)
    module = cls.__module__
    if module.startswith(PLUGIN_MODULE_PREFIX):
        file_version = getattr(sys.modules.get(module), "__corraoi_digest__", "")
        return Resolved(cls, qual, f"sha256:{file_version[:16]}" if file_version else "",
                        file_version)  # fmt: skip
    return Resolved(cls, qual, module_version(module), class_digest(cls))


def class_digest(cls: type[PolicyBase]) -> str:
    """The sha256 (hex) of the code a class runs (:func:`~.loading.class_source`), asked
    anew every time: a class edited and defined again is other code."""
    return hashlib.sha256(class_source(cls)[1]).hexdigest()


def resolve(token: str, *, expect: str = "") -> Resolved:
    """The policy class a ``--policy`` word names (PolicyError with a hint if none).

    ``expect``: the sha256 (hex or a prefix) of the source a run recorded: a plug-in file
    is loaded from that source or refused (:class:`~corraoi.errors.CodeChanged`)."""
    raw = token.strip()
    if not raw:
        raise PolicyError("empty policy name (expected a name, FILE.py:Class or module:Class)")
    name = raw.lower()
    if name in TABLE:
        return _registered(TABLE[name])
    if ":" in raw:
        left, _, attr = raw.rpartition(":")
        if not left or not attr.isidentifier():
            raise PolicyError(f"policy {raw!r}: expected FILE.py:Class or package.module:Class")
        if is_file_ref(left):
            path = Path(left).expanduser()
            if not path.is_file() and not has_source(path, expect):
                raise PolicyError(f"policy {raw!r}: no such file {left}")
            module, version = file_module(path, f"policy {raw!r}", expect)
            qual = f"file:{path.resolve()}:{attr}"
            digest = str(getattr(module, "__corraoi_digest__", ""))
        else:
            with guarded_load(f"policy {raw!r}", f"module {left}", f"cannot import module {left}"):
                module = importlib.import_module(left)
            version = module_version(left)
            qual = f"{left}:{attr}"
            digest = ""
        if not hasattr(module, attr):
            raise PolicyError(f"policy {raw!r}: {left} has no class {attr}")
        cls = check_class(getattr(module, attr), f"policy {raw!r}")
        return Resolved(cls, qual, version, digest or class_digest(cls))
    if ":" not in raw and raw.endswith(".py"):  # FILE.py without its class: say which it holds
        raise PolicyError(_file_without_class(raw))
    for ep in _entry_points():
        if ep.name == raw or ep.name.lower() == name:
            broken = f"its entry point {ep.value} is broken"
            with guarded_load(f"policy {raw!r}", f"entry point {ep.value}", broken):
                loaded = ep.load()
            cls = check_class(loaded, f"policy {raw!r} (entry point {ep.value})")
            modname = ep.value.split(":")[0]
            return Resolved(cls, f"{modname}:{cls.__name__}", module_version(modname),
                            class_digest(cls))  # fmt: skip
    raise PolicyValueError(unknown_policy_message(raw))


def _file_without_class(raw: str) -> str:
    """The one line for ``--policy FILE.py``: the policy classes the file holds."""
    path = Path(raw).expanduser()
    if not path.is_file():
        return f"policy {raw!r}: no such file {raw} (a plug-in is FILE.py:Class)"
    module, _ = file_module(path, f"policy {raw!r}")
    found = [attr for attr, obj in vars(module).items()
             if isinstance(obj, type) and issubclass(obj, PolicyBase) and obj.__module__ ==
             module.__name__ and _is_policy(obj, attr)]  # fmt: skip
    if not found:
        return (f"policy {raw!r}: {raw} holds no policy class (a subclass of "
                "corraoi.policies.Policy or CompiledPolicy); a plug-in is FILE.py:Class")
    return (f"policy {raw!r}: name the class too, e.g. {raw}:{found[0]} (the policy classes "
            f"{raw} holds: {', '.join(found)})")


def _is_policy(obj: type[PolicyBase], where: str) -> bool:
    try:
        check_class(obj, where)
    except PolicyError:
        return False
    return True


def unknown_policy_message(name: str) -> str:
    known = list(TABLE) + [ep.name for ep in _entry_points()]
    close = difflib.get_close_matches(name.lower(), known, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]}?" if close else ""
    return (
        f"unknown policy {name!r}{hint} (see 'corraoi policies'; a plug-in is FILE.py:Class "
        "or package.module:Class)"
    )


def registered_digest(cls: type[PolicyBase]) -> str:
    """The sha256 (hex) of the source a registered class was loaded from ("" if unknown)."""
    return _registered(cls).sha256


def source_path(cls: type[PolicyBase]) -> str:
    """The file a plug-in class was loaded from (its module's name if it has none)."""
    return str(getattr(sys.modules.get(cls.__module__), "__file__", None) or cls.__module__)


def held(name: str, qualname: str, expect: str = "") -> type[PolicyBase] | None:
    """The class registered in this process under ``name``, if it is the one ``qualname``
    names (perhaps defined in a script, so not importable again); otherwise None. With
    ``expect`` (the sha256 a run recorded), a plug-in file's class whose code is other than
    that is passed over when a copy of that code was handed over (a sweep's kept code): the
    copy runs, the user's class stays registered."""
    cls = TABLE.get(name)
    if cls is None or _qualname(cls) != qualname:
        return None
    if expect and qualname.startswith("file:") and not class_digest(cls).startswith(expect):
        path = Path(qualname[len("file:"):].rpartition(":")[0])
        if has_source(path, expect):
            return None
    return cls
