"""The slot-block record: what the engine yields and what every sink and reader speaks.

Arrays use 0-based arm and state indices; files and people see them from 1 (the sinks add 1,
the reader subtracts it).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from corraoi._version import __version__
from corraoi.errors import ConfigError
from corraoi.limits import check_horizon, check_seed
from corraoi.model.channels import Channel, default_channel
from corraoi.model.instance import Instance
from corraoi.model.theory import InstanceTheory, analyse
from corraoi.policies.spec import PolicySpec, check_sources

from .slot_record import BY_NAME, NAMES, REQUIRED

#: Up to this many arms a run logs its policy's scores (``score``, ``forced``) by default:
#: a float32 per candidate and slot (benchmarks/bench_record.py's sizes: at 4 arms a log
#: grows by about a quarter; at 256 arms it is 3 to 7 times as large).
SCORE_ARMS = 64

#: :attr:`RunConfig.instance_name` of a run without an instance.
NO_INSTANCE = "none"

#: The values of :attr:`RunConfig.streams`.
STREAMS = ("cpu", "gpu-cuda", "gpu-emulated")


@dataclass(frozen=True)
class RunConfig:
    """Everything that determines a run: with it, a log replays with nothing else.

    ``instance`` is None for a loop logged by ``corraoi.Logger`` without one (a testbed
    whose ``p`` and ``Y`` nobody knows): such a run has ``arms`` arms and no states, best
    arm or theory, and its log lacks what needs them (``x``, the oracle, the regret, the
    estimator). Everything that reads a run asks :attr:`K`, :attr:`n_states`,
    :attr:`instance_name` and :attr:`theory`, which answer for both kinds.
    """

    instance: Instance | None
    policy: PolicySpec
    seed: int
    horizon: int
    version: str = __version__
    channel: Channel | None = None
    #: whose random streams and rule decide the slots: "cpu" (the engine's), "gpu-cuda" or
    #: "gpu-emulated" (the GPU kernel's, captured on a CUDA device or on the host compiler:
    #: a run of a GPU sweep recorded again, corraoi.gpu.runner.capture_run)
    streams: str = "cpu"
    #: log the policy's scores (``score``, ``forced``): by default up to SCORE_ARMS arms
    score: bool | None = None
    #: the number of arms of a run without an instance (None with one: the instance's)
    arms: int | None = None
    #: the number of sources M sharing the channels (1 <= M <= K): each picks a channel a
    #: slot; two on one channel collide and neither delivers (docs/model.md, "Many sources")
    sources: int = 1

    def __post_init__(self) -> None:
        check_horizon(self.horizon)
        check_seed(self.seed)
        if self.streams not in STREAMS:
            raise ConfigError(f"streams {self.streams!r}: expected one of {', '.join(STREAMS)}")
        if self.instance is None:
            if self.policy.tier != "external":
                raise ConfigError(
                    f"policy {self.policy.name!r}: a run without an instance is a loop logged "
                    "by corraoi.Logger (policy tier external); expected an instance"
                )
            if type(self.arms) is not int or self.arms < 1:
                raise ConfigError(
                    f"arms {self.arms!r}: a run without an instance needs its number of arms, "
                    "an integer >= 1"
                )
        elif self.arms is not None and self.arms != self.instance.K:
            raise ConfigError(
                f"arms {self.arms!r}: instance {self.instance.name} has {self.instance.K} arms"
            )
        else:
            object.__setattr__(self, "arms", None)
        if self.channel is None:
            chan = Channel() if self.instance is None else default_channel(self.instance)
            object.__setattr__(self, "channel", chan)
        if self.score is None:
            object.__setattr__(self, "score", self.K <= SCORE_ARMS)
        if type(self.sources) is not int or not 1 <= self.sources <= self.K:
            raise ConfigError(
                f"sources {self.sources!r}: expected an integer from 1 to the number of "
                f"arms, {self.K}"
            )
        check_sources(self.policy, self.sources)

    @property
    def K(self) -> int:
        """The number of arms."""
        if self.instance is None:
            assert self.arms is not None
            return self.arms
        return self.instance.K

    @property
    def n_states(self) -> int | None:
        """The number of hidden states (None without an instance)."""
        return None if self.instance is None else self.instance.n_states

    @property
    def instance_name(self) -> str:
        """The instance's name, or ``none`` for a run without one."""
        return NO_INSTANCE if self.instance is None else self.instance.name

    @property
    def arm_names(self) -> tuple[str, ...]:
        """The arms' names ("1".."K" without an instance)."""
        if self.instance is None:
            return tuple(str(k + 1) for k in range(self.K))
        return tuple(self.instance.arm_names)

    @property
    def theory(self) -> InstanceTheory | None:
        """The instance's theory (mu, best arm, mu*, competitive arms); None without one."""
        return None if self.instance is None else analyse(self.instance)

    @property
    def model(self) -> Instance:
        """The instance, for what cannot run without one (simulating, recording again)."""
        if self.instance is None:
            raise ConfigError(
                f"run {self.label} has no instance (a loop logged by corraoi.Logger without "
                "one): expected a run with an instance"
            )
        return self.instance

    @property
    def format_version(self) -> int:
        """The slot-log format version this run is written in: 1 for a built-in policy on an
        i.i.d. channel (readable by every corraoi), 2 when the log names a plug-in or a
        non-i.i.d. channel (older readers refuse it instead of misreading it), 3 for a loop
        logged by ``corraoi.Logger`` (policy tier ``external``), whose messages may lack any
        field of the slot record that may be absent, 4 for a run of several sources (a
        channel per source: an older reader refuses it instead of reading one source)."""
        assert self.channel is not None
        if self.sources > 1:
            return 4
        if self.policy.tier == "external":
            return 3
        return 1 if self.policy.builtin and self.channel.iid and self.streams == "cpu" else 2

    @property
    def scored(self) -> bool:
        """Its blocks carry ``score`` and ``forced``: a compiled policy's run, on the CPU
        engine or captured from a GPU sweep's kernel (a plain-Python policy's only when its
        ``select`` returns them)."""
        return bool(self.score) and self.policy.tier == "compiled"

    @property
    def label(self) -> str:
        gpu = "" if self.streams == "cpu" else "-gpu"
        many = "" if self.sources == 1 else f"-m{self.sources}"
        return f"{self.policy.name}-{self.instance_name}{many}-s{self.seed}{gpu}"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = (
            {"arms": self.K} if self.instance is None else {"instance": self.instance.to_dict()}
        )
        out |= {
            "policy": self.policy.to_dict(),
            "seed": int(self.seed),
            "horizon": int(self.horizon),
            "version": self.version,
        }
        assert self.channel is not None
        if not self.channel.iid:
            out["channel"] = self.channel.to_dict()
        if self.streams != "cpu":  # logs of the CPU engine read as before
            out["streams"] = self.streams
        if self.score != (self.K <= SCORE_ARMS):  # the default is not written
            out["score"] = bool(self.score)
        if self.sources != 1:  # a single source's log reads as before
            out["sources"] = self.sources
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunConfig:
        return cls(
            instance=Instance.from_dict(data["instance"], where="run configuration")
            if "instance" in data or "arms" not in data
            else None,
            policy=PolicySpec.from_dict(data["policy"]),
            seed=int(data["seed"]),
            horizon=int(data["horizon"]),
            version=str(data.get("version", "unknown")),
            channel=Channel.from_dict(data["channel"]) if "channel" in data else Channel(),
            streams=str(data.get("streams", "cpu")),
            score=bool(data["score"]) if "score" in data else None,
            arms=data["arms"] if "instance" not in data and "arms" in data else None,
            sources=data.get("sources", 1),
        )


@dataclass
class Columns:
    """The per-slot columns (:mod:`corraoi.engine.slot_record`) of consecutive slots ``t``
    (1-based, (B,)).

    ``mu_hat`` and ``pulls`` are after the slot's update; ``candidates`` is the set the arm
    was chosen from (A_t + {k_emp} for the correlated policies, every arm otherwise);
    ``override`` says that the AoI-aware rule chose the arm; ``regret`` is the pathwise
    regret sum(aoi - oracle_aoi) up to the slot; ``estimator`` the paper's
    sum(aoi) - t / mu*. The fields a run may lack (``score``, ``forced``,
    ``override_threshold``) are None when it does; ``extra`` holds the per-slot fields of a
    log written by a newer corraoi that this one does not know, by name. :class:`SlotBlock`
    holds one run, ``engine.RunsBlock`` many: the two are distinct types so that a
    many-run block cannot be handed to a sink.
    """

    t: np.ndarray
    x: np.ndarray
    arm: np.ndarray
    success: np.ndarray
    aoi: np.ndarray
    oracle_aoi: np.ndarray
    regret: np.ndarray
    estimator: np.ndarray
    override: np.ndarray
    mu_hat: np.ndarray
    pulls: np.ndarray
    candidates: np.ndarray
    forced: np.ndarray | None = None
    collided: np.ndarray | None = None
    override_threshold: np.ndarray | None = None
    score: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    #: the fields of :data:`FIELDS` its run lacks (held as :func:`absent_column`'s fill)
    absent: tuple[str, ...] = ()

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def column(self, name: str) -> np.ndarray:
        value: np.ndarray = getattr(self, name) if name in BY_NAME else self.extra[name]
        return value

    def fields(self) -> tuple[str, ...]:
        """The declared fields this block holds, in log order: not those its run lacks (None,
        or a column of FIELDS named in ``absent``)."""
        if self.absent:
            return tuple(f for f in NAMES if getattr(self, f) is not None and f not in self.absent)
        return tuple(f for f in NAMES if getattr(self, f) is not None)

    def _parts(self, pick: Any) -> dict[str, Any]:
        out: dict[str, Any] = {f: pick(f) for f in (*self.fields(), *self.absent)}
        out["extra"] = {k: pick(k) for k in self.extra}
        out["absent"] = self.absent
        return out


@dataclass
class SlotBlock(Columns):
    """Consecutive slots of one run. Shapes: (B,) per slot, (B, K) per slot and arm."""

    @classmethod
    def concat(cls, blocks: list[SlotBlock]) -> SlotBlock:
        """The blocks joined; a field some of them lack is filled in them (absent_fill)."""
        if not blocks:
            raise ValueError("no blocks to concatenate")
        # a field of FIELDS is an array in every block (held, or filled as absent); another
        # is None in a block that lacks it
        names = [f for f in NAMES if f in FIELDS or any(getattr(b, f) is not None for b in blocks)]
        extra = list(dict.fromkeys(k for b in blocks for k in b.extra))
        out: dict[str, Any] = {f: np.concatenate([absent_fill(b, f) for b in blocks])
                               for f in names}  # fmt: skip
        out["extra"] = {k: np.concatenate([absent_fill(b, k) for b in blocks]) for k in extra}
        out["absent"] = tuple(f for f in FIELDS if all(f in b.absent for b in blocks))
        return cls(**out)

    def slice(self, start: int | None, stop: int | None) -> SlotBlock:
        """Slots ``start:stop`` of the block (views), every field it carries."""
        return SlotBlock(**self._parts(lambda f: self.column(f)[start:stop]))

    def equals(self, other: SlotBlock) -> bool:
        """The same slots with the same fields (two empty blocks: the same arms)."""
        if not len(self) and not len(other):
            return self.mu_hat.shape == other.mu_hat.shape
        if self.fields() != other.fields() or set(self.extra) != set(other.extra):
            return False
        return all(
            np.array_equal(self.column(f), other.column(f), equal_nan=self.column(f).dtype.kind
                           == "f") for f in (*self.fields(), *self.extra)
        )  # fmt: skip


@dataclass
class SourcesBlock:
    """Consecutive slots of one run of M >= 2 sources sharing the channels: one
    :class:`SlotBlock` per source, in source order (source m is ``sources[m - 1]``), each
    holding that source's own fields (its arm, delivery, ``collided``, age, oracle age and
    regret, means, pulls, candidates, scores) and the slot's shared ``t`` and ``x``
    (:data:`~corraoi.engine.slot_record.SHARED`, equal in every source). A source's
    ``oracle_aoi`` is the age on the channel the orthogonal oracle gives it (the m-th best,
    ties by lowest index) and its ``regret`` sum(aoi - oracle_aoi); the run's regret is
    the sum over the sources (docs/model.md, "Many sources")."""

    sources: tuple[SlotBlock, ...]

    def __post_init__(self) -> None:
        if len(self.sources) < 2:
            raise ValueError("a SourcesBlock holds two sources or more")

    @property
    def M(self) -> int:
        """The number of sources."""
        return len(self.sources)

    def __len__(self) -> int:
        return len(self.sources[0])

    @property
    def t(self) -> np.ndarray:
        return self.sources[0].t

    @property
    def x(self) -> np.ndarray:
        return self.sources[0].x

    @classmethod
    def concat(cls, blocks: list[SourcesBlock]) -> SourcesBlock:
        """The blocks joined, source by source."""
        if not blocks:
            raise ValueError("no blocks to concatenate")
        M = blocks[0].M
        return cls(tuple(SlotBlock.concat([b.sources[m] for b in blocks]) for m in range(M)))

    def slice(self, start: int | None, stop: int | None) -> SourcesBlock:
        """Slots ``start:stop`` of every source (views)."""
        return SourcesBlock(tuple(s.slice(start, stop) for s in self.sources))

    def equals(self, other: SourcesBlock) -> bool:
        """The same sources with the same slots and fields."""
        return self.M == other.M and all(
            a.equals(b) for a, b in zip(self.sources, other.sources, strict=True)
        )


#: What a run's sinks are handed: a single source's slots, or a run of several sources'.
RunBlock = SlotBlock | SourcesBlock


def absent_fill(block: Columns, name: str) -> np.ndarray:
    """``block``'s column ``name``, or where it lacks the field the column a table needs:
    NaN for numbers, False for flags (extra fields: None, as objects)."""
    # (a declared field is held where it is not None: in fields(), or in absent as a fill)
    held = getattr(block, name) if name in BY_NAME else block.extra.get(name)
    if held is not None:
        return held
    n = len(block)
    decl = BY_NAME.get(name)
    if decl is None:
        return np.full(n, None, dtype=object)
    K = block.mu_hat.shape[-1]
    shape = (*block.mu_hat.shape[:-1], K) if decl.per_arm else block.aoi.shape
    if decl.dtype == "bool":
        return np.zeros(shape, dtype=bool)
    return np.full(shape, np.nan, dtype=decl.dtype)


def absent_column(name: str, B: int, K: int) -> np.ndarray:
    """What a block holds for a column of :data:`FIELDS` its run lacks: NaN for a number, -1
    for an integer (no state, arm, age or count is -1), False for a flag. Views leave such
    a column out (``SlotBlock.fields()``); the value only keeps a block whole."""
    decl = BY_NAME[name]
    dtype = np.dtype(decl.dtype)
    fill: float | int | bool = np.nan if dtype.kind == "f" else (-1 if dtype.kind == "i" else False)
    return np.full((B, K) if decl.per_arm else (B,), fill, dtype=dtype)


#: The per-slot columns every block carries as arrays, in log order: the fields of the slot
#: record (:mod:`corraoi.engine.slot_record`) the :class:`Columns` dataclass requires. A
#: run may lack one of them too (a field that ``may_be_absent``: a ``corraoi.Logger`` log
#: without the hidden state); its blocks then hold :func:`absent_column` and name it in
#: ``absent``. The other fields are None in a block of a run that lacks them.
_REQUIRED_ARGS = {d.name for d in dataclasses.fields(Columns) if d.default is dataclasses.MISSING
                  and d.default_factory is dataclasses.MISSING}  # fmt: skip
FIELDS: tuple[str, ...] = tuple(f for f in NAMES if f in _REQUIRED_ARGS)
#: The fields a block holds as None when its run lacks them (``score``, ``forced``, ...).
NONE_FIELDS: tuple[str, ...] = tuple(f for f in NAMES if f not in FIELDS)
SCALAR_FIELDS = tuple(f for f in FIELDS if f != "t" and not BY_NAME[f].per_arm)
ARM_FIELDS = tuple(f for f in FIELDS if BY_NAME[f].per_arm)
assert set(REQUIRED) <= set(FIELDS)


#: The kernel's narrower buffers of these fields (the block's columns are int64).
_BUFFER_DTYPES = {"x": "int32", "arm": "int32"}
#: Fields the engine derives after a kernel call rather than buffers in it.
_DERIVED = ("t", "estimator")
#: The fields the engine buffers per slot, in the order the kernel takes them (a single
#: source's: not ``collided``).
BUFFERED = tuple(f for f in NAMES if f not in _DERIVED and not BY_NAME[f].sources_only)


class Outputs:
    """The per-slot output buffers of one advance of R runs by B slots (B = 0 when not
    recording), one per :data:`BUFFERED` field, shaped and typed by the slot record:
    ``(R, B)`` or ``(R, B, K)``."""

    def __init__(self, R: int, B: int, K: int) -> None:
        self.columns: dict[str, np.ndarray] = {
            f: np.empty((R, B, K) if BY_NAME[f].per_arm else (R, B),
                        dtype=_BUFFER_DTYPES.get(f, BY_NAME[f].dtype))
            for f in BUFFERED
        }  # fmt: skip

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def buffers(self) -> tuple[np.ndarray, ...]:
        """The buffers in the kernel's argument order."""
        return tuple(self.columns.values())

    def trim(self, done: int) -> None:
        """Keep the first ``done`` slots (a plug-in failed after them)."""
        for name, value in self.columns.items():
            self.columns[name] = value[:, :done]
