"""The slot blocks of one run (a :class:`corraoi.engine.block.RunConfig`): what every sink of a
recorded run is fed. A CPU run comes from the engine; a run of a GPU sweep
(``config.streams``) from the GPU kernel's own streams, captured slot by slot."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from corraoi.engine.simulation import simulate_run


def slots_of(config: Any) -> Any:
    """The slot blocks of one run: the CPU engine's, or for a run of a GPU sweep
    (``config.streams``) the GPU kernel's own, captured slot by slot."""
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
