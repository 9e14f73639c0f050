"""The paper's asymptotics on I2 (C = 0), checked with the GPU backend (docs/gpu.md).

Theorems 2 and 3: with no competitive sub-optimal arm, the regret of CUCB and CTS stays
bounded (O(1)) while UCB's grows like log T. This sweeps UCB, CUCB and CTS on I2 to --horizon
with log-spaced checkpoints on the GPU, prints the regret at each decade and UCB's growth per
unit of ln T, and draws the curves (mean and 95% CI, log T axis) against the theorem bounds.

    python benchmarks/gpu_asymptotics.py --runs 10000 --horizon 1000000000 -o asymptotics.png
    python benchmarks/gpu_asymptotics.py --device emulate --runs 200 --horizon 1000000 \\
        -o asymptotics.png                          # the same on the CPU, shorter

Needs the plot and analysis extras (matplotlib, pandas).
"""

from __future__ import annotations

import argparse
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
    ap.add_argument("--horizon", type=int, default=1_000_000_000)
    ap.add_argument("-o", "--output", default="asymptotics.png")
    ap.add_argument("--folder", default="asymptotics-sweep", help="the sweep folder it writes")
    args = ap.parse_args()
    os.environ["CORRAOI_GPU_DEVICE"] = args.device

    import corraoi
    from corraoi.experiments.grid import build_grid
    from corraoi.experiments.sweeps import sweep
    from corraoi.gpu import get_device
    from corraoi.model.bounds import cts_bound, cucb_bound

    T = args.horizon
    grid = build_grid(instances=["I2"], policies=list(POLICIES), horizons=[T], runs=args.runs,
                      checkpoints=400, backend="gpu")  # fmt: skip
    folder = Path(args.folder)
    start = time.perf_counter()
    sweep(grid, out=folder, force=True)
    wall = time.perf_counter() - start
    print(f"device: {get_device().name}; {args.runs} runs x T = {T:.3g} x {len(POLICIES)} "
          f"policies in {wall:.1f} s (sweep folder {folder})")  # fmt: skip
    table = corraoi.load(folder).curves
    curves = {}
    for name in POLICIES:
        rows = table[table["policy"] == name].sort_values("t")
        curves[name] = (rows["t"].to_numpy(), rows["regret_mean"].to_numpy(),
                        rows["regret_ci95"].fillna(0.0).to_numpy())  # fmt: skip
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
    for name in ("cucb", "cts"):
        t, mean, half = curves[name]
        i = int(np.searchsorted(t, t[-1] / 10))
        print(f"{name}: regret at T/10 {mean[i]:.2f}, at T {mean[-1]:.2f} "
              f"(growth {mean[-1] - mean[i]:.2f})")  # fmt: skip
    _draw(curves, args.output, T, cucb_bound, cts_bound, title=f"I2, {args.runs} runs, "
          f"{get_device().name}")  # fmt: skip
    print(f"wrote {args.output}")


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
    fig.savefig(path)


if __name__ == "__main__":
    main()
