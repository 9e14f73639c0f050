"""The engine's threads, and the slicing of a compiled kernel call across them.

A kernel call takes the runs of one simulation for some slots. It is cut so that each piece
takes about :data:`PIECE_SECONDS` (Ctrl-C, SIGTERM and SIGHUP are handled between pieces,
issue 19) and, when the work is large enough, its runs are shared among the engine's threads
(both kernels release the GIL). The rate of the previous call sizes the next.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait

import numpy as np

from corraoi._signals import raise_if_asked
from corraoi.errors import ConfigError


def cores() -> int:
    """The cores this process may run on (its CPU affinity), at least 1."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else 1)


#: Threads that share a kernel call's runs (set_workers); every core by default.
_workers = cores()
#: Below this many run-slots a call stays on the calling thread (a thread's start costs more).
_THREAD_MIN_WORK = 200_000
#: A kernel call (one slice of runs, some slots) takes about this long at most, so that
#: Ctrl-C, SIGTERM and SIGHUP are handled within it (issue 19). Measured on the previous call.
PIECE_SECONDS = 0.1
#: The rate assumed before the first call is timed: the slowest built-in's, halved.
_FIRST_RATE = 1e6


_POOL: tuple[int, ThreadPoolExecutor] | None = None  # (workers, the other threads)


def _pool() -> ThreadPoolExecutor:
    """The engine's threads, started once (starting them per call cost 30% of the paper
    workload's time: a sweep makes hundreds of short calls)."""
    global _POOL
    if _POOL is None or _POOL[0] != _workers:
        if _POOL is not None:
            _POOL[1].shutdown(wait=False)
        others = max(1, _workers - 1)  # the calling thread is the first worker
        _POOL = (_workers, ThreadPoolExecutor(others, thread_name_prefix="corraoi-engine"))
    return _POOL[1]


def shutdown() -> None:
    """Stop the engine's threads (idle between calls; started again when needed)."""
    global _POOL
    pool, _POOL = _POOL, None
    if pool is not None:
        pool[1].shutdown(wait=True, cancel_futures=True)


def set_workers(workers: int | None) -> int:
    """Use ``workers`` threads per kernel call (default: every core). Returns the count used."""
    global _workers
    top = cores()
    if workers is None:
        workers = top
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    _workers = min(int(workers), top)
    return _workers


def workers() -> int:
    """The threads a kernel call uses now (:func:`set_workers`)."""
    return _workers


def plan(rate: float | None, R: int, left: int) -> tuple[int, list[tuple[int, int]]]:
    """(slots, run slices) of the next kernel call of ``R`` runs with ``left`` slots to go:
    one slice per thread, each about PIECE_SECONDS of work at ``rate`` (run-slots per second
    per thread, measured on the previous call; None before the first), more slices only when
    one slot of a thread's share of the runs takes longer; at least one slot."""
    budget = max(1.0, (rate if rate is not None else _FIRST_RATE) * PIECE_SECONDS)
    threads = max(1, min(_workers, R)) if R * left >= _THREAD_MIN_WORK else 1
    n = int(min(left, max(1, budget * threads // R)))
    count = max(threads, -(-R * n // int(budget)))
    if count == 1:
        return n, [(0, R)]
    cuts = np.linspace(0, R, count + 1).astype(int)
    return n, [(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:], strict=True)]


def rate(work: int, seconds: float, slices: int, before: float | None) -> float | None:
    """The rate per thread that ``work`` run-slots in ``seconds`` over ``slices`` show
    (``before`` when the call was too short to time)."""
    if seconds <= 1e-3:
        return before
    return work / seconds / max(1, min(_workers, slices))


def run_slices(run: Callable[[int, int], None], slices: list[tuple[int, int]]) -> None:
    """``run(a, b)`` for every slice of runs: in this thread when there is one slice or one
    worker (a signal is handled between slices), else on the engine's threads. On an
    interrupt, the slices not started are cancelled and the running ones (each about
    PIECE_SECONDS) finish before the KeyboardInterrupt goes on."""
    raise_if_asked()  # a signal whose KeyboardInterrupt was swallowed is not lost
    if _workers <= 1 or len(slices) == 1:
        for a, b in slices:
            run(a, b)
        return
    futures = [_pool().submit(run, a, b) for a, b in slices[1:]]
    try:
        run(*slices[0])  # this thread takes a slice too: one hand-over fewer per call
        for f in futures:
            f.result()
    finally:
        for f in futures:
            f.cancel()
        wait(futures)
