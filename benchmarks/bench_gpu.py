"""The GPU backend: start-up, throughput per policy, and the paper workload (docs/gpu.md).

Prints:

1. start-up: importing CuPy, creating the CUDA context, compiling (or loading from CuPy's disk
   cache) the module of K = 4 arms;
2. run-slots per second per policy on I1 (default checkpoints, as a sweep runs them) at
   1e6 runs x T = 1e4 and 1e4 runs x T = 1e7, best of --repeat;
3. the paper workload (I1, the twelve policies, 200 runs, T = 10,000) as
   ``experiments.sweep(grid, backend="gpu")`` in a warm process (modules compiled), best of
   --repeat; start-up (1) is what a fresh process adds to it.

    python benchmarks/bench_gpu.py                     # on the CUDA GPU (the gpu extra)
    python benchmarks/bench_gpu.py --device emulate --quick   # the kernels on the CPU

``--quick`` shrinks the sizes (1e4 runs x 1e3 slots, 100 runs x 1e5 slots) for the emulated
device, whose figures say nothing about a GPU's.
"""

from __future__ import annotations

import argparse
import os
import time

POLICIES = ("ucb", "cucb", "aoi-aware-ucb", "ts", "cts", "ts-gauss", "q-ucb", "q-ts", "sw-ucb",
            "d-ts")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", choices=("cuda", "emulate"), default="cuda")
    ap.add_argument("--quick", action="store_true", help="small sizes (for --device emulate)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--policies", default=",".join(POLICIES))
    args = ap.parse_args()
    os.environ["CORRAOI_GPU_DEVICE"] = args.device

    t0 = time.perf_counter()
    if args.device == "cuda":
        import cupy

        t_import = time.perf_counter() - t0
        t1 = time.perf_counter()
        cupy.zeros(1).sum().item()  # creates the context
        t_context = time.perf_counter() - t1
    else:
        t_import = t_context = 0.0
    from corraoi.experiments.grid import build_grid
    from corraoi.experiments.montecarlo import default_checkpoints
    from corraoi.experiments.sweeps import sweep
    from corraoi.gpu import get_device
    from corraoi.gpu.runner import simulate
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy

    dev = get_device()
    inst = load_instance("I1")
    t2 = time.perf_counter()
    simulate(inst, make_policy("ucb"), seed0=0, runs=1, horizon=1, device=dev)
    t_module = time.perf_counter() - t2
    print(f"device: {dev.name}")
    print("\n| start-up | s |\n|---|---:|")
    print(f"| import cupy | {t_import:.3f} |\n| CUDA context | {t_context:.3f} |")
    print(f"| module K = 4 (compile or cache) | {t_module:.3f} |")

    full = [(1_000_000, 10_000), (10_000, 10_000_000)]
    cases = [(10_000, 1_000), (100, 100_000)] if args.quick else full
    head = " | ".join(f"{r:.0e} runs x T {T:.0e}" for r, T in cases)
    print(f"\n| policy | {head} |\n|---|" + "---:|" * len(cases))
    for name in args.policies.split(","):
        spec = make_policy(name)
        cells = []
        for runs, T in cases:
            stops = default_checkpoints(T)
            best = float("inf")
            for _ in range(args.repeat):
                s = time.perf_counter()
                simulate(inst, spec, seed0=0, runs=runs, horizon=T, checkpoints=stops,
                         device=dev)  # fmt: skip
                best = min(best, time.perf_counter() - s)
            cells.append(f"{runs * T / best:.3g}")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)

    grid = build_grid(instances=["I1"], policies=["all"], horizons=[10_000], runs=200,
                      backend="gpu")  # fmt: skip
    sweep(grid)  # every module of the twelve compiled or loaded
    best = float("inf")
    for _ in range(args.repeat):
        s = time.perf_counter()
        sweep(grid)
        best = min(best, time.perf_counter() - s)
    print("\n| paper workload (I1, 12 policies, 200 runs, T = 1e4), warm | s |\n|---|---:|")
    print(f"| sweep(grid, backend=\"gpu\") | {best:.3f} |")
    print(f"| + start-up of a fresh process (import, context, module) | "
          f"{t_import + t_context + t_module:.3f} |")  # fmt: skip


if __name__ == "__main__":
    main()
