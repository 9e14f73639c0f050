"""The slot-block record: what the engine yields and what every sink and reader speaks.

Arrays use 0-based arm and state indices; files and people see them from 1 (the sinks add 1,
the reader subtracts it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi._version import __version__
from corraoi.errors import ConfigError
from corraoi.limits import check_horizon, check_seed
from corraoi.model.channels import Channel, default_channel
from corraoi.model.instance import Instance
from corraoi.policies.spec import PolicySpec

#: Per-slot columns of a block, in log order.
SCALAR_FIELDS = ("x", "arm", "success", "aoi", "oracle_aoi", "regret", "estimator", "override")
ARM_FIELDS = ("mu_hat", "pulls", "candidates")
FIELDS = ("t",) + SCALAR_FIELDS + ARM_FIELDS
#: The columns every log holds; a log written from another simulator or a testbed
#: (``corraoi.Logger``) may leave any other column of :data:`FIELDS` absent
#: (:attr:`RunConfig.absent`).
ALWAYS_FIELDS = ("t", "arm", "success", "aoi")


#: The values of :attr:`RunConfig.streams`.
STREAMS = ("cpu", "gpu-cuda", "gpu-emulated")


@dataclass(frozen=True)
class RunConfig:
    """Everything that determines a run: with it, a log replays with nothing else."""

    instance: Instance
    policy: PolicySpec
    seed: int
    horizon: int
    version: str = __version__
    channel: Channel | None = None
    #: whose random streams and rule decide the slots: "cpu" (the engine's), "gpu-cuda" or
    #: "gpu-emulated" (the GPU kernel's, captured on a CUDA device or on the host compiler:
    #: a run of a GPU sweep recorded again, corraoi.gpu.runner.capture_run)
    streams: str = "cpu"
    #: the per-slot columns the log does not hold (a run logged by ``corraoi.Logger`` from a
    #: loop that did not give them), in :data:`FIELDS` order; never one of ALWAYS_FIELDS
    absent: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        check_horizon(self.horizon)
        check_seed(self.seed)
        if self.streams not in STREAMS:
            raise ConfigError(f"streams {self.streams!r}: expected one of {', '.join(STREAMS)}")
        absent = set(self.absent)
        wrong = sorted(absent - set(FIELDS) | absent & set(ALWAYS_FIELDS))
        if wrong:
            raise ConfigError(
                f"absent fields {wrong}: expected fields of the slot record other than "
                f"{', '.join(ALWAYS_FIELDS)}"
            )
        object.__setattr__(self, "absent", tuple(f for f in FIELDS if f in absent))
        if self.channel is None:
            object.__setattr__(self, "channel", default_channel(self.instance))

    @property
    def format_version(self) -> int:
        """The slot-log format version this run is written in: 1 for a built-in policy on an
        i.i.d. channel (readable by every corraoi), 2 when the log names a plug-in or a
        non-i.i.d. channel (older readers refuse it instead of misreading it), 3 when it leaves
        a column absent."""
        assert self.channel is not None
        if self.absent:
            return 3
        return 1 if self.policy.builtin and self.channel.iid and self.streams == "cpu" else 2

    @property
    def label(self) -> str:
        gpu = "" if self.streams == "cpu" else "-gpu"
        return f"{self.policy.name}-{self.instance.name}-s{self.seed}{gpu}"

    def to_dict(self) -> dict[str, Any]:
        out = {
            "instance": self.instance.to_dict(),
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
        if self.absent:
            out["absent"] = list(self.absent)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunConfig:
        return cls(
            instance=Instance.from_dict(data["instance"], where="run configuration"),
            policy=PolicySpec.from_dict(data["policy"]),
            seed=int(data["seed"]),
            horizon=int(data["horizon"]),
            version=str(data.get("version", "unknown")),
            channel=Channel.from_dict(data["channel"]) if "channel" in data else Channel(),
            streams=str(data.get("streams", "cpu")),
            absent=tuple(str(f) for f in data.get("absent", ())),
        )


@dataclass
class Columns:
    """The per-slot columns (:data:`FIELDS`) of consecutive slots ``t`` (1-based, (B,)).

    ``mu_hat`` and ``pulls`` are after the slot's update; ``candidates`` is the set the arm
    was chosen from (A_t + {k_emp} for the correlated policies, every arm otherwise);
    ``override`` says that the AoI-aware rule chose the arm; ``regret`` is the pathwise
    regret sum(aoi - oracle_aoi) up to the slot; ``estimator`` the paper's
    sum(aoi) - t / mu*. :class:`SlotBlock` holds one run, ``engine.RunsBlock`` many: the
    two are distinct types so that a many-run block cannot be handed to a sink.
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

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def column(self, name: str) -> np.ndarray:
        value: np.ndarray = getattr(self, name)
        return value


@dataclass
class SlotBlock(Columns):
    """Consecutive slots of one run. Shapes: (B,) per slot, (B, K) per slot and arm."""

    @classmethod
    def concat(cls, blocks: list[SlotBlock]) -> SlotBlock:
        if not blocks:
            raise ValueError("no blocks to concatenate")
        return cls(**{f: np.concatenate([b.column(f) for b in blocks]) for f in FIELDS})

    def equals(self, other: SlotBlock) -> bool:
        return all(np.array_equal(self.column(f), other.column(f)) for f in FIELDS)
