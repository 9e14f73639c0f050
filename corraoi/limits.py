"""The limits of corraoi's numbers, stated once: horizon, seeds, runs, checkpoints, ports.

Every numeric command-line option is range-checked against these (``corraoi.cli.options``)
before anything is allocated, so that a value beyond what the engine's 64-bit sums, the
log format or the machine can hold is one line naming the option and the limit, never a
traceback or a memory blow-up. The engine can call the ``check_*`` functions too.

Why the horizon stops at 2**32 - 1: the engine keeps the AoI sum, the pathwise regret and
the estimator as signed 64-bit integers. The AoI after slot t is at most t + 1, so the AoI
sum over T slots is at most T (T + 3) / 2, and the largest T for which that fits in
2**63 - 1 is 2**32 - 2 (``MAX_HORIZON``). A log's ``log_time`` (t seconds in
nanoseconds) fits for every such T.
"""

from __future__ import annotations

import os
from typing import Final

from .arguments import integer
from .errors import ConfigError

#: The largest signed 64-bit integer: slot values, seeds and sums are stored as int64.
INT64_MAX: Final = 2**63 - 1
INT64_MIN: Final = -(2**63)


def _max_horizon() -> int:
    """The largest T with T (T + 3) / 2 <= INT64_MAX (the worst-case AoI sum)."""
    lo, hi = 1, 2**33
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if mid * (mid + 3) // 2 <= INT64_MAX:
            lo = mid
        else:
            hi = mid - 1
    return lo


#: The largest horizon whose AoI sums cannot overflow int64 (2**32 - 2 = 4,294,967,294).
MAX_HORIZON: Final = _max_horizon()
#: Seeds are int64; run i of a batch uses seed + i, so seed + runs - 1 must fit as well.
MAX_SEED: Final = INT64_MAX
#: Monte Carlo runs of one sweep (the memory estimate below refuses fewer on most hosts).
MAX_RUNS: Final = 10**8
#: Checkpoint slots per sweep curve.
MAX_CHECKPOINTS: Final = 1_000_000
#: Engine threads.
MAX_WORKERS: Final = 1024
#: TCP ports.
MIN_PORT: Final = 1
MAX_PORT: Final = 65535
#: Bytes a sweep keeps per run (seed lists, generator states, sums; generous by design),
#: per run and arm (pulls and successes), and per run, arm and kept figure (the results of
#: each policy and the checkpoint snapshots: regret, AoI sum, pulls per arm).
SWEEP_BYTES_PER_RUN: Final = 512
SWEEP_BYTES_PER_RUN_ARM: Final = 32
SWEEP_BYTES_PER_FIGURE: Final = 16
SWEEP_BYTES_PER_FIGURE_ARM: Final = 8


def check_int(value: object, *, name: str, lo: int, hi: int, why: str = "",
              floats: bool = False) -> int:  # fmt: skip
    """``value`` as an int in ``lo..hi``, or a :class:`ConfigError` naming ``name`` (its
    TypeError or ValueError variant: :func:`corraoi.arguments.integer`). ``floats``: a float
    of integral value is taken too (what a Python caller may write: ``1e4``)."""
    return integer(value, name=name, lo=lo, hi=hi, kind=ConfigError, why=why, floats=floats)


def check_horizon(horizon: object, *, name: str = "horizon", floats: bool = False) -> int:
    return check_int(horizon, name=name, lo=1, hi=MAX_HORIZON,
                     why="the AoI sums must fit in 64 bits", floats=floats)  # fmt: skip


def check_seed(seed: object, *, runs: int = 1, name: str = "seed", floats: bool = False) -> int:
    """A seed such that every seed of the batch (seed .. seed + runs - 1) is an int64."""
    top = MAX_SEED - max(int(runs), 1) + 1
    why = "seeds are 64-bit" + (f" and {runs} runs use seed .. seed+{runs - 1}" if runs > 1 else "")
    return check_int(seed, name=name, lo=0, hi=top, why=why, floats=floats)


def physical_memory() -> int | None:
    """Bytes of RAM of this machine, or None where the OS does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def sweep_memory(runs: int, arms: int, *, policies: int = 1, checkpoints: int = 0) -> int:
    """An upper estimate of the bytes a sweep of ``runs`` runs on ``arms`` arms holds:
    the engine's per-run state, each policy's results and every checkpoint snapshot."""
    figures = int(policies) + int(checkpoints) + 1
    per_figure = SWEEP_BYTES_PER_FIGURE + SWEEP_BYTES_PER_FIGURE_ARM * int(arms)
    per_run = SWEEP_BYTES_PER_RUN + SWEEP_BYTES_PER_RUN_ARM * int(arms) + figures * per_figure
    return int(runs) * per_run


def check_sweep_memory(
    runs: int,
    arms: int,
    *,
    policies: int = 1,
    checkpoints: int = 0,
    available: int | None = None,
) -> int:
    """Refuse a sweep whose state would not fit in half of this machine's memory.

    Checked before any array (or list of seeds) is made; returns the estimate in bytes.
    """
    need = sweep_memory(runs, arms, policies=policies, checkpoints=checkpoints)
    have = physical_memory() if available is None else available
    if have is not None and need > have // 2:
        raise ConfigError(
            f"--runs {runs}: a sweep of {runs} runs on {arms} arms needs about "
            f"{_size(need)} of memory, more than half of this machine's {_size(have)}; "
            "expected fewer runs (split the sweep over several seeds)"
        )
    return need


#: A sweep of more run-slots than this (about a month of one core at 5e6 run-slots/s) is
#: refused unless --allow-huge says it is meant.
MAX_RUN_SLOTS = 10**13


def check_sweep_size(cells: int, runs: int, run_slots: int, *, allow: bool) -> str:
    """The sweep's size in one line; a ConfigError with the numbers and the overriding
    option when it exceeds :data:`MAX_RUN_SLOTS` and ``allow`` is not given."""
    size = f"{cells:,} cell(s) x {runs:,} runs = {run_slots:.3g} run-slots"
    if run_slots > MAX_RUN_SLOTS and not allow:
        raise ConfigError(
            f"this sweep is {size}, more than the {MAX_RUN_SLOTS:.0e} accepted without "
            "--allow-huge (about a month of one core at 5e6 run-slots/s); expected fewer "
            "cells, runs or slots, or --allow-huge if it is meant"
        )
    return size


def _size(n: int) -> str:
    value = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if value < 1024 or unit == "TiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.1f} {unit}"
        value /= 1024
    raise AssertionError("unreachable")


__all__ = [
    "INT64_MAX",
    "INT64_MIN",
    "MAX_CHECKPOINTS",
    "MAX_HORIZON",
    "MAX_PORT",
    "MAX_RUNS",
    "MAX_SEED",
    "MAX_WORKERS",
    "MIN_PORT",
    "check_horizon",
    "check_int",
    "check_seed",
    "check_sweep_memory",
    "physical_memory",
    "sweep_memory",
]
