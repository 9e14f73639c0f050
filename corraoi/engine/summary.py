"""Summary figures of one run, accumulated block by block (one pass, no recompute): measured
by the recording as the blocks go by, and by the viewer from a log's blocks.

Every figure comes from the slots; nothing is simulated. Arms are 0-based in the
Python objects and numbered from 1 in ``to_dict()`` and in everything printed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi.engine.block import RunConfig, SlotBlock, SourcesBlock


@dataclass(frozen=True)
class RunSummary:
    """The figures ``compare``, ``diff`` and ``info`` print for one run.

    ``settled_at`` is the first slot from which the run played the best arm in every slot
    up to its last recorded slot (``None`` when its last slot was not on the best arm or
    nothing was recorded). ``best_share`` is the share of recorded slots on the best arm.
    A figure whose field the run lacks (``SlotBlock.absent``: a log written by
    ``corraoi.Logger`` without the hidden state, say) is None; so are the best arm and
    what depends on it for a run without an instance.

    A run of several sources: ``regret`` is the run's, the sum over the sources, and
    ``regret_by_source`` each source's (source m's at [m - 1]); ``pulls`` each channel's
    plays by all the sources; ``collisions`` the (slot, source) pairs that collided;
    ``overrides`` summed; the estimator, the share on the best arm and the slot it settled
    at (figures of one source) are None. A single source's run has neither of the two
    (None, and not in ``to_dict()``).
    """

    slots: int
    best_arm: int | None
    regret: int | None
    estimator: float | None
    pulls: tuple[int, ...]
    best_share: float | None
    overrides: int | None
    settled_at: int | None
    regret_by_source: tuple[int, ...] | None = None
    collisions: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready figures; arms numbered from 1."""
        several: dict[str, Any] = {}
        if self.regret_by_source is not None:
            several = {"regret_by_source": list(self.regret_by_source),
                       "collisions": self.collisions}  # fmt: skip
        return {
            "slots": self.slots,
            "best_arm": None if self.best_arm is None else self.best_arm + 1,
            "regret": self.regret,
            "estimator": self.estimator,
            "pulls": list(self.pulls),
            "best_share": self.best_share,
            "overrides": self.overrides,
            "settled_at": self.settled_at,
            **several,
        }


class SummaryAccumulator:
    """Feed it the blocks of one run in slot order; ``result()`` gives the RunSummary."""

    def __init__(self, config: RunConfig) -> None:
        self.K = config.K
        theory = config.theory  # None for a run without an instance: no best arm
        self.best_arm: int | None = None if theory is None else theory.best_arm
        #: the fields the run lacks, as its blocks say
        self.absent: tuple[str, ...] = ()
        self.slots = 0
        self.overrides = 0
        self.last_off_best = 0  # last slot whose arm was not the best arm (0: none yet)
        self._last: SlotBlock | None = None
        #: a run of several sources: its last block, and its collisions so far
        self._sources: SourcesBlock | None = None
        self.collisions = 0

    def update(self, block: SlotBlock | SourcesBlock) -> None:
        n = len(block)
        if n == 0:
            return
        if isinstance(block, SourcesBlock):
            self.slots = int(block.t[-1])
            for part in block.sources:
                self.overrides += int(np.count_nonzero(part.override))
                if part.collided is not None:
                    self.collisions += int(np.count_nonzero(part.collided))
            self._sources = block
            self.absent = block.sources[0].absent
            return
        self.slots = int(block.t[-1])
        self.overrides += int(np.count_nonzero(block.override))
        if self.best_arm is not None:
            off = np.flatnonzero(block.arm != self.best_arm)
            if off.size:
                self.last_off_best = int(block.t[off[-1]])
        self._last = block
        self.absent = block.absent

    def result(self) -> RunSummary:
        if self._sources is not None:
            return self._several(self._sources)
        last = self._last
        if last is None:
            return RunSummary(
                slots=0,
                best_arm=self.best_arm,
                regret=None,
                estimator=None,
                pulls=(0,) * self.K,
                best_share=None,
                overrides=None if "override" in self.absent else 0,
                settled_at=None,
            )
        pulls = tuple(int(v) for v in last.pulls[-1])
        settled = self.last_off_best + 1 if self.last_off_best < self.slots else None
        best = self.best_arm
        return RunSummary(
            slots=self.slots,
            best_arm=self.best_arm,
            regret=None if "regret" in self.absent else int(last.regret[-1]),
            estimator=None if "estimator" in self.absent else float(last.estimator[-1]),
            pulls=pulls,
            best_share=None if best is None else pulls[best] / self.slots,
            overrides=None if "override" in self.absent else self.overrides,
            settled_at=None if best is None else settled,
        )

    def _several(self, last: SourcesBlock) -> RunSummary:
        """The figures of a run of several sources (see :class:`RunSummary`)."""
        each = None if "regret" in self.absent else tuple(
            int(s.regret[-1]) for s in last.sources)  # fmt: skip
        pulls = np.sum([s.pulls[-1] for s in last.sources], axis=0)
        return RunSummary(
            slots=self.slots,
            best_arm=self.best_arm,
            regret=None if each is None else sum(each),
            estimator=None,
            pulls=tuple(int(v) for v in pulls),
            best_share=None,
            overrides=None if "override" in self.absent else self.overrides,
            settled_at=None,
            regret_by_source=each,
            collisions=self.collisions,
        )


def summarize_blocks(config: RunConfig, blocks: Any) -> RunSummary:
    """The RunSummary of an iterable of SlotBlocks of the run described by ``config``."""
    acc = SummaryAccumulator(config)
    for b in blocks:
        acc.update(b)
    return acc.result()
