"""The words, paths and objects a user gives, resolved with every reader the house has: what
the top floor hands the layers below, so that they never name the recorder.

* an instance: a built-in name, a file, or an :class:`~corraoi.model.instance.Instance`;
* policies: a name, a ``FILE.py:Class`` or ``module:Class`` word, ``"all"``, a policy class
  (defined anywhere: a notebook cell, a test module) or an instance of one, or a list of
  those; a class is registered under its ``name`` so that every part of corraoi finds it;
* parameters: ``{name: value}`` (every listed policy that declares it, warned when several
  do) or ``{policy: {name: value}}`` (that policy only), as ``--param [POLICY.]NAME=VALUE``;
* a channel: ``iid``, ``markov`` or ``trace:PATH`` (a text trace or a corraoi slot log).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from corraoi.errors import CorraoiWarning, InstanceError, PolicyError, UsageError
from corraoi.model.channels import Channel, TraceReader, parse_channel
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import PolicyBase, PolicySpec, make_policies, register
from corraoi.policies.registry import policy_name
from recorder.slotlog.trace import states_of_log

#: Readers of trace files that are not text, by suffix: a corraoi slot log.
TRACE_READERS: Mapping[str, TraceReader] = {".mcap": states_of_log}

#: What ``policy`` may be: a word, a class, an instance of a class, or several of those.
PolicyLike = str | type[PolicyBase] | PolicyBase
#: A parameter's value: a number, or (for sweeps) several.
ParamValue = float | Sequence[float]


def channel(spec: str | None, instance: Instance) -> Channel:
    """``--channel`` value for ``instance``: ``iid``, ``markov``, ``trace:PATH`` (a text file of
    1-based states or a corraoi slot log), or None for the instance's default."""
    return parse_channel(spec, instance, readers=TRACE_READERS)


def instance(value: str | os.PathLike[str] | Instance) -> Instance:
    """An instance from a built-in name (``"I1"``), a file, or an ``Instance`` itself;
    :class:`~corraoi.errors.InstanceError` when it is none of these or cannot be simulated."""
    if isinstance(value, Instance):
        inst = value
    elif isinstance(value, (str, os.PathLike)):
        inst = load_instance(os.fspath(value))
    else:
        raise InstanceError(
            f"instance {value!r}: expected a built-in name (I1, I2, GE), an instance file or a "
            f"corraoi.Instance, got {type(value).__name__}"
        )
    from corraoi.engine.problem import check_instance

    check_instance(inst)
    return inst


def _word(value: Any) -> tuple[str, dict[str, float]]:
    """The ``--policy`` word of one policy-like value, and the parameters an instance of a
    plain-Python policy carries as attributes."""
    if isinstance(value, str):
        return value, {}
    cls = value if isinstance(value, type) else type(value)
    if not (isinstance(cls, type) and issubclass(cls, PolicyBase)):
        raise PolicyError(
            f"policy {value!r}: expected a policy name, a FILE.py:Class or module:Class word, "
            f"or a corraoi.Policy or corraoi.CompiledPolicy class or instance, got "
            f"{type(value).__name__}"
        )
    if cls in (PolicyBase,) or cls.__name__ in ("Policy", "CompiledPolicy") and (
        cls.__module__ == "corraoi.policies.api"
    ):
        raise PolicyError(f"policy {cls.__name__}: a base class; subclass it to make a policy")
    register(cls)  # PolicyError (one line) if it is not a usable policy class
    given = {}
    if not isinstance(value, type):  # an instance: its declared parameters set on it
        for name in cls.params:
            if name in vars(value):
                given[name] = vars(value)[name]
    return policy_name(cls), given


def _listed(policy: PolicyLike | Sequence[PolicyLike]) -> list[Any]:
    if isinstance(policy, (str, type, PolicyBase)):
        return [policy]
    if isinstance(policy, Sequence) and policy:
        return list(policy)
    raise PolicyError(f"policy {policy!r}: expected a policy, or a non-empty list of them")


def flat_params(
    params: Mapping[str, Any] | None, *, several: bool = False
) -> dict[str, Any]:
    """``{name: value}`` / ``{policy: {name: value}}`` as ``--param`` keys (``NAME``,
    ``POLICY.NAME``). ``several``: a value may be a list of values (a sweep's grid)."""
    out: dict[str, Any] = {}
    if params is None:
        return out
    if not isinstance(params, Mapping):
        raise UsageError(f"params: expected a dict of name: value, got {type(params).__name__}")

    def value(key: str, v: Any) -> Any:
        if isinstance(v, bool) or not isinstance(v, (int, float, Sequence)) or isinstance(v, str):
            raise UsageError(f"params[{key!r}]: expected a number, got {v!r}")
        if isinstance(v, Sequence):
            if not several:
                raise UsageError(f"params[{key!r}]: expected one number, got {v!r} (several "
                                 "values make a grid: corraoi.sweep)")  # fmt: skip
            if not v or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                for x in v):  # fmt: skip
                raise UsageError(f"params[{key!r}]: expected numbers, got {v!r}")
            return [float(x) for x in v]
        return float(v)

    for key, v in params.items():
        if not isinstance(key, str) or not key:
            raise UsageError(f"params: keys are parameter or policy names, got {key!r}")
        if isinstance(v, Mapping):
            for name, inner in v.items():
                if not isinstance(name, str) or not name.isidentifier():
                    raise UsageError(f"params[{key!r}]: {name!r} is not a parameter name")
                out[f"{key}.{name}"] = value(f"{key}.{name}", inner)
        else:
            out[key] = value(key, v)
    return out


def python_warn(message: str) -> None:
    """A warning of the command line's words, said to a Python caller."""
    warnings.warn(message.replace("--param ", "params "), CorraoiWarning, stacklevel=4)


def policy_words(
    policy: PolicyLike | Sequence[PolicyLike], params: Mapping[str, Any] | None
) -> tuple[list[str], dict[str, Any]]:
    """The ``--policy`` words and the ``--param`` keys of a Python call: classes registered,
    an instance's own parameters scoped to it (``params`` win where both set one)."""
    words: list[str] = []
    scoped: dict[str, Any] = {}
    for item in _listed(policy):
        word, own = _word(item)
        words.append(word)
        for name, v in own.items():
            scoped[f"{word}.{name}"] = float(v)
    return words, scoped


def policies(
    policy: PolicyLike | Sequence[PolicyLike],
    params: Mapping[str, Any] | None = None,
    *,
    warn: Callable[[str], None] | None = python_warn,
) -> list[PolicySpec]:
    """The checked specs of ``policy`` with ``params`` (module docstring)."""
    words, scoped = policy_words(policy, params)
    return make_policies(words, {**scoped, **flat_params(params)}, warn=warn)


__all__ = [
    "TRACE_READERS",
    "ParamValue",
    "PolicyLike",
    "channel",
    "flat_params",
    "instance",
    "policies",
    "policy_words",
    "python_warn",
]
