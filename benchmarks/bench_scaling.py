"""Grid sweeps: the cost of the grid machinery, of a LocalCluster, and memory in runs and cells.

Prints:

1. the paper workload (I1, the twelve policies, 200 runs, T = 10,000) three ways, best of
   --repeat in one warm process: the engine alone (``corraoi.experiments.montecarlo.run_sweep``,
   what a sweep
   cost before grids), the grid in-process (``corraoi.experiments.sweeps.sweep``), and the grid on a
   LocalCluster of 2 workers (its start-up reported separately);
2. the per-core rate, and the model of docs/scaling.md: 5 instances x 16 policies x 10,000 runs
   x T = 1e5 on 1, 16 and 256 cores;
3. peak memory (max RSS of a fresh process) of a sweep into a folder with 1 and 16 cells.

    python benchmarks/bench_scaling.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time


def paper_workload(repeat: int) -> float:
    from corraoi.engine.threads import set_workers
    from corraoi.experiments.grid import build_grid
    from corraoi.experiments.montecarlo import default_checkpoints, run_sweep
    from corraoi.experiments.sweeps import sweep
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policies

    runs, T = 200, 10_000
    set_workers(None)
    inst = load_instance("I1")
    specs = make_policies(["all"])
    grid = build_grid(instances=["I1"], policies=["all"], horizons=[T], runs=runs)
    stops = default_checkpoints(T)

    def best(f) -> float:  # type: ignore[no-untyped-def]
        times = []
        for _ in range(repeat):
            s = time.perf_counter()
            f()
            times.append(time.perf_counter() - s)
        return min(times)

    engine = best(lambda: run_sweep(inst, specs, runs=runs, horizon=T, checkpoints=stops))
    in_process = best(lambda: sweep(grid))
    import dask.distributed as dd

    s = time.perf_counter()
    cluster = dd.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                              host="127.0.0.1", dashboard_address=None)  # fmt: skip
    client = dd.Client(cluster)
    start_up = time.perf_counter() - s
    sweep(grid, client=client)  # workers import corraoi and load the kernels once
    on_cluster = best(lambda: sweep(grid, client=client))
    client.close()
    cluster.close()
    print(f"1. the paper workload (I1, 12 policies, {runs} runs, T = {T:,}), best of {repeat}")
    print(f"{'how':46s} {'wall s':>7} {'x engine':>9}")
    print(f"{'engine alone (run_sweep, before grids)':46s} {engine:7.3f} {1:9.2f}")
    ratio = in_process / engine
    print(f"{'grid, in-process':46s} {in_process:7.3f} {ratio:9.2f}  (target <= 1.10)")
    print(f"{'grid, LocalCluster(2 workers)':46s} {on_cluster:7.3f} {on_cluster / engine:9.2f}"
          "  (target <= 1.25)")  # fmt: skip
    print(f"{'LocalCluster(2) start-up (not included above)':46s} {start_up:7.3f}")
    return 12 * runs * T / engine / (os.cpu_count() or 1)


def model(per_core: float) -> None:
    work = 5 * 16 * 10_000 * 100_000
    print(f"\n2. per-core rate {per_core:,.0f} run-slots/s (the paper mix on this machine)")
    print(f"   5 instances x 16 policies x 10,000 runs x T = 1e5 = {work:.1e} run-slots:")
    for cores in (1, 16, 256):
        hours = work / (per_core * cores) / 3600
        print(f"   {cores:4d} cores: {hours:8.2f} h")


def peak_rss(cells: int) -> float:
    policies = "ucb,cucb,ts,cts"
    instances = ",".join(["I1", "I2", "I1", "I2"][: max(1, cells // 4)])
    if cells == 1:
        policies, instances = "ucb", "I1"
    with tempfile.TemporaryDirectory() as tmp:
        horizons = "2000" if cells <= 8 else "2000,3000"
        code = (
            "import resource, sys\n"
            "from corraoi.cli import main\n"
            f"sys.argv = ['corraoi', 'sweep', '-i', {instances!r}, '-p', {policies!r}, "
            f"'-T', {horizons!r}, '-n', '200', '--chunk', '50', '-o', {tmp + '/s'!r}]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
        )
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             check=True)  # fmt: skip
        return int(out.stdout.strip().splitlines()[-1]) / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}, "
          f"load average {os.getloadavg()[0]:.2f} at start\n")  # fmt: skip
    per_core = paper_workload(args.repeat)
    model(per_core)
    one, sixteen = peak_rss(1), peak_rss(16)
    print(f"\n3. peak memory of `sweep -o` (200 runs, chunks of 50): 1 cell {one:.0f} MiB, "
          f"16 cells {sixteen:.0f} MiB")  # fmt: skip


if __name__ == "__main__":
    main()
