"""The slot blocks of one run (a :class:`corraoi.engine.block.RunConfig`): what every sink of a
recorded run is fed. A CPU run comes from the engine; a run of a GPU sweep
(``config.streams``) from the GPU kernel's own streams, captured slot by slot."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace
from typing import TYPE_CHECKING

from corraoi.engine.simulation import simulate_run

if TYPE_CHECKING:
    from corraoi.engine.block import RunConfig, SlotBlock


def slots_of(config: RunConfig) -> Iterator[SlotBlock]:
    """The slot blocks of one run: the CPU engine's, or for a run of a GPU sweep
    (``config.streams``) the GPU kernel's own, captured slot by slot."""
    if config.streams == "cpu":
        blocks = simulate_run(config.model, config.policy, config.seed, config.horizon,
                              channel=config.channel)  # fmt: skip
        if not config.score:  # the scores left out (RunConfig.score)
            return (replace(b, score=None, forced=None) for b in blocks)
        return blocks
    from corraoi.gpu.device import device_of
    from corraoi.gpu.runner import capture_run

    device = device_of("emulate" if config.streams == "gpu-emulated" else "cuda")
    return capture_run(config.model, config.policy, seed=config.seed,
                       horizon=config.horizon, channel=config.channel, device=device)  # fmt: skip
