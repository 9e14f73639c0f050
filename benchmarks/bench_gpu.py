"""The GPU backend: start-up, throughput per policy, and the paper workload (docs/gpu.md).

Prints, each as a table:

1. start-up, in fresh processes: importing CuPy, creating the CUDA context, and the module of
   UCB for K = 4 arms, compiled into an empty CuPy cache, then loaded from it (--startup);
2. what each entry point of UCB and TS takes on the device (registers, local memory, blocks
   a multiprocessor holds at the block size) and, for a few launch shapes (threads a block,
   a register cap), their run-slots per second on I1 (--variants; measured last);
3. run-slots per second per policy on I1 (default checkpoints, as a sweep runs them) at each
   --sizes (runs x T), best of --repeat after one warm-up run;
4. the paper workload (I1, the twelve policies, 200 runs, T = 10,000) as
   ``experiments.sweep(grid, backend="gpu")`` in a warm process (modules compiled), best and
   median of 3 or --repeat; start-up (1) is what a fresh process adds to it.

    python benchmarks/bench_gpu.py --startup --variants --json bench.json   # on a CUDA GPU
    python benchmarks/bench_gpu.py --device emulate --quick       # the kernels on the CPU

``--quick`` shrinks the sizes for the emulated device, whose figures say nothing about a
GPU's. ``--json FILE`` writes every figure into FILE as it is measured (the file is replaced
whole after each table, never left half-written).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

POLICIES = ("ucb", "cucb", "aoi-aware-ucb", "aoi-aware-cucb", "ts", "cts", "aoi-aware-ts",
            "aoi-aware-cts", "ts-gauss", "q-ucb", "q-ts", "sw-ucb", "d-ts")  # fmt: skip
#: (threads a block, register cap, kernel.cu switches) measured by --variants; the first is
#: the device's default.
VARIANTS = ((128, None, ()), (256, None, ()), (128, 128, ()), (128, 96, ()),
            (128, None, ("CAI_LOG_BATCH=1",)))  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", choices=("cuda", "emulate"), default="cuda")
    ap.add_argument("--quick", action="store_true", help="small sizes (for --device emulate)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--policies", default=",".join(POLICIES))
    ap.add_argument("--sizes", default=None,
                    help="runs x T, comma-separated (default 1e5x1e4,1e6x1e4)")  # fmt: skip
    ap.add_argument("--startup", action="store_true", help="time start-up in fresh processes")
    ap.add_argument("--variants", action="store_true", help="time launch shapes (CUDA)")
    ap.add_argument("--paper-runs", type=int, default=200,
                    help="runs of the paper workload (0: leave it out)")  # fmt: skip
    ap.add_argument("--json", default=None, help="write the figures into this file")
    ap.add_argument("--startup-child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    os.environ["CORRAOI_GPU_DEVICE"] = args.device
    if args.startup_child:
        print(json.dumps(_startup(args.device)))
        return
    out = _Figures(args.json)

    if args.startup:
        _startup_table(args, out)

    from corraoi.gpu import get_device

    dev = get_device()
    out["device"] = dev.name
    print(f"device: {dev.name}", flush=True)
    default = "1e3x1e3,1e2x1e4" if args.quick else "1e5x1e4,1e6x1e4"
    sizes = [tuple(int(float(v)) for v in size.split("x"))
             for size in (args.sizes or default).split(",")]  # fmt: skip
    _rates_table(args, out, dev, sizes)
    if args.paper_runs > 0:
        _paper_table(args, out)
    if args.variants and args.device == "cuda":  # last: the figures above matter more
        _variants_table(args, out)


class _Figures(dict[str, Any]):
    """The figures measured so far, written to ``path`` (whole, through a .partial) on save."""

    def __init__(self, path: str | None) -> None:
        super().__init__()
        self.path = Path(path) if path else None

    def save(self) -> None:
        if self.path is None:
            return
        tmp = self.path.with_name(self.path.name + ".partial")
        tmp.write_text(json.dumps(self, indent=2) + "\n")
        os.replace(tmp, self.path)


# ---------------------------------------------------------------------------- start-up


def _startup(device: str) -> dict[str, float]:
    """In this (fresh) process: seconds to import CuPy, create the context, and make UCB's
    K = 4 module ready (compiled, or loaded from the cache)."""
    t0 = time.perf_counter()
    if device == "cuda":
        import cupy

        t_import = time.perf_counter() - t0
        t1 = time.perf_counter()
        cupy.zeros(1).sum().item()  # creates the context
        t_context = time.perf_counter() - t1
    else:
        t_import = t_context = 0.0
    from corraoi.gpu import get_device

    dev = get_device()
    t2 = time.perf_counter()
    dev.module(4, "ucb")
    return {"import": t_import, "context": t_context, "module": time.perf_counter() - t2}


def _startup_table(args: argparse.Namespace, out: _Figures) -> None:
    """Two fresh processes on one new, empty cache folder: the first compiles, the second
    loads what the first left (--quick: one process, on the caches as they are)."""
    runs: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory(prefix="corraoi-startup-") as cache:
        env = dict(os.environ)
        if not args.quick:
            env.update(CUPY_CACHE_DIR=cache, CORRAOI_CACHE_DIR=cache)
        for _ in range(1 if args.quick else 2):
            done = subprocess.run([sys.executable, __file__, "--device", args.device,
                                   "--startup-child"], env=env, capture_output=True,
                                  text=True, timeout=300)  # fmt: skip
            if done.returncode != 0:
                sys.exit(f"bench_gpu: the start-up process failed: {done.stderr.strip()}")
            runs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    cold = runs[0]
    first = "compiled (empty cache)" if not args.quick else "as the cache has it"
    print("\n| start-up (a fresh process) | s |\n|---|---:|")
    print(f"| import cupy | {cold['import']:.3f} |\n| CUDA context | {cold['context']:.3f} |")
    print(f"| module of UCB, K = 4: {first} | {cold['module']:.3f} |")
    if len(runs) > 1:
        print(f"| module of UCB, K = 4: loaded from the cache | {runs[1]['module']:.3f} |")
    out["startup"] = {"first": cold, "cached": runs[1] if len(runs) > 1 else None}
    out.save()


# ---------------------------------------------------------------------------- launch shapes


def _variants_table(args: argparse.Namespace, out: _Figures) -> None:
    import cupy

    from corraoi.gpu.device import CudaDevice, entry_name

    drv = cupy.cuda.driver
    sms = cupy.cuda.runtime.getDeviceProperties(cupy.cuda.Device().id)["multiProcessorCount"]
    runs, T = (4096, 500) if args.quick else (1_000_000, 2_000)
    rows = []
    print(f"\n| threads a block | register cap | switches | entry | registers | local bytes | "
          f"blocks / SM | run-slots/s ({runs:.0e} runs x T {T}) |")  # fmt: skip
    print("|---:|---:|---|---|---:|---:|---:|---:|")
    for block, cap, defines in VARIANTS:
        dev = CudaDevice(block=block, maxrregcount=cap, defines=defines)
        pairs = (("ucb", "ucb", False), ("cucb", "ucb", True), ("ts", "ts_beta", False),
                 ("cts", "ts_beta", True))  # fmt: skip
        if defines:  # the switches are the sampling families'
            pairs = pairs[2:]
        for policy, family, corr in pairs:
            entry = entry_name(family, corr, False)
            func = dev.module(4, family).get_function(entry)
            try:
                regs = drv.funcGetAttribute(drv.CU_FUNC_ATTRIBUTE_NUM_REGS, func.ptr)
                local = drv.funcGetAttribute(drv.CU_FUNC_ATTRIBUTE_LOCAL_SIZE_BYTES, func.ptr)
                per_sm = drv.occupancyMaxActiveBlocksPerMultiprocessor(func.ptr, block, 0)
            except Exception as exc:  # the figures below matter more than these
                print(f"(attributes of {entry} not read: {type(exc).__name__}: {exc})")
                regs = local = per_sm = -1
            rate = _rate(dev, policy, runs, T, repeat=args.repeat)
            rows.append({"block": block, "maxrregcount": cap, "defines": list(defines),
                         "entry": entry, "registers": regs, "local_bytes": local,
                         "blocks_per_sm": per_sm, "sms": sms,
                         "run_slots_per_s": rate})  # fmt: skip
            print(f"| {block} | {cap or '-'} | {' '.join(defines) or '-'} | {entry} | {regs} | "
                  f"{local} | {per_sm} | {rate:.3g} |", flush=True)  # fmt: skip
        out["variants"] = rows
        out.save()


# ---------------------------------------------------------------------------- rates


def _rate(dev: Any, name: str, runs: int, T: int, *, repeat: int) -> float:
    """Run-slots per second of ``name`` on I1, best of ``repeat`` after one warm-up run."""
    from corraoi.experiments.montecarlo import default_checkpoints
    from corraoi.gpu.runner import simulate
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy

    inst, spec, stops = load_instance("I1"), make_policy(name), default_checkpoints(T)
    simulate(inst, spec, seed0=0, runs=min(runs, 256), horizon=min(T, 100), device=dev)
    best = float("inf")
    for i in range(repeat):
        s = time.perf_counter()
        simulate(inst, spec, seed0=i * runs, runs=runs, horizon=T, checkpoints=stops,
                 device=dev)  # fmt: skip
        best = min(best, time.perf_counter() - s)
    return runs * T / best


def _rates_table(args: argparse.Namespace, out: _Figures, dev: Any,
                 sizes: list[tuple[int, ...]]) -> None:  # fmt: skip
    head = " | ".join(f"{r:.0e} runs x T {T:.0e}" for r, T in sizes)
    print(f"\n| run-slots/s, best of {args.repeat} | {head} |\n|---|" + "---:|" * len(sizes))
    rates: dict[str, dict[str, float]] = {}
    out["rates"] = rates
    for name in args.policies.split(","):
        cells = []
        for runs, T in sizes:
            rate = _rate(dev, name, runs, T, repeat=args.repeat)
            rates.setdefault(name, {})[f"{runs}x{T}"] = rate
            cells.append(f"{rate:.3g}")
            out.save()
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


def _paper_table(args: argparse.Namespace, out: _Figures) -> None:
    from corraoi.experiments.grid import build_grid
    from corraoi.experiments.sweeps import sweep

    grid = build_grid(instances=["I1"], policies=["all"], horizons=[10_000],
                      runs=args.paper_runs, backend="gpu")  # fmt: skip
    sweep(grid)  # every module of the twelve compiled or loaded
    times = []
    for _ in range(max(args.repeat, 3)):
        s = time.perf_counter()
        sweep(grid)
        times.append(time.perf_counter() - s)
    times.sort()
    print(f"\n| paper workload (I1, 12 policies, {args.paper_runs} runs, T = 1e4), warm | s |"
          "\n|---|---:|")  # fmt: skip
    print(f"| sweep(grid, backend=\"gpu\"), best of {len(times)} | {times[0]:.3f} |")
    print(f"| the same, median | {times[len(times) // 2]:.3f} |")
    out["paper_workload_s"] = {"runs": args.paper_runs, "best": times[0],
                               "median": times[len(times) // 2]}  # fmt: skip
    out.save()


if __name__ == "__main__":
    main()
