"""Simulating runs on a device (:mod:`corraoi.gpu.device`): one policy's runs, with their seeds.

A policy's runs advance launch by launch; each launch captures every run's regret, AoI sum
and pulls at the checkpoints it passes into device buffers, which are reduced on the device
(kernel.cu's ``reduce_checkpoints``: exact integer sums and sums of squares, one pass) and
become :class:`corraoi.stats.Moments` (count, mean, sum of squared deviations) of the regret
and the estimator and, with a baseline, of the run-by-run difference against it. What comes
back to the host: those sums per checkpoint and every run's final values -- never every
run's checkpoints (a million runs x 200 checkpoints would be gigabytes). The sums stay on the
device until the last launch, and the host keeps the next launch queued while it waits for
one (``Device.in_flight``), so that the device never waits for the host between launches.
``Device.reduction = "arrays"`` reduces with the array module instead (``Moments.of`` on
CuPy arrays, the path of the second GPU run), to be timed and checked beside it.
"""

from __future__ import annotations

import bisect
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi.engine.block import SlotBlock
from corraoi.engine.problem import Problem
from corraoi.engine.slot_record import GPU_CAPTURE_PER_ARM, GPU_CAPTURE_ROW
from corraoi.errors import ConfigError, GpuUnavailable
from corraoi.model.candidates import candidate_bitsets
from corraoi.model.channels import Channel
from corraoi.model.instance import Instance
from corraoi.policies import PolicySpec, gpu_form
from corraoi.stats import Moments

from .checkpoints import Checkpoints, buffer_bytes
from .device import MAX_ARMS, Device, entry_name, entry_names, get_device


@dataclass
class DeviceRun:
    """What a device returns for the runs of one policy."""

    t: np.ndarray  # (S,) checkpoint slots, ascending, the last = horizon
    regret: Moments  # of the pathwise regret at each checkpoint
    estimator: Moments  # of the paper's estimator sum(aoi) - t / mu*
    pulls_sum: np.ndarray  # (S, K) int64: pulls per arm summed over the runs
    paired: Moments | None  # of regret - the baseline's regret, run by run
    regret_final: np.ndarray  # (R,) float64 at the horizon
    estimator_final: np.ndarray  # (R,) float64
    best_pulls_final: np.ndarray  # (R,) int64
    kept: Any  # (S, R) int64 device array: the regret at every checkpoint (keep=True), or None
    wall_s: float


def gpu_problem(policy: PolicySpec, K: int) -> str | None:
    """Why ``policy`` cannot run on the GPU backend with K arms, or None when it can."""
    cls = policy.resolve()
    form = gpu_form(cls)
    entry = None if form is None else entry_name(form.kernel, getattr(cls, "correlated", False),
                                                 getattr(cls, "aoi_aware", False))  # fmt: skip
    if entry is None or entry not in entry_names():
        kind = "a plain-Python policy" if cls.tier == "python" else "no GPU form"
        return f"policy {policy.name} has {kind} (the GPU backend runs the built-ins)"
    if K > MAX_ARMS:
        return f"K = {K} arms: the GPU backend holds at most {MAX_ARMS} arms per run"
    return None


def hidden_table(cdf_rows: np.ndarray) -> np.ndarray:
    """The kernel's CDF rows (kernel.cu, cai_hidden): per row, h then three unused words,
    then thr_i = ceil(cdf_i 2^32) for the h first states i < n - 1 with thr_i < 2^32, padded
    with 2^32 - 1 to a multiple of four words, as uint32. For a 32-bit word w (the uniform
    w / 2^32), ``w >= thr_i`` exactly when ``w / 2^32 >= cdf_i``, so the hidden state
    ``min(#{i: w >= thr_i}, h)`` is numpy's ``searchsorted(cdf, w / 2^32, side="right")``
    clipped to n - 1."""
    cdf = np.atleast_2d(np.asarray(cdf_rows, dtype=np.float64))
    rows, n = cdf.shape
    pad = 4 * ((n + 2) // 4)
    out = np.full((rows, 4 + pad), 2**32 - 1, dtype=np.uint64)
    scaled = np.ceil(cdf[:, : n - 1] * 2.0**32)
    below = scaled < 2.0**32
    out[:, 0] = below.sum(axis=1)
    out[:, 1:4] = 0
    out[:, 4 : 4 + n - 1] = np.where(below, np.maximum(scaled, 0.0), 2**32 - 1)
    return np.ascontiguousarray(out.astype(np.uint32))


def reward_masks(Y: np.ndarray) -> np.ndarray:
    """(n,) uint64: bit k of entry x is Y[k][x] (the arms that succeed in state x)."""
    Y = np.asarray(Y)
    bits = np.uint64(1) << np.arange(Y.shape[0], dtype=np.uint64)
    return np.ascontiguousarray(((Y != 0).astype(np.uint64) * bits[:, None]).sum(axis=0,
                                                                            dtype=np.uint64))


class _Problem:
    """A policy's runs on a device, ready to launch: the constants and the per-run state
    (laid out [field][run]) that carries from one launch to the next."""

    def __init__(self, instance: Instance, policy: PolicySpec, horizon: int,
                 channel: Channel | None, runs: int, dev: Device) -> None:  # fmt: skip
        if runs < 1:
            raise ConfigError(f"runs must be >= 1, got {runs}")
        K = instance.K
        problem = gpu_problem(policy, K)
        if problem is not None:
            raise GpuUnavailable(f"--backend gpu: {problem}; run it with --backend cpu")
        pb = Problem.of(instance, policy, horizon, channel)  # every check, once
        cls: Any = pb.cls
        self.cls = cls
        form = gpu_form(cls)
        assert form is not None
        self.family = form.kernel
        self.entry = entry_name(form.kernel, cls.correlated, cls.aoi_aware)
        self.theory = pb.theory
        self.cdf, self.kind = pb.cdf_rows, pb.kind
        self.S_state = pb.state_size if form.uses_state else 0
        self.K, self.R, self.dev = K, int(runs), dev
        xp, R = dev.xp, self.R

        def arr(a: np.ndarray) -> Any:
            return xp.asarray(np.ascontiguousarray(a))

        self.arr = arr
        try:
            self.consts = {
                "thr": arr(hidden_table(pb.cdf_rows)), "trace": arr(pb.trace),
                "ymask": arr(reward_masks(pb.Y)),
                "comb": arr(candidate_bitsets(pb.pclass).reshape(K * 8)),
                "prm": arr(pb.params if pb.params.size else np.zeros(1)),
                "none": xp.zeros(1, dtype=np.int64),
            }  # fmt: skip
            self.st = {
                "pulls": xp.zeros((K, R), dtype=np.int64),
                "succ": xp.zeros((K, R), dtype=np.int64),
                "pstate": xp.zeros((max(self.S_state, 1), R)),
                "xprev": xp.full(R, -1, dtype=np.int32),
                "age": xp.ones(R, dtype=np.int64), "oage": xp.ones(R, dtype=np.int64),
                "reg": xp.zeros(R, dtype=np.int64), "asum": xp.zeros(R, dtype=np.int64),
            }  # fmt: skip
        except Exception as exc:  # CuPy's OutOfMemoryError (no CuPy import needed here)
            raise _memory_error(exc, R, policy) from None

    def launch(self, seed0: int, t: int, nslots: int, *, nck: int = 0, ck_t: Any = None,
               ck_reg: Any = None, ck_asum: Any = None, ck_pulls: Any = None,
               cap_run: int = -1, cap: Any = None) -> None:  # fmt: skip
        """Advance every run from slot ``t`` by ``nslots`` (capturing the checkpoints in
        ``ck_t`` it passes, and every slot of run ``cap_run`` into ``cap``, with the capture
        module: ``capture_width(K)`` values a slot)."""
        c, st, none = self.consts, self.st, self.consts["none"]
        xp = self.dev.xp
        lnt = xp.log(xp.arange(t + 1, t + nslots + 1, dtype=np.float64))  # the same for every run
        args = [
            ("i", self.R), ("Q", int(seed0)), ("q", t), ("q", nslots), ("p", lnt),
            ("i", int(self.cdf.shape[1])), ("i", int(self.cdf.shape[0])), ("i", int(self.kind)),
            ("p", c["thr"]), ("p", c["trace"]), ("p", c["ymask"]), ("p", c["comb"]),
            ("i", int(self.theory.best_arm)), ("p", c["prm"]), ("i", self.S_state),
            *(("p", st[k]) for k in ("pulls", "succ", "pstate", "xprev", "age", "oage", "reg",
                                     "asum")),
            ("i", nck), *(("p", none if a is None else a) for a in (ck_t, ck_reg, ck_asum,
                                                                       ck_pulls)),
            ("i", int(cap_run)), ("p", none if cap is None else cap),
        ]  # fmt: skip
        self.dev.launch(self.K, self.family, self.entry, self.R, args, capture=cap is not None)


def simulate(
    instance: Instance,
    policy: PolicySpec,
    *,
    seed0: int,
    runs: int,
    horizon: int,
    checkpoints: Sequence[int] = (),
    channel: Channel | None = None,
    baseline: Any = None,
    keep: bool = False,
    on_slots: Callable[[int], None] | None = None,
    device: Device | None = None,
) -> DeviceRun:
    """Runs ``seed0 .. seed0 + runs - 1`` of ``policy`` to ``horizon`` on the device.

    ``baseline``: the ``kept`` array of another policy's runs on the same seeds and
    checkpoints (the paired moments are computed against it); ``keep``: keep this policy's
    regret at every checkpoint on the device (to be a baseline).
    """
    start = time.perf_counter()
    dev = device if device is not None else get_device()
    prob = _Problem(instance, policy, horizon, channel, runs, dev)
    K, R, theory = prob.K, prob.R, prob.theory
    stops = sorted({int(c) for c in checkpoints if 0 < c <= horizon} | {int(horizon)})
    S = len(stops)
    cmax = max(1, min(S, dev.checkpoint_bytes // buffer_bytes(R, K)))
    if baseline is not None and (tuple(baseline.shape) != (S, R) or baseline.dtype != np.int64):
        raise ConfigError(f"baseline of shape {tuple(baseline.shape)} and type {baseline.dtype}, "
                          f"expected {(S, R)} int64 (the kept regret of another policy's runs)")
    try:
        ck_t = prob.arr(np.array(stops))
        ck = Checkpoints(dev, prob.family, R=R, K=K, S=S, cmax=cmax, baseline=baseline,
                         keep=keep)  # fmt: skip
    except Exception as exc:  # CuPy's OutOfMemoryError (no CuPy import needed here)
        raise _memory_error(exc, R, policy) from None
    per_launch = max(1, min(dev.launch_work // R, dev.launch_slots))
    queued: deque[tuple[Any, int]] = deque()  # (mark after a launch, its slots)

    def done(pending: int) -> None:  # wait until at most `pending` launches are queued
        while len(queued) > pending:
            mark, slots = queued.popleft()
            dev.wait(mark)
            if on_slots is not None:
                on_slots(slots)

    t = 0
    ci = 0
    while t < horizon:
        end = min(horizon, t + per_launch, stops[min(ci + cmax, S) - 1])
        nck = bisect.bisect_right(stops, end) - ci
        try:
            prob.launch(seed0, t, end - t, nck=nck, ck_t=ck_t[ci:], ck_reg=ck.reg,
                        ck_asum=ck.asum, ck_pulls=ck.pulls)  # fmt: skip
            if nck:
                ck.reduce(ci, nck)
            queued.append((dev.mark(), end - t))
            done(dev.in_flight)
        except Exception as exc:
            raise _memory_error(exc, R, policy) from None
        ci += nck
        t = end
    done(0)
    dev.synchronize()
    st = prob.st
    best = int(theory.best_arm)
    mu_star = float(theory.mu_star)
    regret_final = dev.asnumpy(st["reg"]).astype(np.float64)
    est_final = dev.asnumpy(st["asum"]).astype(np.float64) - horizon / mu_star
    regret, asum, paired, pulls_sum = ck.moments()
    t_arr = np.asarray(stops, dtype=np.int64)
    return DeviceRun(
        t=t_arr, regret=regret, estimator=Moments(asum.n, asum.mean - t_arr / mu_star, asum.m2),
        pulls_sum=pulls_sum, paired=paired, regret_final=regret_final,
        estimator_final=est_final, best_pulls_final=dev.asnumpy(st["pulls"][best]).astype(
            np.int64), kept=ck.kept, wall_s=time.perf_counter() - start,
    )  # fmt: skip


def capture_columns(K: int) -> dict[str, slice]:
    """Where each field of the slot record's capture row (``GPU_CAPTURE_ROW``) lies in the
    K-arm kernel's row (kernel.cu, CAI_CAPW): one value, or K for a per-arm field."""
    out, at = {}, 0
    for name in GPU_CAPTURE_ROW:
        width = K if name in GPU_CAPTURE_PER_ARM else 1
        out[name] = slice(at, at + width)
        at += width
    return out


def capture_width(K: int) -> int:
    """Values the K-arm capture module captures per slot (kernel.cu, CAI_CAPW)."""
    return capture_columns(K)[GPU_CAPTURE_ROW[-1]].stop


def _float32(words: np.ndarray) -> np.ndarray:
    """The float32 values whose bits the kernel wrote in the low words of ``words``."""
    return np.ascontiguousarray(words & 0xFFFFFFFF).astype(np.uint32).view(np.float32)


def capture_run(
    instance: Instance,
    policy: PolicySpec,
    *,
    seed: int,
    horizon: int,
    channel: Channel | None = None,
    block: int = 1000,
    device: Device | None = None,
) -> Iterator[SlotBlock]:
    """The slots of the device's run with seed ``seed`` (run ``seed - grid seed`` of a GPU
    sweep), captured by the kernel as it decides them, as the :class:`SlotBlock` a CPU
    record yields: the GPU's own random streams and rule, slot for slot (on the emulated
    device, the host compiler's arithmetic). With them, why each arm was played, as the CPU
    engine's record gives it: ``score`` (float32, NaN outside the candidates and at a slot
    not scored), ``forced`` and, for an AoI-aware policy, ``override_threshold``; the
    kernel's capture module computes them (CAI_CAPTURE=1), a sweep's never does."""
    dev = device if device is not None else get_device()
    prob = _Problem(instance, policy, horizon, channel, 1, dev)
    K, mu_star = prob.K, float(prob.theory.mu_star)
    aware = bool(getattr(prob.cls, "aoi_aware", False))
    cols, width = capture_columns(K), capture_width(K)
    cap = dev.xp.zeros(block * width, dtype=np.int64)
    pulls = np.zeros(K, dtype=np.int64)
    succ = np.zeros(K, dtype=np.int64)
    bits = np.uint64(1) << np.arange(K, dtype=np.uint64)
    t = 0
    while t < horizon:
        n = min(block, horizon - t)
        prob.launch(seed, t, n, cap_run=0, cap=cap)
        rows = dev.asnumpy(cap)[: n * width].reshape(n, width)
        col = {name: rows[:, at] if name in GPU_CAPTURE_PER_ARM else rows[:, at.start]
               for name, at in cols.items()}  # fmt: skip
        arm = col["arm"]
        success = col["success"] == 1
        hit = np.zeros((n, K), dtype=np.int64)
        hit[np.arange(n), arm] = 1
        p = pulls + np.cumsum(hit, axis=0)
        s = succ + np.cumsum(hit * success[:, None], axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mu_hat = np.where(p > 0, s / np.maximum(p, 1), 0.0)
        ts = np.arange(t + 1, t + n + 1, dtype=np.int64)
        yield SlotBlock(
            t=ts, x=col["x"].copy(), arm=arm.copy(), success=success, aoi=col["aoi"].copy(),
            oracle_aoi=col["oracle_aoi"].copy(), regret=col["regret"].copy(),
            estimator=col["aoisum"] - ts / mu_star, override=col["override"] == 1,
            mu_hat=mu_hat, pulls=p,
            candidates=(col["candidates"][:, None].astype(np.uint64) & bits[None, :]) != 0,
            forced=col["forced"] == 1, score=_float32(col["score"]),
            override_threshold=_float32(col["override_threshold"]) if aware else None,
        )  # fmt: skip
        pulls, succ = p[-1].copy(), s[-1].copy()
        t += n


def _memory_error(exc: Exception, R: int, policy: PolicySpec) -> Exception:
    if "OutOfMemory" in type(exc).__name__:
        return ConfigError(
            f"{policy.name}: {R} runs do not fit in the GPU's memory ({exc}); "
            "split them with --chunk"
        )
    return exc
