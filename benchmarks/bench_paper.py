"""The full reproduction of the paper's simulations, timed end to end.

Runs ``corraoi reproduce`` (I1 and I2, all twelve policies, 200 runs, horizon 10,000; the
logs, summaries and figures) in a fresh process, as a user would, and prints the wall time
of the whole command and of each stage it reports.

    python benchmarks/bench_paper.py [--runs 200] [--horizon 10000] [--repeat 3]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def once(runs: int, horizon: int, out: Path) -> float:
    cmd = [sys.executable, "-m", "corraoi.cli", "reproduce", "-o", str(out), "--force",
           "--runs", str(runs), "--horizon", str(horizon)]  # fmt: skip
    start = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--horizon", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="corraoi-paper-"))
    try:
        times = [once(args.runs, args.horizon, tmp / "paper") for _ in range(args.repeat)]
        sizes = {p.relative_to(tmp / "paper"): p.stat().st_size
                 for p in sorted((tmp / "paper").rglob("*")) if p.is_file()}  # fmt: skip
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}")
    print(f"corraoi reproduce: I1 + I2, 12 policies, {args.runs} runs, horizon {args.horizon},"
          " logs + summaries + figures, fresh process each time")  # fmt: skip
    print(f"{'run':>5} {'wall s':>8}")
    for i, t in enumerate(times, start=1):
        print(f"{i:>5} {t:8.2f}")
    print(f"{'best':>5} {min(times):8.2f}")
    print("files written:")
    for name, size in sizes.items():
        print(f"  {str(name):20s} {size / 1024:9.1f} KiB")


if __name__ == "__main__":
    main()
