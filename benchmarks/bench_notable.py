"""What naming a sweep's runs worth watching costs (issue 20: at most 2% of a sweep).

Two measurements, printed as one table:

* the paper's sweep of one instance (twelve policies, 200 runs, T = 10,000, into a folder),
  in this process, with the notable runs named and with the naming switched off, in
  alternation, best of ``--repeat``;
* ``corraoi.experiments.notable.notable_runs`` alone on synthetic finals of 24 cells (every pair:
276)
  for 1e4, 1e5 and 1e6 runs, beside the time the engine needs for those runs at the paper's
  horizon at the rate measured in the first part.

    python benchmarks/bench_notable.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np


def _sweep_once(out: Path, named: bool) -> float:
    import corraoi.experiments.summary as so
    import corraoi.experiments.sweeps as ex
    from corraoi.experiments.grid import build_grid

    grid = build_grid(instances=["I1"], policies=["all"], horizons=[10_000], runs=200)
    real = so.group_notable
    if not named:
        so.group_notable = lambda grid, cells: {"cells": {}, "pairs": []}  # type: ignore[assignment]
    try:
        start = time.perf_counter()
        ex.sweep(grid, out=out, force=True)
        return time.perf_counter() - start
    finally:
        so.group_notable = real  # type: ignore[assignment]


def _parts(tmp: Path) -> dict[str, float]:
    """The two costs inside one named sweep: computing the runs, drawing them in sweep.rrd."""
    import corraoi.experiments.summary as so
    from corraoi.recorder.sweeplog.recording import SweepRerunSink

    took = {"naming (corraoi.experiments.notable)": 0.0, "drawing 36 runs into sweep.rrd": 0.0}
    real_name, real_mark = so.group_notable, SweepRerunSink.mark

    def timed(key: str, fn: Any) -> Any:
        def wrapper(*a: Any, **k: Any) -> Any:
            start = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                took[key] += time.perf_counter() - start

        return wrapper

    so.group_notable = timed("naming (corraoi.experiments.notable)", real_name)  # type: ignore[assignment]
    SweepRerunSink.mark = timed("drawing 36 runs into sweep.rrd", real_mark)  # type: ignore[method-assign]
    try:
        _sweep_once(tmp / "parts", True)
    finally:
        so.group_notable, SweepRerunSink.mark = real_name, real_mark  # type: ignore[method-assign]
    return took


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    from corraoi.experiments.notable import notable_runs

    tmp = Path(tempfile.mkdtemp(prefix="corraoi-notable-"))
    try:
        _sweep_once(tmp / "warm", True)  # kernels loaded, caches warm
        times: dict[bool, list[float]] = {True: [], False: []}
        for _ in range(args.repeat):
            for named in (False, True):
                times[named].append(_sweep_once(tmp / f"s{named}", named))
        parts = _parts(tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    off, on = min(times[False]), min(times[True])
    rate = 12 * 200 * 10_000 / off  # run-slots a second, whole sweep with its files
    rows: list[tuple[str, str, str, str]] = [
        ("paper sweep of I1 (12 cells x 200 runs, T = 1e4, -o)", f"{off:.3f} s", f"{on:.3f} s",
         f"{100 * (on - off) / off:+.1f}%"),
    ]  # fmt: skip
    for what, took in parts.items():
        rows.append((f"  of which {what}", "", f"{took:.4f} s", f"{100 * took / off:+.2f}%"))
    rng = np.random.default_rng(0)
    for runs in (10_000, 100_000, 1_000_000):
        finals: list[Any] = [rng.normal(100, 30, runs).round() for _ in range(24)]
        best = float("inf")
        for _ in range(3):
            start = time.perf_counter()
            notable_runs([f"p{i}" for i in range(24)], finals, [{}] * 24, seed=0)
            best = min(best, time.perf_counter() - start)
        sweep_s = 24 * runs * 10_000 / rate
        rows.append((f"notable_runs: 24 cells, 276 pairs, {runs:,} runs",
                     f"{sweep_s:,.0f} s (sweep, est.)", f"{best:.3f} s",
                     f"{100 * best / sweep_s:+.3f}%"))  # fmt: skip
    print(f"{'what':58s} {'without':>22s} {'naming':>10s} {'cost':>9s}")
    for what, a, b, c in rows:
        print(f"{what:58s} {a:>22s} {b:>10s} {c:>9s}")
    print(f"(all times best of {args.repeat} or 3; sweep rate {rate / 1e6:.1f} M run-slots/s)")


if __name__ == "__main__":
    main()
