"""The policy API: parameters, the two tiers of policies, and the spec a run is logged with.

A policy is ONE class. Built-ins and plug-ins subclass the same two bases:

* :class:`CompiledPolicy` -- numba-compiled hooks (``forced``, ``score``, ``update``) that the
  engine inlines into its compiled kernel: built-in speed. ``correlated`` and ``aoi_aware``
  switch on the paper's candidate set (CUCB/CTS) and the AoI-aware override around any score.
* :class:`Policy` -- plain Python: ``select(t, state)`` returns one arm per run, vectorised
  over runs (arrays of shape runs x K), for quick experiments.

A :class:`PolicySpec` is what a run is made and logged with: the name, the parameter values,
and where the class came from (qualified name, version), so a log reads without the plug-in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .._version import __version__
from ..errors import PolicyError

if TYPE_CHECKING:
    from ..pyengine import RunState

RGB = tuple[int, int, int]
BUILTIN_PREFIX = "corraoi:"


@dataclass(frozen=True)
class Param:
    """A declared policy parameter: default, valid range and help.

    ``low``/``high`` bound the value (``None``: unbounded); ``open_low``/``open_high`` make a
    bound strict; ``integer`` asks for a whole number (still passed to hooks as a float).
    """

    default: float
    help: str = ""
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    integer: bool = False

    def __post_init__(self) -> None:
        if self.check(float(self.default)) is not None:
            raise PolicyError(f"parameter default {self.default!r} is outside {self.range_text()}")

    def range_text(self) -> str:
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        left = "(" if self.open_low or self.low is None else "["
        right = ")" if self.open_high or self.high is None else "]"
        kind = "an integer in " if self.integer else ""
        return f"{kind}{left}{lo}, {hi}{right}"

    def check(self, value: float) -> str | None:
        """None when ``value`` is valid, else what is wrong with it."""
        if not math.isfinite(value):
            return "must be finite"
        if self.integer and value != int(value):
            return "must be a whole number"
        if self.low is not None and (value < self.low or (self.open_low and value == self.low)):
            return f"must be in {self.range_text()}"
        if self.high is not None and (value > self.high or (self.open_high and value == self.high)):
            return f"must be in {self.range_text()}"
        return None


@dataclass(frozen=True)
class GpuForm:
    """The GPU form of a compiled policy family: its entry point ``advance_<kernel>`` in
    ``corraoi/gpu/kernel.cu`` (one CUDA thread per run, the same rule as the CPU hooks), and
    whether it keeps the CPU hooks' per-run state ``ps`` (same layout, ``state_size``)."""

    kernel: str
    uses_state: bool = False


def gpu_form(cls: type[PolicyBase]) -> GpuForm | None:
    """The GPU form of ``cls``, or None: a subclass that replaces a hook of the class that
    declared the form has none (the GPU kernel would not run its rule)."""
    form = getattr(cls, "gpu", None)
    if form is None or not issubclass(cls, CompiledPolicy):
        return None
    owner = next(c for c in cls.__mro__ if "gpu" in c.__dict__)
    for hook in ("forced", "score", "update"):
        if getattr(cls, hook) is not getattr(owner, hook):
            return None
    return form


class PolicyBase:
    """What every policy class declares (class attributes)."""

    #: The name ``--policy`` takes and logs and file names show.
    name: ClassVar[str] = ""
    #: Declared parameters, in the order compiled hooks receive them in ``params``.
    params: ClassVar[Mapping[str, Param]] = {}
    #: A short human label for legends (defaults to ``name``).
    label: ClassVar[str] = ""
    #: Display colour (RGB 0..255) in every view and figure; None: one derived from the name.
    color: ClassVar[RGB | None] = None
    #: A one-line description (``corraoi policies``); the class docstring by default.
    summary: ClassVar[str] = ""
    #: Where the rule comes from (shown by ``corraoi policies --json``).
    reference: ClassVar[str] = ""
    #: The policy's GPU form (:class:`GpuForm`; the built-in families have one), or None.
    gpu: ClassVar[GpuForm | None] = None
    #: The paper's theorem bounding this policy's regret, if any ("cucb" or "cts").
    theorem: ClassVar[str | None] = None
    #: In ``--policy all``: the paper's twelve policies.
    paper: ClassVar[bool] = False
    tier: ClassVar[str] = ""

    @classmethod
    def describe(cls) -> str:
        if cls.summary:
            return cls.summary
        doc = (cls.__doc__ or "").strip().splitlines()
        return doc[0].strip() if doc else ""


class CompiledPolicy(PolicyBase):
    """A policy made of numba-compiled hooks, inlined into the engine's kernel.

    Hooks (each ``@numba.njit(cache=True)``, defined at module level; signatures fixed):

    Each hook is the function itself or its ``"module:function"`` name (imported only when the
    engine composes the kernel, so listing and reading logs never needs numba):

    * ``forced(t, K, npull, nsucc, params, ps, pst) -> int``: an arm to play whatever the
      score says (UCB's first pull of every arm, forced exploration), or -1;
    * ``score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache)``: write the
      index of every arm with ``cand[k]`` into ``vals[k]``; the engine plays the argmax over
      the candidates (ties uniformly at random);
    * ``update(t, arm, reward, K, npull, nsucc, params, ps)``: after the slot (counts are
      already updated), update the policy's own state ``ps``.

    ``t`` is the 1-based slot; ``npull``/``nsucc`` (K,) int64 pulls and successes; ``muhat``
    (K,) empirical means (0 for unpulled arms); ``params`` (P,) float64 in declared order;
    ``ps`` (S,) float64 per-run state of :meth:`state_size` entries, zero at the start;
    ``pst`` the run's policy stream and ``cache`` a scratch pair, for :mod:`corraoi.rng`.
    """

    tier: ClassVar[str] = "compiled"
    forced: ClassVar[Any] = None
    score: ClassVar[Any] = None
    update: ClassVar[Any] = None
    #: Restrict the choice to the correlated candidate set A_t + {k_emp} (CUCB/CTS).
    correlated: ClassVar[bool] = False
    #: The AoI-aware override: play argmax mu_hat when the age exceeds 1 / max mu_hat.
    aoi_aware: ClassVar[bool] = False

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        """Per-run float64 state entries the hooks need (``ps``); 0 by default."""
        return 0


class Policy(PolicyBase):
    """A plain-Python policy, vectorised over runs. Subclass it and define :meth:`select`.

    Parameters arrive as attributes (``self.epsilon``). The engine calls :meth:`reset` once
    before slot 1, :meth:`select` every slot and :meth:`update` after it; ``state`` (a
    :class:`corraoi.pyengine.RunState`) holds the history as arrays of shape (runs, K) and
    the runs' own random streams (``state.rng``). Plain-Python policies log every arm as a
    candidate and no AoI-aware override unless ``select`` returns ``(arms, candidates)``.
    """

    tier: ClassVar[str] = "python"

    def __init__(self, **params: float) -> None:
        for key, value in params.items():
            setattr(self, key, value)

    def reset(self, state: RunState) -> None:
        """Called once before slot 1."""

    def select(self, t: int, state: RunState) -> Any:
        """The arm of every run at slot ``t``: an int array of shape (runs,), 0-based."""
        raise NotImplementedError

    def update(self, t: int, arms: np.ndarray, rewards: np.ndarray, state: RunState) -> None:
        """Called after slot ``t`` with the arms played and their 0/1 rewards."""


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
            from .registry import builtins

            known = builtins().get(data["name"])
            return cls(name=data["name"], params={k: float(v) for k, v in params.items()},
                       version=__version__, label=known.label if known else "",
                       color=known.color if known else None)  # fmt: skip
        if not isinstance(plugin, Mapping):
            raise PolicyError(f"policy {data['name']}: 'plugin' must be an object")
        color = plugin.get("color")
        rgb: RGB | None = None
        if isinstance(color, list) and len(color) == 3 and all(isinstance(c, int) for c in color):
            rgb = (int(color[0]), int(color[1]), int(color[2]))
        return cls(
            name=data["name"],
            params={k: float(v) for k, v in params.items()},
            qualname=str(plugin.get("qualname", "")) or f"plugin:{data['name']}",
            version=str(plugin.get("version", "")),
            tier=str(plugin.get("tier", "compiled")),
            label=str(plugin.get("label", "") or data["name"]),
            color=rgb,
        )

    def resolve(self) -> type[PolicyBase]:
        """The policy class (importing the plug-in); PolicyError when it cannot be had."""
        from .registry import resolve_spec

        return resolve_spec(self)

    def param_vector(self, cls: type[PolicyBase]) -> np.ndarray:
        """The parameters in the class's declared order (what compiled hooks receive)."""
        return np.array([float(self.params[p]) for p in cls.params], dtype=np.float64)
