"""The GPU backend: start-up, throughput per policy, and the paper workload (docs/gpu.md).

Prints, each as a table:

1. start-up, in fresh processes: importing CuPy, creating the CUDA context, and the module of
   UCB for K = 4 arms, compiled into an empty CuPy cache, then loaded from it (--startup);
2. what each entry point of UCB and TS takes on the device (registers, local memory, blocks
   a multiprocessor holds at the block size) and, for each variant of VARIANTS (launch shapes:
   threads a block, a register cap; kernel.cu's switches: CAI_LOG_TEST, CAI_FP64), their
   run-slots per second on I1 (--variants; measured last), so that one run on a GPU says
   which variant is fastest;
3. run-slots per second per policy on I1 (default checkpoints, as a sweep runs them) at each
   --sizes (runs x T), best of --repeat after one warm-up run, with each of --reductions side
   by side (how the checkpoints are reduced over the runs: kernel.cu's reduce_checkpoints,
   the default, or the array module's reductions, the second GPU run's; one after the other
   for each policy and size); then UCB and TS at the largest size with a checkpoint at T only
   (the kernel alone, without the checkpoints' reductions);
4. the paper workload (I1, the twelve policies, 200 runs, T = 10,000) as
   ``experiments.sweep(grid, backend="gpu")`` in a warm process (modules compiled), best and
   median of 3 or --repeat; start-up (1) is what a fresh process adds to it.

    python benchmarks/bench_gpu.py --startup --variants --json bench.json   # on a CUDA GPU
    python benchmarks/bench_gpu.py --sizes 1e6x1e4 --reductions kernel,arrays --repeat 2
    python benchmarks/bench_gpu.py --device emulate --quick       # the kernels on the CPU

``--quick`` shrinks the sizes for the emulated device, whose figures say nothing about a
GPU's. ``--json FILE`` writes every figure into FILE as it is measured (the file is replaced
whole after each table, never left half-written): ``rates`` are the device's default
reduction's, ``rates_by_reduction`` each reduction's.
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
#: (name, threads a block, register cap, kernel.cu switches) measured by --variants; the first
#: is the device's default. The switches change the Beta sampler (CAI_LOG_TEST) or all the
#: arithmetic (CAI_FP64); a variant with switches of the sampler alone times TS and CTS only.
VARIANTS = (("default", 128, None, ()), ("block 256", 256, None, ()),
            ("registers <= 64", 128, 64, ()), ("registers <= 96", 128, 96, ()),
            ("log test where needed", 128, None, ("CAI_LOG_TEST=1",)),
            ("log tests batched", 128, None, ("CAI_LOG_TEST=2",)),
            ("double precision", 128, None, ("CAI_FP64=1",)))  # fmt: skip
#: Switches that touch the Beta-sampling families only.
SAMPLER_SWITCHES = ("CAI_LOG_TEST",)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", choices=("cuda", "emulate"), default="cuda")
    ap.add_argument("--quick", action="store_true", help="small sizes (for --device emulate)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--policies", default=",".join(POLICIES))
    ap.add_argument("--sizes", default=None,
                    help="runs x T, comma-separated (default 1e5x1e4,1e6x1e4)")
    ap.add_argument("--reductions", default=None,
                    help="checkpoint reductions timed side by side, comma-separated, of "
                         "kernel, arrays (default: the device's own)")  # fmt: skip
    ap.add_argument("--startup", action="store_true", help="time start-up in fresh processes")
    ap.add_argument("--variants", action="store_true",
                    help="time the variants of VARIANTS (emulated: the switches only)")
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
    from corraoi.gpu.device import REDUCTIONS

    dev = get_device()
    out["device"] = dev.name
    out["reduction"] = dev.reduction
    print(f"device: {dev.name}; checkpoints reduced by default with: {dev.reduction}", flush=True)
    reductions = (args.reductions or dev.reduction).split(",")
    for r in reductions:
        if r not in REDUCTIONS:
            sys.exit(f"bench_gpu: --reductions {args.reductions!r}: {r!r} is not one of "
                     f"{', '.join(REDUCTIONS)}")  # fmt: skip
    default = "1e3x1e3,1e2x1e4" if args.quick else "1e5x1e4,1e6x1e4"
    sizes = [tuple(int(float(v)) for v in size.split("x"))
             for size in (args.sizes or default).split(",")]  # fmt: skip
    _rates_table(args, out, dev, sizes, reductions)
    if args.paper_runs > 0:
        _paper_table(args, out)
    if args.variants:  # last: the figures above matter more
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


def kernel_attributes(func: Any, block: int) -> dict[str, int]:
    """Registers, local memory (bytes a thread) and blocks a multiprocessor holds at ``block``
    threads of a CuPy RawKernel (its ``num_regs`` and ``local_size_bytes``; the occupancy from
    the driver, on the kernel's CUfunction ``kernel.ptr``)."""
    import cupy

    drv = cupy.cuda.driver
    return {"registers": int(func.num_regs), "local_bytes": int(func.local_size_bytes),
            "blocks_per_sm": int(drv.occupancyMaxActiveBlocksPerMultiprocessor(
                func.kernel.ptr, block, 0))}  # fmt: skip


def _variants_table(args: argparse.Namespace, out: _Figures) -> None:
    """Each variant's run-slots per second (and on a CUDA device its entries' attributes). On
    the emulated device only the switches mean anything: the launch shapes are left out."""
    from corraoi.gpu.device import CudaDevice, EmulatedDevice, entry_name

    cuda = args.device == "cuda"
    sms = 0
    if cuda:
        import cupy

        sms = cupy.cuda.runtime.getDeviceProperties(cupy.cuda.Device().id)["multiProcessorCount"]
    runs, T = (1024, 200) if args.quick else (1_000_000, 2_000)
    rows = []
    print(f"\n| variant | threads a block | register cap | switches | entry | registers | "
          f"local bytes | blocks / SM | run-slots/s ({runs:.0e} runs x T {T}) |")  # fmt: skip
    print("|---|---:|---:|---|---|---:|---:|---:|---:|")
    for name, block, cap, defines in VARIANTS:
        if not cuda and (block, cap) != (VARIANTS[0][1], VARIANTS[0][2]):
            continue
        dev: Any = (CudaDevice(block=block, maxrregcount=cap, defines=defines) if cuda
                    else EmulatedDevice(defines=defines))  # fmt: skip
        pairs = (("ucb", "ucb", False), ("cucb", "ucb", True), ("ts", "ts_beta", False),
                 ("cts", "ts_beta", True))  # fmt: skip
        if defines and all(d.split("=")[0] in SAMPLER_SWITCHES for d in defines):
            pairs = pairs[2:]
        for policy, family, corr in pairs:
            entry = entry_name(family, corr, False)
            attrs = {"registers": -1, "local_bytes": -1, "blocks_per_sm": -1}
            try:
                if cuda:
                    attrs = kernel_attributes(dev.module(4, family).get_function(entry), block)
            except Exception as exc:  # the rates below matter more than these
                print(f"(attributes of {entry} not read: {type(exc).__name__}: {exc})")
            rate = _rate(dev, policy, runs, T, repeat=args.repeat)
            rows.append({"variant": name, "block": block, "maxrregcount": cap,
                         "defines": list(defines), "policy": policy, "entry": entry, **attrs,
                         "sms": sms, "run_slots_per_s": rate})  # fmt: skip
            print(f"| {name} | {block} | {cap or '-'} | {' '.join(defines) or '-'} | {entry} | "
                  f"{attrs['registers']} | {attrs['local_bytes']} | {attrs['blocks_per_sm']} | "
                  f"{rate:.3g} |", flush=True)  # fmt: skip
            out["variants"] = rows
            out.save()


# ---------------------------------------------------------------------------- rates


def _rate(dev: Any, name: str, runs: int, T: int, *, repeat: int, bare: bool = False) -> float:
    """Run-slots per second of ``name`` on I1, best of ``repeat`` after one warm-up run; with
    the default checkpoints (as a sweep runs), or ``bare``: a checkpoint at T only."""
    from corraoi.experiments.montecarlo import default_checkpoints
    from corraoi.gpu.runner import simulate
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy

    inst, spec = load_instance("I1"), make_policy(name)
    stops = [T] if bare else default_checkpoints(T)
    simulate(inst, spec, seed0=0, runs=min(runs, 256), horizon=min(T, 100), device=dev)
    best = float("inf")
    for i in range(repeat):
        s = time.perf_counter()
        simulate(inst, spec, seed0=i * runs, runs=runs, horizon=T, checkpoints=stops,
                 device=dev)  # fmt: skip
        best = min(best, time.perf_counter() - s)
    return runs * T / best


def _with_reduction(dev: Any, reduction: str) -> Any:
    """``dev`` itself where it reduces with ``reduction``, else a device of its kind that does."""
    from corraoi.gpu.device import CudaDevice, EmulatedDevice

    if dev.reduction == reduction:
        return dev
    return (CudaDevice(reduction=reduction) if isinstance(dev, CudaDevice)
            else EmulatedDevice(reduction=reduction))  # fmt: skip


def _rates_table(args: argparse.Namespace, out: _Figures, dev: Any,
                 sizes: list[tuple[int, ...]], reductions: list[str]) -> None:  # fmt: skip
    devices = {r: _with_reduction(dev, r) for r in reductions}
    cols = [(f"{r:.0e} runs x T {T:.0e}" + (f", {red}" if len(reductions) > 1 else ""), red,
             r, T) for r, T in sizes for red in reductions]  # fmt: skip
    head = " | ".join(c[0] for c in cols)
    print(f"\n| run-slots/s, best of {args.repeat} | {head} |\n|---|" + "---:|" * len(cols))
    rates: dict[str, dict[str, float]] = {}
    by_reduction: dict[str, dict[str, dict[str, float]]] = {r: {} for r in reductions}
    out["rates"] = rates
    out["rates_by_reduction"] = by_reduction
    for name in args.policies.split(","):
        cells = []
        for _, red, runs, T in cols:
            rate = _rate(devices[red], name, runs, T, repeat=args.repeat)
            by_reduction[red].setdefault(name, {})[f"{runs}x{T}"] = rate
            if red == dev.reduction or (dev.reduction not in reductions and red == reductions[0]):
                rates.setdefault(name, {})[f"{runs}x{T}"] = rate
            cells.append(f"{rate:.3g}")
            out.save()
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    runs, T = max(sizes, key=lambda size: size[0] * size[1])
    bare: dict[str, float] = {}
    out["rates_checkpoint_at_T_only"] = {"size": f"{runs}x{T}", "rates": bare}
    for name in ("ucb", "ts"):
        if name in args.policies.split(","):
            bare[name] = _rate(dev, name, runs, T, repeat=args.repeat, bare=True)
            print(f"| {name}, a checkpoint at T only, {runs:.0e} runs x T {T:.0e} | "
                  f"{bare[name]:.3g} |", flush=True)  # fmt: skip
            out.save()


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
