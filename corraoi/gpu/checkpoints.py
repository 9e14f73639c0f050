"""The checkpoints of a policy's runs on a device: the buffers a launch writes every run's
values into, and their reduction over the runs to moments (docs/gpu.md, "Checkpoints").

At each checkpoint slot a launch writes every run's regret and AoI sum (int64) and its pulls
per arm (uint32) into buffers for up to ``cmax`` checkpoints; after the launch they are
reduced on the device, by one of :data:`corraoi.gpu.device.REDUCTIONS`:

* ``kernel`` -- kernel.cu's ``reduce_checkpoints``: one pass over the buffers, no temporary
  arrays, into exact integer sums and sums of squares per checkpoint (128 and 192 bits) that
  stay on the device until the last launch. The host makes the moments of them in Python's
  integers, rounded once (:func:`moments_of_sums`): exact, and the same whatever the launch
  shape or the order of the device's atomics.
* ``arrays`` -- :meth:`corraoi.stats.Moments.of` on the buffers (CuPy's or NumPy's reductions:
  a mean, then the squared deviations, several passes and temporaries a figure), the path of
  the second GPU run, kept to be timed and checked beside the kernel's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from corraoi.stats import Moments

from .device import Device

#: reduce_checkpoints' flags (kernel.cu, CAI_CK_BASE and CAI_CK_KEEP).
_BASE, _KEEP = 1, 2


def sum_words(K: int) -> int:
    """Words a checkpoint of reduce_checkpoints' sums (kernel.cu, CAI_CKW): per figure
    (regret, AoI sum, paired difference) a 2-word sum and a 3-word sum of squares, then the
    pulls of each arm."""
    return 15 + K


def buffer_bytes(R: int, K: int) -> int:
    """Bytes of one checkpoint's buffers: regret and AoI sum (int64), pulls per arm (uint32)."""
    return R * (16 + 4 * K)


def reduce_checkpoints(dev: Device, family: str, reg: Any, asum: Any, pulls: Any, *,
                       nck: int, out: Any, base: Any = None, kept: Any = None) -> None:  # fmt: skip
    """Add the sums over the runs of the first ``nck`` checkpoints of the buffers ``reg``,
    ``asum`` (nck.., R) int64 and ``pulls`` (nck.., K, R) uint32 into ``out`` (nck.., words)
    uint64 (zeroed by the caller), with the sums of ``reg - base`` (int64, a baseline's
    regret at the same checkpoints) and copying ``reg`` into ``kept`` where given; device
    arrays, each C-contiguous from its first checkpoint on."""
    R, K = int(reg.shape[1]), int(pulls.shape[1])
    none = dev.xp.zeros(1, dtype=np.int64)
    flags = (_BASE if base is not None else 0) | (_KEEP if kept is not None else 0)
    args = [("i", R), ("i", int(nck)), ("p", reg), ("p", asum), ("p", pulls),
            ("p", none if base is None else base), ("p", none if kept is None else kept),
            ("i", flags), ("p", out)]  # fmt: skip
    dev.reduce(K, family, int(nck), R, args)


def _signed(lo: int, hi: int) -> int:
    v = lo | hi << 64
    return v - (1 << 128) if v >> 127 else v


def moments_of_sums(words: np.ndarray, n: int) -> tuple[Moments, Moments, Moments, np.ndarray]:
    """The moments over ``n`` runs that reduce_checkpoints' sums (S, words) give: of the
    regret, of the AoI sum, of the paired difference (zero without a baseline), and the pulls
    summed per arm (S, K) int64. Mean s1 / n and M2 = (n s2 - s1^2) / n in exact integers,
    each rounded once to float64."""
    rows = np.asarray(words, dtype=np.uint64).tolist()
    out = []
    for q in (0, 5, 10):
        s1 = [_signed(r[q], r[q + 1]) for r in rows]
        s2 = [r[q + 2] | r[q + 3] << 64 | r[q + 4] << 128 for r in rows]
        out.append(Moments(n, np.array([s / n for s in s1], dtype=np.float64),
                           np.array([(n * q2 - s * s) / n for s, q2 in zip(s1, s2, strict=True)],
                                    dtype=np.float64)))  # fmt: skip
    pulls = np.asarray(words, dtype=np.uint64)[:, 15:].astype(np.int64)
    return out[0], out[1], out[2], pulls


class Checkpoints:
    """The checkpoint buffers of ``R`` runs of a K-arm policy (``family``'s module) on
    ``dev``, for ``S`` checkpoints, ``cmax`` of them between two reductions, and what the
    reductions have gathered so far (on the device). ``baseline``: the (S, R) int64 regret of
    another policy's runs on the same seeds (paired moments); ``keep``: keep this policy's
    regret at every checkpoint (to be a baseline: :attr:`kept`)."""

    def __init__(self, dev: Device, family: str, *, R: int, K: int, S: int, cmax: int,
                 baseline: Any = None, keep: bool = False) -> None:  # fmt: skip
        xp = dev.xp
        self.dev, self.family, self.R, self.K = dev, family, R, K
        self.baseline = baseline
        self.reg = xp.zeros((cmax, R), dtype=np.int64)
        self.asum = xp.zeros((cmax, R), dtype=np.int64)
        self.pulls = xp.zeros((cmax, K, R), dtype=np.uint32)
        self.kept = xp.zeros((S, R), dtype=np.int64) if keep else None
        self.sums = xp.zeros((S, sum_words(K)), dtype=np.uint64) if dev.reduction == "kernel" \
            else None  # fmt: skip
        self._parts: dict[str, list[Any]] = {"regret": [], "asum": [], "paired": [], "pulls": []}

    def reduce(self, ci: int, nck: int) -> None:
        """Reduce the buffers' first ``nck`` checkpoints, the checkpoints ci .. ci + nck - 1."""
        base = None if self.baseline is None else self.baseline[ci:]
        if self.sums is not None:
            reduce_checkpoints(self.dev, self.family, self.reg, self.asum, self.pulls, nck=nck,
                               out=self.sums[ci:], base=base,
                               kept=None if self.kept is None else self.kept[ci:])  # fmt: skip
            return
        reg, parts = self.reg[:nck], self._parts
        parts["regret"].append(Moments.of(reg, axis=1, host=None))
        parts["asum"].append(Moments.of(self.asum[:nck], axis=1, host=None))
        parts["pulls"].append(self.pulls[:nck].sum(axis=2, dtype=np.int64))
        if base is not None:
            parts["paired"].append(Moments.of(reg - base[:nck], axis=1, host=None))
        if self.kept is not None:
            self.kept[ci : ci + nck] = reg

    def moments(self) -> tuple[Moments, Moments, Moments | None, np.ndarray]:
        """On the host: the moments of the regret, of the AoI sum and of the paired difference
        (None without a baseline) at every checkpoint, and the pulls summed per arm (S, K)."""
        host, xp = self.dev.asnumpy, self.dev.xp
        if self.sums is not None:
            regret, asum, paired, pulls = moments_of_sums(host(self.sums), self.R)
            return regret, asum, paired if self.baseline is not None else None, pulls

        def joined(parts: list[Moments]) -> Moments:
            return Moments(parts[0].n, np.asarray(host(xp.concatenate([p.mean for p in parts]))),
                           np.asarray(host(xp.concatenate([p.m2 for p in parts]))))  # fmt: skip

        parts = self._parts
        return (joined(parts["regret"]), joined(parts["asum"]),
                joined(parts["paired"]) if parts["paired"] else None,
                np.asarray(host(xp.concatenate(parts["pulls"])), dtype=np.int64))  # fmt: skip
