"""The GPU's mean regret against the CPU engine's: a million runs on the device, the CPU
engine's mean at 4,000 runs, within --z standard errors of their difference (docs/gpu.md).

The two draw independent streams (the GPU's Philox, the CPU's SFC64), so they agree
statistically, not run by run. The CPU engine's means are deterministic: they are computed
once, on any machine, into ``benchmarks/gpu_cpu_reference.json`` (seconds on two cores), and
read from there; a reference the file does not hold is computed now, and the table says so.

    python benchmarks/gpu_means.py                      # 1e6 runs on the CUDA GPU
    python benchmarks/gpu_means.py --write-reference    # the CPU engine's means, into the file
    python benchmarks/gpu_means.py --device emulate --gpu-runs 2000 --cpu-runs 1000 \\
        --horizon 1000                                  # the same, small, on the CPU
    python benchmarks/gpu_means.py --variant "" --variant CAI_FP64=1 \\
        --variant CAI_LOG_TEST=1:ts,cts                 # kernel.cu's variants too

``--variant DEFINES[:POLICIES]`` (repeatable) checks kernel.cu compiled with those switches
(comma-separated; "" or "default" is the default kernel; ``reduction=arrays`` reduces the
checkpoints with the array module instead of kernel.cu's reduce_checkpoints), for POLICIES
(default: --policies), so that a variant a benchmark finds faster can be made the default
with its means checked. Each row also checks the device's moments at T against those of the
runs' final regrets, which come back one by one (the checkpoint reduction itself: within
1e-9). Prints a table; ``--json FILE`` writes it as JSON too. Exit status 1 when a policy's
means differ by more than --z standard errors, or a reduction by more than 1e-9.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any

REFERENCE = Path(__file__).with_name("gpu_cpu_reference.json")
POLICIES = ("ucb", "cucb", "ts", "cts")
#: kernel.cu's switches (compile-time defines) a --variant may set, and the device's reduction.
SWITCHES = ("CAI_FP64", "CAI_LOG_TEST", "reduction")
#: The largest relative difference between the device's moments at T and those of the final
#: regrets: both are of the same values, so only rounding may part them.
REDUCTION_TOLERANCE = 1e-9


def _key(instance: str, horizon: int, runs: int) -> str:
    return f"{instance} T={horizon} runs={runs} seeds from 0"


def cpu_reference(instance: str, names: list[str], horizon: int, runs: int) -> dict[str, Any]:
    """The CPU engine's regret at ``horizon`` over seeds 0 .. runs - 1: n, mean, m2 per policy."""
    from corraoi.experiments.montecarlo import run_policy
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy
    from corraoi.stats import Moments

    inst = load_instance(instance)
    out = {}
    for name in names:
        m = Moments.of(run_policy(inst, make_policy(name), seeds=range(runs),
                                  horizon=horizon).regret)  # fmt: skip
        out[name] = {"n": m.n, "mean": float(m.mean), "m2": float(m.m2)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", choices=("cuda", "emulate"), default="cuda")
    ap.add_argument("--instance", default="I1")
    ap.add_argument("--policies", default=",".join(POLICIES))
    ap.add_argument("--horizon", type=int, default=10_000)
    ap.add_argument("--gpu-runs", type=int, default=1_000_000)
    ap.add_argument("--cpu-runs", type=int, default=4_000)
    ap.add_argument("--z", type=float, default=4.0)
    ap.add_argument("--variant", action="append", default=None,
                    help="kernel.cu switches, comma-separated ('' = default), optionally "
                         ":policies; repeatable (default: the default kernel only)")
    ap.add_argument("--json", default=None, help="write the table into this file as well")
    ap.add_argument("--write-reference", action="store_true",
                    help=f"compute the CPU engine's means into {REFERENCE.name}")  # fmt: skip
    args = ap.parse_args()
    names = args.policies.split(",")
    key = _key(args.instance, args.horizon, args.cpu_runs)
    stored = json.loads(REFERENCE.read_text()) if REFERENCE.exists() else {}

    if args.write_reference:
        from corraoi import __version__

        start = time.perf_counter()
        ref = cpu_reference(args.instance, names, args.horizon, args.cpu_runs)
        stored[key] = {"corraoi": __version__, "policies": ref}
        tmp = REFERENCE.with_name(REFERENCE.name + ".partial")
        tmp.write_text(json.dumps(stored, indent=2, sort_keys=True) + "\n")
        os.replace(tmp, REFERENCE)
        print(f"wrote {REFERENCE.name} [{key}] in {time.perf_counter() - start:.1f} s")
        return

    os.environ["CORRAOI_GPU_DEVICE"] = args.device
    from corraoi.gpu.device import REDUCTIONS, CudaDevice, Device, EmulatedDevice
    from corraoi.gpu.runner import simulate
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy
    from corraoi.stats import Moments

    variants = []
    for spec in args.variant if args.variant is not None else [""]:
        defines, _, which = spec.partition(":")
        items = [d for d in defines.split(",") if d and d != "default"]
        for d in items:
            name, _, value = d.partition("=")
            if name not in SWITCHES or (name == "reduction" and value not in REDUCTIONS):
                sys.exit(f"gpu_means: --variant {spec!r}: {d!r} is not one of kernel.cu's "
                         f"switches ({', '.join(SWITCHES[:-1])}), NAME=VALUE, or reduction="
                         f"{'|'.join(REDUCTIONS)}")  # fmt: skip
        variants.append((tuple(items), which.split(",") if which else names))
    wanted = sorted({n for _, ns in variants for n in ns})
    held = stored.get(key, {}).get("policies", {})
    missing = [n for n in wanted if n not in held]
    source = f"{REFERENCE.name}" if not missing else "computed now"
    ref = {**held, **(cpu_reference(args.instance, missing, args.horizon, args.cpu_runs)
                      if missing else {})}  # fmt: skip
    inst = load_instance(args.instance)
    rows: list[dict[str, Any]] = []
    device_name = ""
    for items, which in variants:
        defines = tuple(d for d in items if not d.startswith("reduction="))
        reduction = next((d.split("=")[1] for d in items if d.startswith("reduction=")), None)
        dev: Device = (CudaDevice(defines=defines, reduction=reduction) if args.device == "cuda"
                       else EmulatedDevice(defines=defines, reduction=reduction))  # fmt: skip
        device_name = dev.name
        label = " ".join(items) or "default"
        print(f"\ndevice: {dev.name}, kernel: {label} (checkpoints reduced with: "
              f"{dev.reduction}); {args.instance}, T = {args.horizon}: GPU {args.gpu_runs} runs "
              f"against the CPU engine's {args.cpu_runs} ({source})")
        print("\n| policy | GPU mean +- se | CPU mean +- se | difference / se | GPU s | within | "
              "reduction vs finals |")  # fmt: skip
        print("|---|---:|---:|---:|---:|---|---:|")
        for name in which:
            start = time.perf_counter()
            r = simulate(inst, make_policy(name), seed0=0, runs=args.gpu_runs,
                         horizon=args.horizon, device=dev)  # fmt: skip
            wall = time.perf_counter() - start
            g_mean, g_var = float(r.regret.mean[-1]), float(r.regret.m2[-1]) / (r.regret.n - 1)
            c = ref[name]
            c_mean, c_var = c["mean"], c["m2"] / (c["n"] - 1)
            g_se, c_se = math.sqrt(g_var / r.regret.n), math.sqrt(c_var / c["n"])
            z = (g_mean - c_mean) / math.hypot(g_se, c_se)
            finals = Moments.of(r.regret_final)
            rel = max(abs(g_mean - float(finals.mean)) / max(abs(float(finals.mean)), 1e-300),
                      abs(float(r.regret.m2[-1]) - float(finals.m2))
                      / max(abs(float(finals.m2)), 1e-300))  # fmt: skip
            ok = abs(z) <= args.z and rel <= REDUCTION_TOLERANCE
            rows.append({"policy": name, "variant": label, "reduction": dev.reduction,
                         "gpu_mean": g_mean, "gpu_se": g_se, "gpu_runs": r.regret.n,
                         "cpu_mean": c_mean, "cpu_se": c_se, "cpu_runs": c["n"], "z": z,
                         "reduction_rel_error": rel, "gpu_seconds": wall,
                         "within": ok})  # fmt: skip
            print(f"| {name} | {g_mean:.2f} +- {g_se:.2f} | {c_mean:.2f} +- {c_se:.2f} | "
                  f"{z:+.2f} | {wall:.2f} | {'yes' if ok else 'NO'} | {rel:.1e} |",
                  flush=True)  # fmt: skip
            if args.json:
                tmp = Path(args.json + ".partial")
                tmp.write_text(json.dumps({"device": device_name, "instance": args.instance,
                                           "horizon": args.horizon, "reference": source,
                                           "z_limit": args.z, "rows": rows}, indent=2) + "\n")
                os.replace(tmp, args.json)
    bad = [f"{row['policy']} ({row['variant']})" for row in rows if not row["within"]]
    if bad:
        sys.exit(f"gpu_means: {', '.join(bad)}: the GPU's mean is more than {args.z} standard "
                 f"errors from the CPU engine's, or its moments at T more than "
                 f"{REDUCTION_TOLERANCE:g} from those of the final regrets")  # fmt: skip
    print(f"\nevery policy within {args.z} standard errors")


if __name__ == "__main__":
    main()
