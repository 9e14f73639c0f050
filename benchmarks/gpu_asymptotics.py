"""The paper's asymptotics on I2 (C = 0), checked with the GPU backend (docs/gpu.md).

Theorems 2 and 3: with no competitive sub-optimal arm, the regret of CUCB and CTS stays
bounded (O(1)) while UCB's grows like log T. This runs UCB, CUCB and CTS on I2 to a horizon
with 400 checkpoints (half of them log-spaced) on the GPU, prints the regret at each decade
and UCB's growth per unit of ln T, and draws the curves (mean and 95% CI, log T axis) against
the theorem bounds.

The horizon is --horizon, or, with --budget SECONDS, the longest of 1, 2 and 5 times a power
of ten that a pilot run (the same runs to --pilot slots) says fits in that many seconds; the
output says which, and from what.

    python benchmarks/gpu_asymptotics.py --runs 10000 --horizon 1000000000 -o asymptotics.png
    python benchmarks/gpu_asymptotics.py --runs 10000 --budget 60 -o asymptotics.png
    python benchmarks/gpu_asymptotics.py --device emulate --runs 200 --horizon 1000000 \\
        -o asymptotics.png                          # the same on the CPU, shorter

Needs matplotlib for the figure.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

POLICIES = ("ucb", "cucb", "cts")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", choices=("cuda", "emulate"), default="cuda")
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--horizon", type=int, default=None, help="default 1e9 (or from --budget)")
    ap.add_argument("--budget", type=float, default=None,
                    help="seconds: choose the horizon from a pilot run")  # fmt: skip
    ap.add_argument("--pilot", type=int, default=20_000, help="slots of the pilot run")
    ap.add_argument("-o", "--output", default="asymptotics.png")
    ap.add_argument("--json", default=None, help="write the curves into this file as well")
    args = ap.parse_args()
    if args.horizon is not None and args.budget is not None:
        ap.error("give --horizon or --budget, not both")
    os.environ["CORRAOI_GPU_DEVICE"] = args.device

    from corraoi.experiments.montecarlo import default_checkpoints
    from corraoi.gpu import get_device
    from corraoi.gpu.runner import simulate
    from corraoi.model.bounds import cts_bound, cucb_bound
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy

    dev = get_device()
    inst = load_instance("I2")

    def run(name: str, T: int):  # type: ignore[no-untyped-def]
        return simulate(inst, make_policy(name), seed0=0, runs=args.runs, horizon=T,
                        checkpoints=default_checkpoints(T, 400), device=dev)  # fmt: skip

    if args.budget is not None:
        T, note = _choose_horizon(run, args.budget, args.pilot)
    else:
        T = args.horizon if args.horizon is not None else 1_000_000_000
        note = "given"
    print(f"device: {dev.name}; I2, {args.runs} runs; horizon T = {T:.3g} ({note})", flush=True)
    curves = {}
    for name in POLICIES:
        start = time.perf_counter()
        r = run(name, T)
        wall = time.perf_counter() - start
        curves[name] = (r.t, r.regret.mean, np.nan_to_num(r.regret.ci95()))
        print(f"{name}: {wall:.1f} s ({args.runs * T / wall:.3g} run-slots/s)", flush=True)
    decades = [10**k for k in range(2, int(math.log10(T)) + 1)]
    print("\n| policy | " + " | ".join(f"T = {d:.0e}" for d in decades) + " |")
    print("|---|" + "---:|" * len(decades))
    for name, (t, mean, half) in curves.items():
        cells = []
        for d in decades:
            i = min(int(np.searchsorted(t, d)), len(t) - 1)
            cells.append(f"{mean[i]:.1f} +- {half[i]:.1f}")
        print(f"| {name} | " + " | ".join(cells) + " |")
    t, mean, _ = curves["ucb"]
    late = t >= max(t[-1] / 1000, 100)
    slope = np.polyfit(np.log(t[late]), mean[late], 1)[0]
    print(f"\nUCB: regret grows by {slope:.1f} per unit of ln T over the last three decades")
    growth = {}
    for name in ("cucb", "cts"):
        t, mean, half = curves[name]
        i = int(np.searchsorted(t, t[-1] / 10))
        growth[name] = float(mean[-1] - mean[i])
        print(f"{name}: regret at T/10 {mean[i]:.2f}, at T {mean[-1]:.2f} "
              f"(growth {growth[name]:.2f})")  # fmt: skip
    if args.json:
        data = {"device": dev.name, "runs": args.runs, "horizon": T, "horizon_from": note,
                "ucb_slope_per_ln_t": float(slope), "growth_t10_to_t": growth,
                "curves": {n: {"t": c[0].tolist(), "mean": c[1].tolist(), "ci95": c[2].tolist()}
                           for n, c in curves.items()}}  # fmt: skip
        tmp = Path(args.json + ".partial")
        tmp.write_text(json.dumps(data) + "\n")
        os.replace(tmp, args.json)
    _draw(curves, args.output, T, cucb_bound, cts_bound, title=f"I2, {args.runs} runs, "
          f"{dev.name}")  # fmt: skip
    print(f"wrote {args.output}")


def _choose_horizon(run, budget: float, pilot: int) -> tuple[int, str]:  # type: ignore[no-untyped-def]
    """The longest 1, 2 or 5 x 10^k slots that the pilot's seconds per slot (the three
    policies together, modules loaded) put within ``budget`` seconds, and how it was found."""
    from corraoi.limits import MAX_HORIZON

    for name in POLICIES:
        run(name, 100)  # modules compiled or loaded, outside the timing
    start = time.perf_counter()
    for name in POLICIES:
        run(name, pilot)
    per_slot = (time.perf_counter() - start) / pilot
    T = pilot
    for k in range(int(math.log10(pilot)), 13):
        for m in (1, 2, 5):
            if pilot <= m * 10**k <= MAX_HORIZON and m * 10**k * per_slot <= budget:
                T = m * 10**k
    return T, (f"the longest 1-2-5 horizon within {budget:g} s at the pilot's "
               f"{per_slot * 1e6:.3g} us a slot for the three policies (pilot: {pilot} slots)")


def _draw(curves, path, T, cucb_bound, cts_bound, *, title):  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from corraoi.model.instance import load_instance
    from corraoi.policies import builtins

    inst = load_instance("I2")
    fig, ax = plt.subplots(figsize=(8, 5), dpi=120)
    for name, (t, mean, half) in curves.items():
        rgb = builtins()[name].color or (0, 0, 0)
        color = tuple(c / 255 for c in rgb)
        ax.plot(t, mean, color=color, label=name)
        ax.fill_between(t, mean - half, mean + half, color=color, alpha=0.2, linewidth=0)
    ts = np.unique(np.geomspace(10, T, 60).astype(np.int64))
    for label, fn, style in (("Theorem 2 (CUCB) bound", cucb_bound, "--"),
                             ("Theorem 3 (CTS) bound", cts_bound, ":")):  # fmt: skip
        vals = [fn(inst, int(x)).value for x in ts]
        ax.plot(ts, vals, style, color="0.3", label=label)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("T (slots)")
    ax.set_ylabel("AoI regret (mean, 95% CI)")
    ax.set_title(f"Regret against log T: {title}")
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(True, which="major", alpha=0.3)
    fig.tight_layout()
    tmp = Path(str(path) + ".partial.png")
    fig.savefig(tmp)
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
