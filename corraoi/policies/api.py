"""The policy API: parameters, the two tiers of policies, and the spec a run is logged with.

A policy is ONE class. Built-ins and plug-ins subclass the same two bases:

* :class:`CompiledPolicy` -- numba-compiled hooks (``forced``, ``score``, ``update``) that the
  engine inlines into its compiled kernel: built-in speed. ``correlated`` and ``aoi_aware``
  switch on the paper's candidate set (CUCB/CTS) and the AoI-aware override around any score.
* :class:`Policy` -- plain Python: ``select(t, state)`` returns one arm per run, vectorised
  over runs (arrays of shape runs x K), for quick experiments.

What a run is made and logged with (the name, parameter values and where the class came
from) is a :class:`~corraoi.policies.spec.PolicySpec`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from corraoi.arguments import flag, number, optional, text, wrong_type, wrong_value
from corraoi.errors import PolicyError, PolicyTypeError

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
        hint = " (Param(default, help, low, high, ...))"
        number(self.default, name="Param default", kind=PolicyError, finite=False,
               expected="a number" + hint)  # fmt: skip
        for bound in ("low", "high"):
            optional(number, getattr(self, bound), name=f"Param {bound}", kind=PolicyError,
                     finite=False, expected="a number or None" + hint)  # fmt: skip
        text(self.help, name="Param help", kind=PolicyError, empty=True,
             expected="a line of text" + hint)  # fmt: skip
        for field in ("open_low", "open_high", "integer"):
            flag(getattr(self, field), name=f"Param {field}", kind=PolicyError)
        if self.low is not None and self.high is not None and self.low > self.high:
            raise wrong_value(PolicyError, "Param low", self.low,
                              f"a low bound <= high ({self.high!r})")  # fmt: skip
        problem = self.check(float(self.default))
        if problem is not None:
            why = "out of range" if problem.startswith("must be in") else problem
            raise wrong_value(PolicyError, "Param default", self.default, self.range_text(), why)

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
        inside = "must be " + ("" if self.integer else "in ") + self.range_text()
        if self.low is not None and (value < self.low or (self.open_low and value == self.low)):
            return inside
        if self.high is not None and (value > self.high or (self.open_high and value == self.high)):
            return inside
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
    #: How several sources share the channels (docs/model.md, "Many sources"); "" for a
    #: single-source policy. A compiled policy names the engine's rule that picks each
    #: source's channel from its scores ("rhorand", "mctopm", "centralized" or "chairs"),
    #: its hooks run once per source; a plain-Python policy says "own": each source is an
    #: instance of its own that picks its channel from its own state.
    multi_source: ClassVar[str] = ""
    tier: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        check_declaration(cls)

    @classmethod
    def describe(cls) -> str:
        if cls.summary:
            return cls.summary
        doc = (cls.__doc__ or "").strip().splitlines()
        return doc[0].strip() if doc else ""


def check_declaration(cls: type[PolicyBase]) -> type[PolicyBase]:
    """A policy class's declarations checked as it is declared (and again where it is
    registered): ``params`` a table of parameter names to :class:`Param`, ``name``,
    ``label``, ``summary`` and ``reference`` text, ``color`` an RGB triple or None.
    :class:`~corraoi.errors.PolicyTypeError` / ``PolicyValueError`` name what is wrong."""
    where = cls.__qualname__
    for attr in ("name", "label", "summary", "reference"):
        text(getattr(cls, attr), name=f"{where}.{attr}", kind=PolicyError, empty=True)
    table = cls.params
    if not isinstance(table, Mapping):
        raise wrong_type(PolicyError, f"{where}.params", table,
                         'a dict of parameter names to corraoi.Param (e.g. {"epsilon": '
                         'Param(0.1, "exploration", low=0, high=1)})')  # fmt: skip
    for key, decl in table.items():
        if not isinstance(key, str) or not key.isidentifier():
            raise wrong_value(PolicyError, f"{where}.params key", key,
                              "a parameter name (a Python identifier)")  # fmt: skip
        if not isinstance(decl, Param):
            raise wrong_type(PolicyError, f"{where}.params[{key!r}]", decl,
                             f'a corraoi.Param (e.g. Param({decl!r}, "help", low=..., '
                             "high=...))" if isinstance(decl, (int, float)) else
                             "a corraoi.Param")  # fmt: skip
    color = cls.color
    if color is not None and not (
        isinstance(color, (tuple, list)) and len(color) == 3
        and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 255 for c in color)
    ):  # fmt: skip
        raise wrong_type(PolicyError, f"{where}.color", color,
                         "None or an (r, g, b) tuple of integers 0..255")  # fmt: skip
    return cls


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


class RunStreams(Protocol):
    """The runs' own random streams (``state.rng``), vectorised: every method returns one
    value (or row) per run, drawn from that run's stream only (the engine's
    :class:`corraoi.engine.pyengine.Streams`)."""

    @property
    def runs(self) -> int: ...

    def random(self, size: int | None = None) -> np.ndarray:
        """Uniforms in [0, 1): shape (runs,) or (runs, size)."""
        ...

    def integers(self, high: int | np.ndarray) -> np.ndarray:
        """A uniform integer in [0, high) per run (``high`` a scalar or (runs,), >= 1)."""
        ...

    def normal(self, size: int | None = None) -> np.ndarray:
        """Standard normals: shape (runs,) or (runs, size)."""
        ...

    def beta(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Beta(a, b) samples of shape (runs, K) for shape parameters >= 1 of that shape."""
        ...

    def argmax(self, values: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Per run, the index of the largest value (among ``mask``), ties uniformly at
        random -- the rule the built-ins use."""
        ...


class RunState:
    """What a plain-Python policy sees: read-only, arms 0-based.

    ``t`` the current slot (1-based; 0 in ``reset``); ``runs``, ``arms`` (K); ``seeds``
    (runs,); ``pulls`` and ``successes`` (runs, K) int64 before this slot; ``mu_hat``
    (runs, K) their ratio (0 for unpulled arms); ``aoi`` (runs,) the current age; ``rng`` the
    runs' streams. In a run of several sources (a policy with ``multi_source = "own"``) each
    source has a state of its own: ``source`` (1..``sources``) says whose, its counts and age
    are that source's, and ``collided`` (runs,) bool says whether its last play collided
    (always False with one source). ``successes`` counts the slots its channel was ON when it
    played it, delivered or not (collision sensing).

    The arrays are read-only views of the engine's own: they follow the run as it advances
    (keep ``state.pulls.copy()`` for a snapshot), and a write into one (``state.mu_hat[0] =
    1``, ``state.aoi += 1``, ``np.copyto(state.pulls, 0)``) raises at once, as does setting
    any attribute (``state.t = 0``); the engine then ends the run with one
    :class:`~corraoi.errors.PolicyRuntimeError` naming the policy, the field and the slot.
    """

    #: The fields a policy reads (each read-only).
    FIELDS: ClassVar[tuple[str, ...]] = ("t", "runs", "arms", "seeds", "pulls", "successes",
                                         "mu_hat", "aoi", "rng", "source", "sources",
                                         "collided")  # fmt: skip
    __slots__ = ("_clock", "runs", "arms", "seeds", "rng", "pulls", "successes", "mu_hat",
                 "aoi", "source", "sources", "collided")  # fmt: skip
    _clock: np.ndarray
    runs: int
    arms: int
    seeds: np.ndarray
    rng: RunStreams
    pulls: np.ndarray
    successes: np.ndarray
    mu_hat: np.ndarray
    aoi: np.ndarray
    source: int
    sources: int
    collided: np.ndarray

    def __init__(self, *, runs: int, arms: int, seeds: np.ndarray, rng: RunStreams,
                 pulls: np.ndarray, successes: np.ndarray, mu_hat: np.ndarray,
                 aoi: np.ndarray, clock: np.ndarray, source: int = 1, sources: int = 1,
                 collided: np.ndarray | None = None) -> None:  # fmt: skip
        """The engine's arrays, each shown through a read-only view (``clock``: a (1,) array
        whose entry is the current slot; ``collided`` None: never, for one source)."""
        put = object.__setattr__
        put(self, "_clock", read_only(clock))
        put(self, "runs", int(runs))
        put(self, "arms", int(arms))
        put(self, "seeds", read_only(seeds))
        put(self, "rng", rng)
        put(self, "pulls", read_only(pulls))
        put(self, "successes", read_only(successes))
        put(self, "mu_hat", read_only(mu_hat))
        put(self, "aoi", read_only(aoi))
        put(self, "source", int(source))
        put(self, "sources", int(sources))
        put(self, "collided", read_only(np.zeros(int(runs), dtype=np.bool_) if collided is None
                                        else collided))  # fmt: skip

    @property
    def t(self) -> int:
        return int(self._clock[0])

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"state.{name} is read-only", name=name, obj=self)

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"state.{name} is read-only", name=name, obj=self)


def read_only(a: np.ndarray) -> np.ndarray:
    """A view of the C-contiguous array ``a`` that nothing can write through: its memory is a
    read-only buffer, so even ``view.flags.writeable = True`` is refused. It sees every
    later write into ``a``."""
    ro = np.frombuffer(a.data.toreadonly(), dtype=a.dtype)
    return ro.reshape(a.shape)


@dataclass(frozen=True)
class Choice:
    """What a plain-Python policy's ``select`` may return instead of bare arms: the arm of
    every run (runs,), and optionally the candidate set it chose from (runs, K) bool and the
    score of every arm (runs, K) numbers, what it maximised (logged as ``score``; NaN for an
    arm it did not score). A slot whose played arm does not have the highest score (or has
    none) is logged ``forced``."""

    arms: Any
    candidates: Any = None
    scores: Any = None


class Policy(PolicyBase):
    """A plain-Python policy, vectorised over runs. Subclass it and define :meth:`select`.

    Parameters arrive as attributes (``self.epsilon``). The engine calls :meth:`reset` once
    before slot 1, :meth:`select` every slot and :meth:`update` after it; ``state`` (a
    :class:`RunState`) holds the history as arrays of shape (runs, K) and
    the runs' own random streams (``state.rng``). Plain-Python policies log every arm as a
    candidate, no AoI-aware override and no score unless ``select`` returns
    ``(arms, candidates)`` or a :class:`Choice` with candidates and scores.
    """

    tier: ClassVar[str] = "python"

    def __init__(self, **params: float) -> None:
        cls = type(self)
        for key, value in params.items():
            decl = cls.params.get(key)
            if decl is None:
                declared = ", ".join(cls.params) or "none"
                raise PolicyTypeError(f"{cls.__qualname__}({key}=...): not a parameter it "
                                      f"declares (it declares: {declared})")  # fmt: skip
            x = number(value, name=f"{cls.__qualname__}({key}=...)", kind=PolicyError,
                       finite=False)  # fmt: skip
            problem = decl.check(x)
            if problem is not None:
                raise wrong_value(PolicyError, f"{cls.__qualname__}({key}=...)", value,
                                  decl.range_text(), problem)  # fmt: skip
            setattr(self, key, value)

    def reset(self, state: RunState) -> None:
        """Called once before slot 1."""

    def select(self, t: int, state: RunState) -> Any:
        """The arm of every run at slot ``t``: an int array of shape (runs,), 0-based."""
        raise NotImplementedError

    def update(self, t: int, arms: np.ndarray, rewards: np.ndarray, state: RunState) -> None:
        """Called after slot ``t`` with the arms played and their 0/1 rewards."""
