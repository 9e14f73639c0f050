"""Engine benchmark: the paper's workload (I1, all twelve policies, 200 runs, T = 10,000).

Prints a table of wall seconds and run-slots per second per policy, the total, the cold
start (numba compile or cache load) separately, and peak memory (max RSS of a fresh
process) for the sweep at horizon 10,000 against 1,000,000.

    python benchmarks/bench_engine.py [--runs 200] [--horizon 10000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time


def workload(runs: int, horizon: int, repeat: int) -> None:
    t0 = time.perf_counter()
    from corraoi.engine import Simulation, set_workers
    from corraoi.instance import load_instance
    from corraoi.policies import POLICY_NAMES, make_policy

    inst = load_instance("I1")
    workers = set_workers(None)
    # cold start: import + compile (or load from numba's cache) + one tiny run
    Simulation(inst, make_policy("ucb"), [0], 10).advance(10, record=False)
    cold = time.perf_counter() - t0
    best: dict[str, float] = {}
    for _ in range(repeat):
        for name in POLICY_NAMES:
            sim = Simulation(inst, make_policy(name), list(range(runs)), horizon)
            s = time.perf_counter()
            sim.advance(horizon, record=False)
            dt = time.perf_counter() - s
            best[name] = min(best.get(name, float("inf")), dt)
    run_slots = runs * horizon
    print(f"workload: I1, {len(best)} policies, {runs} runs, horizon {horizon}, "
          f"{workers} threads, best of {repeat}")  # fmt: skip
    print(f"{'policy':22s} {'wall s':>8} {'run-slots/s':>14}")
    for name, dt in best.items():
        print(f"{name:22s} {dt:8.3f} {run_slots / dt:14,.0f}")
    total = sum(best.values())
    print(f"{'total':22s} {total:8.3f} {run_slots * len(best) / total:14,.0f}")
    print(f"cold start (import + compile or cache load): {cold:.2f} s")


def peak_rss(horizon: int, runs: int, policies: str) -> float:
    code = (
        "import resource, sys\n"
        "from corraoi.instance import load_instance\n"
        "from corraoi.policies import make_policies\n"
        "from corraoi.sweep import run_sweep\n"
        f"run_sweep(load_instance('I1'), make_policies([{policies!r}]), runs={runs}, "
        f"horizon={horizon}, checkpoints=range(0, {horizon} + 1, {max(horizon // 100, 1)}))\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--horizon", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--memory-policies", default="ucb,cts")
    ap.add_argument("--skip-memory", action="store_true")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}")
    workload(args.runs, args.horizon, args.repeat)
    if not args.skip_memory:
        small = peak_rss(10_000, args.runs, args.memory_policies)
        large = peak_rss(1_000_000, args.runs, args.memory_policies)
        print(
            f"peak memory ({args.memory_policies}, {args.runs} runs): T=10,000 {small:.1f} MiB,"
            f" T=1,000,000 {large:.1f} MiB, ratio {large / small:.3f}"
        )


if __name__ == "__main__":
    main()
