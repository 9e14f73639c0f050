"""The slot blocks of one run (a :class:`corraoi.engine.block.RunConfig`): what every sink of a
recorded run is fed. A CPU run comes from the engine (a run of several sources, its
:class:`~corraoi.engine.block.SourcesBlock` s); a run of a GPU sweep (``config.streams``)
from the GPU kernel's own streams, captured slot by slot."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from typing import TYPE_CHECKING

from corraoi.engine.block import SourcesBlock
from corraoi.engine.simulation import simulate_run

if TYPE_CHECKING:
    from corraoi.engine.block import RunBlock, RunConfig


def slots_of(config: RunConfig) -> Iterator[RunBlock]:
    """The slot blocks of one run: the CPU engine's, or for a run of a GPU sweep
    (``config.streams``) the GPU kernel's own, captured slot by slot. A run of several
    sources (``config.sources`` > 1) gives SourcesBlocks."""
    if config.sources > 1:
        from corraoi.engine.sources import (  # type: ignore[import-not-found, unused-ignore]
            simulate_run_sources,
        )

        many: Iterator[SourcesBlock] = simulate_run_sources(
            config.model, config.policy, config.seed, config.horizon, config.sources,
            channel=config.channel)  # fmt: skip
        if not config.score:
            return (SourcesBlock(tuple(replace(s, score=None, forced=None) for s in b.sources))
                    for b in many)  # fmt: skip
        return many
    if config.streams == "cpu":
        blocks = simulate_run(config.model, config.policy, config.seed, config.horizon,
                              channel=config.channel)  # fmt: skip
    else:
        from corraoi.gpu.device import device_of
        from corraoi.gpu.runner import capture_run

        device = device_of("emulate" if config.streams == "gpu-emulated" else "cuda")
        blocks = capture_run(config.model, config.policy, seed=config.seed,
                             horizon=config.horizon, channel=config.channel,
                             device=device)  # fmt: skip
    if not config.score:  # the scores left out (RunConfig.score), on either engine
        return (replace(b, score=None, forced=None) for b in blocks)
    return blocks
