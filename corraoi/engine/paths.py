"""The hidden path alone: the states a run of seed ``s`` sees, drawn block by block as the
engine draws them (the same latent stream, the same compiled draw), without a policy.

What an environment that lets another program choose the arms needs
(:mod:`corraoi.gym`): its run on seed ``s`` is paired with every built-in policy's run of
seed ``s`` on the same instance and channel.
"""

from __future__ import annotations

import numpy as np

from corraoi.limits import check_horizon, check_seed
from corraoi.model.channels import Channel, default_channel
from corraoi.model.instance import Instance

from ._kernel import draw_states
from .seeds import streams_for_seeds


class HiddenPaths:
    """The hidden paths of the runs of ``seeds`` on ``instance`` and ``channel``, each
    drawn from slot 1 on, ``draw(n)`` slots at a time: memory grows with ``n``, never with
    the horizon."""

    def __init__(
        self,
        instance: Instance,
        seeds: np.ndarray | list[int],
        *,
        channel: Channel | None = None,
        horizon: int | None = None,
    ) -> None:
        chan = channel if channel is not None else default_channel(instance)
        if horizon is not None:
            check_horizon(horizon)
            chan.check(instance, int(horizon))
        seed_arr = np.asarray(seeds, dtype=np.int64).reshape(-1)
        for s in seed_arr.tolist():
            check_seed(s, name="seed")
        cdf_rows, kind, trace = chan.kernel_arrays(instance)
        self._cdf_rows = np.ascontiguousarray(cdf_rows, dtype=np.float64)
        self._kind = int(kind)
        self._trace = np.ascontiguousarray(trace, dtype=np.int64)
        self._lat, _ = streams_for_seeds(seed_arr)
        self._xprev = np.full(seed_arr.size, -1, dtype=np.int64)
        #: slots drawn so far
        self.t = 0

    @property
    def runs(self) -> int:
        return int(self._xprev.size)

    def draw(self, n: int) -> np.ndarray:
        """The 0-based hidden states of the next ``n`` slots of every run: (runs, n) int64."""
        out = np.empty((self.runs, int(n)), dtype=np.int64)
        if n > 0:
            draw_states(self._cdf_rows, self._kind, self._trace, self._lat, self._xprev,
                        self.t, int(n), out)  # fmt: skip
            self.t += int(n)
        return out


__all__ = ["HiddenPaths"]
