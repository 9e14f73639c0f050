"""The runs' random streams from their seeds: :func:`streams_for_seeds`, memoised, for the
engine (a run's states are :func:`corraoi.rng.streams_for_seed`'s)."""

from __future__ import annotations

import numpy as np

from corraoi._signals import raise_if_asked
from corraoi.rng import streams_for_seed

_STREAMS_CACHE: dict[int, tuple[np.ndarray, np.ndarray]] = {}
_STREAMS_CACHE_MAX = 1 << 16


def streams_for_seeds(seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(latent, policy) states of many seeds: ((R, 4), (R, 4)) uint64.

    ``SeedSequence.spawn`` costs about 37 us a seed and every policy of a sweep needs the same
    seeds, so states are memoised (up to 65,536 seeds; the arrays are copied out).
    """
    R = len(seeds)
    lat = np.empty((R, 4), dtype=np.uint64)
    pol = np.empty((R, 4), dtype=np.uint64)
    for i, s in enumerate(seeds):
        if i % 1024 == 1023:
            raise_if_asked()  # 100,000 seeds take seconds: a signal is answered meanwhile
        key = int(s)
        pair = _STREAMS_CACHE.get(key)
        if pair is None:
            pair = streams_for_seed(key)
            if len(_STREAMS_CACHE) < _STREAMS_CACHE_MAX:
                _STREAMS_CACHE[key] = pair
        lat[i], pol[i] = pair
    return lat, pol


__all__ = ["streams_for_seeds"]
