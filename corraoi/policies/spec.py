"""A policy with its parameter values, as a run is made and logged with, and the words of
``--policy``/``--param`` turned into such specs.

A spec names its class (built-in name, ``FILE.py:Class``, ``module:Class``) and does not hold
it, so that a log reads without the plug-in installed; :meth:`PolicySpec.resolve` finds the
class through the registry when it is needed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from corraoi._version import __version__
from corraoi.errors import CodeChanged, ConfigValueError, PolicyError

from .api import BUILTIN_PREFIX, RGB, PolicyBase
from .registry import (
    builtins,
    held,
    paper_names,
    policy_name,
    registered_digest,
    resolve,
    source_path,
)


@dataclass(frozen=True)
class PolicySpec:
    """A policy with its parameter values, and where it came from: what a log records.

    Built-ins are logged as ``{"name", "params"}`` (as in every earlier version); plug-ins add
    a ``plugin`` entry with the qualified name, version and tier, so that info, replay,
    compare and diff read their logs without the plug-in installed.
    """

    name: str
    params: Mapping[str, float] = field(default_factory=dict)
    qualname: str = ""
    version: str = ""
    tier: str = field(default="compiled", compare=False)
    label: str = field(default="", compare=False)
    color: RGB | None = field(default=None, compare=False)
    #: sha256 (hex) of the plug-in's source as loaded ("" for a built-in, or a log written
    #: before corraoi recorded it): a spec names the code it ran, and resolves only to it
    sha256: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", dict(self.params))
        if not self.qualname:
            object.__setattr__(self, "qualname", BUILTIN_PREFIX + self.name)
        if not self.label:
            object.__setattr__(self, "label", self.name)

    def __hash__(self) -> int:
        return hash((self.name, tuple(sorted(self.params.items())), self.qualname))

    @property
    def builtin(self) -> bool:
        return self.qualname.startswith(BUILTIN_PREFIX)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "params": dict(self.params)}
        if not self.builtin:
            out["plugin"] = {
                "qualname": self.qualname,
                "version": self.version,
                "tier": self.tier,
                "label": self.label,
                "color": list(self.color) if self.color is not None else None,
            }
            if self.sha256:
                out["plugin"]["sha256"] = self.sha256
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PolicySpec:
        """The spec of a log, without importing anything (the plug-in may be absent)."""
        if not isinstance(data, Mapping) or not isinstance(data.get("name"), str):
            raise PolicyError("policy: expected an object with a string 'name'")
        params = data.get("params", {}) or {}
        if not isinstance(params, Mapping) or not all(
            isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool)
            for k, v in params.items()
        ):
            raise PolicyError(f"policy {data['name']}: params must map names to numbers")
        plugin = data.get("plugin")
        if plugin is None:  # a built-in: its display colour and label from this registry
            known = builtins(multi=True).get(data["name"])
            return cls(name=data["name"], params={k: float(v) for k, v in params.items()},
                       version=__version__, label=known.label if known else "",
                       color=known.color if known else None)  # fmt: skip
        if not isinstance(plugin, Mapping):
            raise PolicyError(f"policy {data['name']}: 'plugin' must be an object")
        color = plugin.get("color")
        rgb: RGB | None = None
        if isinstance(color, list) and len(color) == 3 and all(isinstance(c, int) for c in color):
            rgb = (int(color[0]), int(color[1]), int(color[2]))
        sha = plugin.get("sha256", "")
        if not (isinstance(sha, str) and len(sha) == 64
                and all(c in "0123456789abcdef" for c in sha)):  # fmt: skip
            sha = ""
        return cls(
            name=data["name"],
            params={k: float(v) for k, v in params.items()},
            qualname=str(plugin.get("qualname", "")) or f"plugin:{data['name']}",
            version=str(plugin.get("version", "")),
            tier=str(plugin.get("tier", "compiled")),
            label=str(plugin.get("label", "") or data["name"]),
            color=rgb,
            sha256=sha,
        )

    @property
    def digest(self) -> str:
        """The sha256 (hex, or the 16 digits an older log's version holds) of the source
        this spec ran with; "" when it names none (a built-in, a versioned package)."""
        if self.sha256:
            return self.sha256
        tail = self.version.removeprefix("sha256:")
        if tail != self.version and len(tail) >= 16 and all(c in "0123456789abcdef" for c in tail):
            return tail
        return ""

    def resolve(self) -> type[PolicyBase]:
        """The policy class (importing the plug-in); PolicyError when it cannot be had, and
        :class:`~corraoi.errors.CodeChanged` when its source is not the one this spec names
        (a run never goes under another code's hash)."""
        if self.builtin:
            cls = builtins(multi=True).get(self.name)
            if cls is None:
                raise PolicyError(f"policy {self.name}: not a built-in of corraoi {__version__}")
            return cls
        expect = self.digest
        here = held(self.name, self.qualname, expect)
        if here is not None:
            found = registered_digest(here)
            if expect and found and not found.startswith(expect):
                raise CodeChanged(source_path(here), expect, found)
            return here
        qual = self.qualname
        if qual.startswith("__main__:"):
            raise PolicyError(
                f"policy {self.name}: its class {qual.partition(':')[2]} was defined in a Python "
                "session (a notebook or a script), not in a module corraoi can import; record "
                "its runs from a session that defines it: corraoi.load(SWEEP).record(..., "
                f"policy={qual.partition(':')[2]})"
            )
        if qual.startswith("file:"):
            return resolve(qual[len("file:") :], expect=expect).cls
        res = resolve(qual if ":" in qual and not qual.startswith("plugin:") else self.name)
        if expect and res.sha256 and not res.sha256.startswith(expect):
            raise CodeChanged(source_path(res.cls), expect, res.sha256)
        return res.cls

    def param_vector(self, cls: type[PolicyBase]) -> np.ndarray:
        """The parameters in the class's declared order (what compiled hooks receive)."""
        return np.array([float(self.params[p]) for p in cls.params], dtype=np.float64)


def multi_source_forms(name: str) -> list[str]:
    """The built-in multi-source forms of the policy ``name`` (``rhorand-ucb``, ... for
    ``ucb``; none for most)."""
    return [n for n, cls in builtins(multi=True).items()
            if getattr(cls, "multi_source", "") and n == f"{cls.multi_source}-{name}"]  # fmt: skip


def check_sources(spec: PolicySpec, sources: int, cls: type[PolicyBase] | None = None) -> None:
    """A ConfigValueError (one line naming its multi-source forms) when a single-source policy is
    given several sources. A multi-source form takes any number (one source is its base
    policy); ``cls`` is the resolved class, else a built-in's is looked up (a plug-in's is
    checked when it runs) and a loop logged by ``corraoi.Logger`` is not checked."""
    if sources == 1 or spec.tier == "external":
        return
    if cls is None:
        if not spec.builtin:
            return
        cls = builtins(multi=True).get(spec.name)
        if cls is None:
            return
    if getattr(cls, "multi_source", ""):
        return
    if getattr(cls, "tier", "") == "python":
        raise ConfigValueError(f"policy {spec.name} is single-source; with sources {sources} "
                               'a plain-Python policy declares multi_source = "own" (each '
                               'source an instance of its own; docs/extending.md, "Many '
                               'sources")')  # fmt: skip
    forms = multi_source_forms(spec.name)
    rules = sorted({getattr(c, "multi_source", "") for c in builtins(multi=True).values()} - {""})
    bases = sorted({n.split("-", 1)[1] for n, c in builtins(multi=True).items()
                    if getattr(c, "multi_source", "")}, key=len)  # fmt: skip
    hint = (f"use one of its multi-source forms: {', '.join(forms)}" if forms else
            f"it has no multi-source form ({'-, '.join(rules)}-<policy> exist for "
            f"{', '.join(bases)})")  # fmt: skip
    raise ConfigValueError(f"policy {spec.name} is single-source; with sources {sources} "
                           f"{hint}")


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
        if given is not None and (isinstance(given, bool)
                                  or not isinstance(given, (int, float, np.number))):
            raise PolicyError(f"policy {policy_name(cls)}: parameter {pname}={given!r}: "
                              "expected a number")  # fmt: skip
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
        sha256=res.sha256,
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
                key = n.lower() if n.lower() in builtins(multi=True) else n
                resolve(key)
                if key not in names:
                    names.append(key)
    if not names:
        raise PolicyError("no policy given (expected a name, a comma list or all)")
    return names


def param_key(item: str, name: str, example: str = "c=1.5") -> str:
    """The NAME (or POLICY.NAME) of one ``--param`` word, checked (PolicyError if not)."""
    scope, _, pname = name.strip().rpartition(".")
    if not pname.isidentifier() or (scope == "" and "." in name):
        raise PolicyError(f"--param {item!r}: expected NAME=VALUE or POLICY.NAME=VALUE (e.g. "
                          f"--param {example})")  # fmt: skip
    return f"{scope.strip()}.{pname}" if scope.strip() else pname


def parse_param_assignments(items: Iterable[str]) -> dict[str, float]:
    """``--param NAME=VALUE`` (or ``POLICY.NAME=VALUE``, for one policy) words into a dict
    (later ones win); one clear line if malformed."""
    out: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise PolicyError(f"--param {item!r}: expected NAME=VALUE or POLICY.NAME=VALUE "
                              "(e.g. --param c=1.5)")  # fmt: skip
        key = param_key(item, name)
        try:
            value = float(text)
        except ValueError:
            raise PolicyError(f"--param {item!r}: {text.strip()!r} is not a number") from None
        out[key] = value
    return out


V = TypeVar("V")


def assign_params(
    tokens: Sequence[str],
    classes: Mapping[str, type[PolicyBase]],
    given: Mapping[str, V],
    *,
    warn: Callable[[str], None] | None = None,
) -> dict[str, dict[str, V]]:
    """Which listed policy (a ``--policy`` word in ``tokens``) takes which parameter.

    ``NAME`` goes to every listed policy that declares it (an error if none does, so that a
    typo is never ignored; a warning through ``warn`` when more than one does, since a value
    meant for one changes the others too); ``POLICY.NAME`` to that policy only (its name or
    its ``--policy`` word), and wins over ``NAME`` there."""
    names = {t: policy_name(classes[t]) for t in tokens}
    out: dict[str, dict[str, V]] = {t: {} for t in tokens}
    scoped: list[tuple[str, str, V]] = []
    for key, value in given.items():
        scope, _, pname = key.rpartition(".")
        if scope:
            scoped.append((scope, pname, value))
            continue
        takers = [t for t in tokens if pname in classes[t].params]
        if not takers:
            users = sorted(n for n, cls in builtins().items() if pname in cls.params)
            read_by = f" (it is read by {', '.join(users)})" if users else ""
            raise PolicyError(f"parameter {pname} does not apply to "
                              f"{', '.join(names.values())}{read_by}")  # fmt: skip
        if len(takers) > 1 and warn is not None:
            listed = ", ".join(names[t] for t in takers)
            warn(f"--param {pname} applies to {listed}; to set it for one of them, write "
                 f"--param POLICY.{pname}=... (e.g. --param {names[takers[-1]]}.{pname}=...)")
        for t in takers:
            out[t][pname] = value
    for scope, pname, value in scoped:
        match = [t for t in tokens if scope.lower() in (t.lower(), names[t].lower())]
        if not match:
            raise PolicyError(f"--param {scope}.{pname}: {scope} is not one of the listed "
                              f"policies ({', '.join(names.values())})")  # fmt: skip
        for t in match:
            if pname not in classes[t].params:
                known = ", ".join(classes[t].params) or "none"
                raise PolicyError(f"--param {scope}.{pname}: policy {names[t]} has no "
                                  f"parameter {pname!r} (it declares: {known})")  # fmt: skip
            out[t][pname] = value
    return out


def make_policies(
    values: Iterable[str],
    params: Mapping[str, float] | None = None,
    *,
    c: float | None = None,
    beta: float | None = None,
    warn: Callable[[str], None] | None = None,
) -> list[PolicySpec]:
    """Specs for ``--policy`` values, with the parameters :func:`assign_params` gives each.
    ``c`` and ``beta`` are the shorthands ``--c`` and ``--beta``."""
    given = dict(params or {})
    for key, value in (("c", c), ("beta", beta)):
        if value is not None:
            given[key] = float(value)
    tokens = parse_policy_names(values)
    classes = {t: resolve(t).cls for t in tokens}
    each = assign_params(tokens, classes, given, warn=warn)
    return [make_policy(t, **each[t]) for t in tokens]
