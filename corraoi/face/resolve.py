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

from corraoi.arguments import number, optional, path, text, wrong_type, wrong_value
from corraoi.errors import ConfigError, CorraoiWarning, InstanceError, PolicyError
from corraoi.model.channels import Channel, TraceReader, parse_channel
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import PolicyBase, PolicySpec, make_policies, register
from corraoi.policies.registry import policy_name


def _states_of_log(path: Any, instance: Instance, where: str) -> Any:
    """:func:`corraoi.recorder.slotlog.trace.states_of_log`, imported when a trace is a log."""
    from corraoi.recorder.slotlog.trace import states_of_log

    return states_of_log(path, instance, where)


#: Readers of trace files that are not text, by suffix: a corraoi slot log.
TRACE_READERS: Mapping[str, TraceReader] = {".mcap": _states_of_log}

#: What ``policy`` may be: a word, a class, an instance of a class, or several of those.
PolicyLike = str | type[PolicyBase] | PolicyBase
#: What a ``channel`` argument accepts, in words.
CHANNEL_WORDS = "iid, markov or trace:PATH (a text trace or a slot log), or None"
#: What a policy argument accepts, in words.
POLICY_LIKE = ("a policy name, a FILE.py:Class or module:Class word, or a corraoi.Policy or "
               "corraoi.CompiledPolicy class or instance")  # fmt: skip
#: A parameter's value: a number, or (for sweeps) several.
ParamValue = float | Sequence[float]


def channel_word(value: object, name: str = "channel") -> str | None:
    """A ``channel`` argument checked before anything is done: None (the instance's
    default), ``iid``, ``markov`` or ``trace:PATH`` (:data:`CHANNEL_WORDS`)."""
    word = optional(text, value, name=name, kind=ConfigError, empty=True, expected=CHANNEL_WORDS)
    kind = (word or "").strip()
    if kind and kind not in ("iid", "markov") and not kind.startswith("trace:"):
        raise wrong_value(ConfigError, name, value, CHANNEL_WORDS)
    return word


def channel(spec: str | None, instance: Instance) -> Channel:
    """``--channel`` value for ``instance``: ``iid``, ``markov``, ``trace:PATH`` (a text file of
    1-based states or a corraoi slot log), or None for the instance's default."""
    return parse_channel(spec, instance, readers=TRACE_READERS)


def instance(value: str | os.PathLike[str] | Instance, what: str = "instance") -> Instance:
    """An instance from a built-in name (``"I1"``), a file, or an ``Instance`` itself;
    :class:`~corraoi.errors.InstanceError` when it is none of these or cannot be simulated."""
    if isinstance(value, Instance):
        inst = value
    else:
        given = path(value, name=what, kind=InstanceError,
                     what="a built-in name (I1, I2, GE), an instance file or a corraoi.Instance")
        inst = load_instance(os.fspath(given))
    from corraoi.engine.problem import check_instance

    check_instance(inst)
    return inst


def _word(value: object, what: str = "policy") -> tuple[str, dict[str, float]]:
    """The ``--policy`` word of one policy-like value, and the parameters an instance of a
    plain-Python policy carries as attributes."""
    if isinstance(value, str):
        return text(value, name=what, kind=PolicyError, expected=POLICY_LIKE), {}
    cls = value if isinstance(value, type) else type(value)
    if not (isinstance(cls, type) and issubclass(cls, PolicyBase)):
        raise wrong_type(PolicyError, what, value, POLICY_LIKE)
    if cls in (PolicyBase,) or cls.__name__ in ("Policy", "CompiledPolicy") and (
        cls.__module__ == "corraoi.policies.api"
    ):
        raise wrong_value(PolicyError, what, value, "a subclass of it (a base class makes no "
                          "policy)")  # fmt: skip
    register(cls)  # PolicyError (one line) if it is not a usable policy class
    given = {}
    if not isinstance(value, type):  # an instance: its declared parameters set on it
        for name in cls.params:
            if name in vars(value):
                given[name] = vars(value)[name]
    return policy_name(cls), given


def _listed(policy: PolicyLike | Sequence[PolicyLike], what: str = "policy") -> list[PolicyLike]:
    if isinstance(policy, (str, type, PolicyBase)):
        return [policy]
    if not isinstance(policy, Sequence) or isinstance(policy, (bytes, bytearray)):
        several = ", or a list of them" if what == "policies" else ""
        raise wrong_type(PolicyError, what, policy, POLICY_LIKE + several)
    if not policy:
        raise wrong_value(PolicyError, what, policy, "at least one policy", "empty")
    return list(policy)


def flat_params(
    params: Mapping[str, Any] | None, *, several: bool = False
) -> dict[str, Any]:
    """``{name: value}`` / ``{policy: {name: value}}`` as ``--param`` keys (``NAME``,
    ``POLICY.NAME``). ``several``: a value may be a list of values (a sweep's grid)."""
    out: dict[str, Any] = {}
    if params is None:
        return out
    if not isinstance(params, Mapping):
        raise wrong_type(PolicyError, "params", params, "a dict of name: value (or policy: "
                         "{name: value}), or None")  # fmt: skip
    one = "a number" + (" or a list of numbers (a grid)" if several else "")

    def value(key: str, v: Any) -> Any:
        where = f"params[{key!r}]"
        if isinstance(v, Sequence) and not isinstance(v, str):
            if not several:
                raise wrong_type(PolicyError, where, v, "one number (several values make a "
                                 "grid: corraoi.sweep)")  # fmt: skip
            if not v:
                raise wrong_value(PolicyError, where, v, "at least one number", "empty")
            return [number(x, name=f"{where}[{i}]", kind=PolicyError) for i, x in enumerate(v)]
        return number(v, name=where, kind=PolicyError, expected=one)

    for key, v in params.items():
        if not isinstance(key, str) or not key.strip():
            raise wrong_type(PolicyError, "params key", key, "a parameter or policy name")
        if isinstance(v, Mapping):
            for name, inner in v.items():
                if not isinstance(name, str) or not name.isidentifier():
                    raise wrong_type(PolicyError, f"params[{key!r}] key", name,
                                     "a parameter name")  # fmt: skip
                out[f"{key}.{name}"] = value(f"{key}.{name}", inner)
        else:
            out[key] = value(key, v)
    return out


def python_warn(message: str) -> None:
    """A warning of the command line's words, said to a Python caller."""
    warnings.warn(message.replace("--param ", "params "), CorraoiWarning, stacklevel=4)


def policy_words(
    policy: PolicyLike | Sequence[PolicyLike], params: Mapping[str, Any] | None,
    what: str = "policy",
) -> tuple[list[str], dict[str, Any]]:
    """The ``--policy`` words and the ``--param`` keys of a Python call: classes registered,
    an instance's own parameters scoped to it (``params`` win where both set one)."""
    words: list[str] = []
    scoped: dict[str, Any] = {}
    listed = _listed(policy, what)
    for i, item in enumerate(listed):
        word, own = _word(item, what if len(listed) == 1 else f"{what}[{i}]")
        words.append(word)
        for name, v in own.items():
            scoped[f"{word}.{name}"] = number(v, name=f"{word}.{name}", kind=PolicyError)
    return words, scoped


def policies(
    policy: PolicyLike | Sequence[PolicyLike],
    params: Mapping[str, Any] | None = None,
    *,
    warn: Callable[[str], None] | None = python_warn,
    what: str = "policy",
) -> list[PolicySpec]:
    """The checked specs of ``policy`` with ``params`` (module docstring); ``what``: the
    argument's name in messages."""
    words, scoped = policy_words(policy, params, what)
    return make_policies(words, {**scoped, **flat_params(params)}, warn=warn)


__all__ = [
    "CHANNEL_WORDS",
    "POLICY_LIKE",
    "TRACE_READERS",
    "ParamValue",
    "PolicyLike",
    "channel",
    "channel_word",
    "flat_params",
    "instance",
    "policies",
    "policy_words",
    "python_warn",
]
