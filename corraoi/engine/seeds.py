"""The runs' random streams from their seeds: :func:`streams_for_seeds`, for the engine.

A run's states are :func:`corraoi.rng.streams_for_seed`'s, that is NumPy's
``SFC64(SeedSequence(seed).spawn(2)[i])``, bit for bit (tests/test_engine.py checks it). NumPy
builds them one seed at a time (about 37 us a seed: seconds for a chunk of 100,000 runs);
here the same arithmetic runs on every seed at once, as arrays: NumPy's ``SeedSequence``
(``numpy/random/bit_generator.pyx``: its pool of four 32-bit words, ``hashmix``, ``mix`` and
``generate_state``) and ``SFC64``'s seeding (``sfc64_set_seed``: three words of
``generate_state(3, uint64)``, a counter of 1, twelve steps).
"""

from __future__ import annotations

import numpy as np

from corraoi.errors import ConfigError
from corraoi.rng import streams_for_seed

# NumPy's SeedSequence constants (bit_generator.pyx), all 32-bit arithmetic
_POOL = 4
_INIT_A, _MULT_A = 0x43B0D7E5, 0x931E8875
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED
_MIX_L, _MIX_R = np.uint32(0xCA01F9DD), np.uint32(0x4973F715)
_X16 = np.uint32(16)
_M32 = 0xFFFFFFFF


def _hash_consts(init: int, mult: int, count: int) -> list[np.uint32]:
    """The multipliers ``hashmix`` (or ``generate_state``) uses on its calls 1..count: the
    running constant is multiplied by ``mult`` on every call, whatever the data."""
    out, h = [], init
    for _ in range(count):
        h = (h * mult) & _M32
        out.append(np.uint32(h))
    return out


# ``mix_entropy`` calls hashmix 4 + 12 + 4 times for a pool of 4 and one spawn-key word
_HASH_A = _hash_consts(_INIT_A, _MULT_A, _POOL + _POOL * (_POOL - 1) + _POOL)
_XOR_A = [np.uint32(_INIT_A)] + _HASH_A[:-1]  # the constant before each call's multiply
_HASH_B = _hash_consts(_INIT_B, _MULT_B, 6)  # generate_state(3, uint64): six 32-bit words
_XOR_B = [np.uint32(_INIT_B)] + _HASH_B[:-1]


def _hashmix(value: np.ndarray, call: int) -> np.ndarray:
    """``hashmix`` of ``value`` on ``mix_entropy``'s call number ``call`` (from 0)."""
    v = (value ^ _XOR_A[call]) * _HASH_A[call]
    return v ^ (v >> _X16)


def _mix(x: np.ndarray, y: np.ndarray | np.uint32) -> np.ndarray:
    r = _MIX_L * x - _MIX_R * y
    return r ^ (r >> _X16)


def _pools(seeds: np.ndarray) -> list[np.ndarray]:
    """The mixed entropy pools of ``SeedSequence(seed).spawn(2)``'s two children: four
    (2, R) uint32 arrays, row 0 the latent child's, row 1 the policy child's.

    A child's entropy is the seed's 32-bit words padded to the pool's size (4) followed by
    its spawn key (0 or 1), so every seed below 2**128 has the same five words, and the two
    children differ only in the last four calls (the key's, the same for every seed).
    """
    with np.errstate(over="ignore"):
        low = (seeds & _M32).astype(np.uint32)
        high = (seeds >> 32).astype(np.uint32)
        zero = np.zeros_like(low)
        mixer = [_hashmix(w, i) for i, w in enumerate((low, high, zero, zero))]
        call = _POOL
        for src in range(_POOL):
            for dst in range(_POOL):
                if src != dst:
                    mixer[dst] = _mix(mixer[dst], _hashmix(mixer[src], call))
                    call += 1
        keys = np.array([[0], [1]], dtype=np.uint32)  # the spawn keys, one row per child
        return [_mix(mixer[dst], _hashmix(keys, call + dst)) for dst in range(_POOL)]


def _sfc64_states(pool: list[np.ndarray]) -> np.ndarray:
    """``SFC64(seed_sequence).state`` of every child and seed from its mixed pool:
    (2, R, 4) uint64."""
    with np.errstate(over="ignore"):
        words = []
        for i in range(6):  # generate_state(3, uint64) cycles through the pool
            v = (pool[i % _POOL] ^ _XOR_B[i]) * _HASH_B[i]
            words.append((v ^ (v >> _X16)).astype(np.uint64))
        # pairs of 32-bit words, low first, as NumPy's view of them on a little-endian machine
        a, b, c = (words[i] | (words[i + 1] << np.uint64(32)) for i in (0, 2, 4))
        w = np.ones_like(a)
        for _ in range(12):  # sfc64_set_seed: a counter of 1, then twelve steps
            tmp = a + b + w
            w = w + np.uint64(1)
            a = b ^ (b >> np.uint64(11))
            b = c + (c << np.uint64(3))
            c = ((c << np.uint64(24)) | (c >> np.uint64(40))) + tmp
    return np.stack([a, b, c, w], axis=-1)


#: Below this many seeds NumPy's own SeedSequence, seed by seed, is the quicker (the arrays'
#: arithmetic costs a few hundred microseconds whatever their length).
_FEW = 8


def streams_for_seeds(seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(latent, policy) states of many seeds (integers in [0, 2**64)): ((R, 4), (R, 4))
    uint64, those of :func:`corraoi.rng.streams_for_seed` seed by seed."""
    arr = np.asarray(seeds).ravel()
    if arr.dtype.kind not in "iu" or (arr.size and arr.min() < 0):
        raise ConfigError(f"seeds: non-negative integers expected, got {arr.dtype} "
                          f"{arr[:3].tolist()}...")  # fmt: skip
    if arr.size < _FEW:
        pairs = [streams_for_seed(int(s)) for s in arr]
        lat = np.array([p[0] for p in pairs], dtype=np.uint64).reshape(arr.size, 4)
        pol = np.array([p[1] for p in pairs], dtype=np.uint64).reshape(arr.size, 4)
        return lat, pol
    states = _sfc64_states(_pools(arr.astype(np.uint64)))
    return np.ascontiguousarray(states[0]), np.ascontiguousarray(states[1])


__all__ = ["streams_for_seeds"]
