"""Engine benchmark: the paper's workload, the wide instance, and plain-Python plug-ins.

Prints four tables:

1. per policy, the paper's workload in-process (I1, 200 runs, T = 10,000; best of --repeat),
   and a compiled plug-in (tests/plugins/compiled_greedy.py, UCB with a bonus);
2. the paper workload as whole processes, ``corraoi sweep --instance I1 --policy all --runs 200
   --horizon 10000 --json`` (best of --repeat, warm kernel cache), and start-up (the same
   command with one run of one slot);
3. the wide instance (K = 256, n = 1024, pinned), 50 runs, T = 2000: CUCB against UCB and CTS
   against TS on the same work;
4. a plain-Python plug-in (tests/plugins/eps_greedy.py) in ``sweep`` on I1 with 200 runs;

then peak memory (max RSS of a fresh process) at T = 10,000 and 1,000,000.

    python benchmarks/bench_engine.py [--runs 200] [--horizon 10000] [--repeat 5]

With ``--against REV`` it prints one table instead: table 1's rows (the paper's twelve, their
total, and the compiled plug-in) for the code at REV (``git archive`` into a temporary
folder, its own kernel cache; or REV a folder holding that code's ``corraoi/``, with its
``recorder/`` and ``viewer/``; run by ``checkouts.pythonpath``, never the installed code) and for
this checkout, each side in fresh processes that alternate (before, after, after, before,
...), ``--repeat`` of each, best per row: what a change to the engine costs
(docs/performance.md, the hook checks of issue 32).

    python benchmarks/bench_engine.py --against HEAD~1 --repeat 7

``--instance k16`` runs that table on bench_sources.py's pinned instance of 16 channels
instead of I1 (or any instance name or file ``load_instance`` reads): where the correlated
policies' candidate set costs most.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from checkouts import MAPPED, pythonpath

ROOT = Path(__file__).resolve().parent.parent
PLUGIN = ROOT / "tests" / "plugins" / "eps_greedy.py"
#: A compiled plug-in (UCB with a bonus): its hooks go through the kernel as a user's do.
COMPILED = f"{ROOT / 'tests' / 'plugins' / 'compiled_greedy.py'}:BonusUCB"


def per_policy(runs: int, horizon: int, repeat: int, extra: bool) -> None:
    from corraoi.engine.simulation import Simulation
    from corraoi.engine.threads import set_workers
    from corraoi.model.instance import load_instance
    from corraoi.policies import builtins, make_policy, paper_names

    inst = load_instance("I1")
    workers = set_workers(None)
    names = [*(builtins() if extra else paper_names()), COMPILED]
    times: dict[str, list[float]] = {n: [] for n in names}
    for _ in range(repeat):
        for name in names:
            sim = Simulation(inst, make_policy(name), range(runs), horizon)
            s = time.perf_counter()
            sim.advance(horizon, record=False)
            times[name].append(time.perf_counter() - s)
    run_slots = runs * horizon
    print(f"\n1. per policy: I1, {runs} runs, horizon {horizon}, {workers} threads, best of "
          f"{repeat} (spread: max/min - 1 over the repeats)")  # fmt: skip
    print(f"{'policy':22s} {'wall s':>8} {'run-slots/s':>14} {'spread':>7}")
    best = {n: min(v) for n, v in times.items()}
    for name, dt in best.items():
        spread = max(times[name]) / dt - 1
        label = "compiled plug-in" if name == COMPILED else name
        print(f"{label:22s} {dt:8.3f} {run_slots / dt:14,.0f} {spread:6.0%}")
    paper = [best[n] for n in paper_names()]
    print(f"{'total (paper twelve)':22s} {sum(paper):8.3f} "
          f"{run_slots * len(paper) / sum(paper):14,.0f}")  # fmt: skip


#: One side's timings, in a fresh process: each policy's ``advance`` over every run (its
#: kernel loaded first, so that neither compiling nor loading is counted).
_SIDE = (
    "import json, sys, time\n"
    "from corraoi.engine.simulation import Simulation\n"
    "from corraoi.engine.threads import set_workers\n"
    "from corraoi.model.instance import load_instance\n"
    "from corraoi.policies import make_policy\n"
    "names, runs, horizon = json.loads(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])\n"
    "if sys.argv[4] == 'k16':\n"
    "    sys.path.insert(0, sys.argv[5])\n"
    "    from bench_sources import instance_k16\n"
    "    inst = instance_k16()\n"
    "else:\n"
    "    inst = load_instance(sys.argv[4])\n"
    "set_workers(None)\n"
    "out = {}\n"
    "for name in names:\n"
    "    Simulation(inst, make_policy(name), range(2), 2).advance(2, record=False)\n"
    "    best = [float('inf'), float('inf')]\n"
    "    for _ in range(3):\n"
    "        sim = Simulation(inst, make_policy(name), range(runs), horizon)\n"
    "        s, c = time.perf_counter(), time.process_time()\n"
    "        sim.advance(horizon, record=False)\n"
    "        s, c = time.perf_counter() - s, time.process_time() - c\n"
    "        best = [min(best[0], s), min(best[1], c)]\n"
    "    out[name] = best\n"
    "import corraoi\n"
    "print(json.dumps({'code': corraoi.__file__, 'times': out}))\n"
)


def against(rev: str, runs: int, horizon: int, repeat: int, instance: str = "I1") -> None:
    """Table 1 for the code at ``rev`` and for this checkout, alternated (module docstring)."""
    from corraoi.policies import paper_names

    names = [*paper_names(), COMPILED]
    tmp = Path(tempfile.mkdtemp(prefix="corraoi-bench-"))
    if Path(rev, "corraoi").is_dir():  # a folder that holds the other code's corraoi/
        for pkg in ("corraoi", *MAPPED):
            if Path(rev, pkg).is_dir():
                shutil.copytree(Path(rev, pkg), tmp / pkg)
    else:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "corraoi", *MAPPED],
                                 capture_output=True, check=True)  # fmt: skip
        subprocess.run(["tar", "-x", "-C", str(tmp)], input=archive.stdout, check=True)
    sides = {"before": (tmp, tmp / "cache"), "after": (ROOT, ROOT / ".cache-corraoi")}
    # each side starts in an empty folder: python -c puts its working folder first on
    # sys.path, and a folder holding the other side's corraoi/ would be imported instead
    # (both sides then timed the same code)
    empty = tmp / "cwd"
    empty.mkdir()

    def run(side: str) -> dict[str, list[float]]:
        path, cache = sides[side]
        env = {**os.environ, "PYTHONPATH": pythonpath(path), "CORRAOI_CACHE_DIR": str(cache)}
        out = subprocess.run([sys.executable, "-c", _SIDE, json.dumps(names), str(runs),
                              str(horizon), instance, str(Path(__file__).parent)], env=env,
                             capture_output=True, text=True, check=True, cwd=empty)  # fmt: skip
        found = json.loads(out.stdout.splitlines()[-1])
        code = Path(found["code"]).resolve()
        if not code.is_relative_to(path.resolve()):
            raise SystemExit(f"the {side} side ran {code}, not the code in {path}")
        times: dict[str, list[float]] = found["times"]
        return times

    run("before")  # both kernel caches warm: nothing below compiles
    run("after")
    times: dict[str, dict[str, list[list[float]]]] = {s: {n: [] for n in names} for s in sides}
    for i in range(repeat):
        for side in ("before", "after") if i % 2 == 0 else ("after", "before"):
            for name, dt in run(side).items():
                times[side][name].append(dt)
    # per row: the best wall time and the best CPU time (every thread's) of the repeats
    best = {s: {n: [min(v[0] for v in t[n]), min(v[1] for v in t[n])] for n in names}
            for s, t in times.items()}  # fmt: skip
    print(f"\nthe engine at {rev} (before) and this checkout (after): {instance}, {runs} runs, "
          f"horizon {horizon}, fresh processes alternated, best of {repeat} each (each the "
          "best of 3 advances in its process); wall and CPU seconds (CPU: every thread's, "
          "which a loaded machine disturbs less)")  # fmt: skip
    print(f"{'policy':22s} {'wall before':>11} {'after':>7} {'ratio':>6} {'CPU before':>11} "
          f"{'after':>7} {'ratio':>6}")  # fmt: skip
    rows = [(n, best["before"][n], best["after"][n]) for n in names if n != COMPILED]
    total = ("paper workload (total)", [sum(r[1][i] for r in rows) for i in (0, 1)],
             [sum(r[2][i] for r in rows) for i in (0, 1)])  # fmt: skip
    plugin = ("compiled plug-in", best["before"][COMPILED], best["after"][COMPILED])
    for name, b, a in [*rows, total, plugin]:
        print(f"{name:22s} {b[0]:11.3f} {a[0]:7.3f} {a[0] / b[0]:6.3f} {b[1]:11.3f} "
              f"{a[1]:7.3f} {a[1] / b[1]:6.3f}")  # fmt: skip


def whole_process(runs: int, horizon: int, repeat: int) -> None:
    exe = [sys.executable, "-m", "corraoi", "sweep", "--instance", "I1", "--policy", "all",
           "--json"]  # fmt: skip

    def timed(args: list[str]) -> float:
        s = time.perf_counter()
        subprocess.run(exe + args, check=True, capture_output=True)
        return time.perf_counter() - s

    timed(["--runs", "1", "--horizon", "1"])  # warm the kernel cache
    work = [timed(["--runs", str(runs), "--horizon", str(horizon)]) for _ in range(repeat)]
    start = [timed(["--runs", "1", "--horizon", "1"]) for _ in range(repeat)]
    print(f"\n2. whole process: corraoi sweep --instance I1 --policy all --runs {runs} "
          f"--horizon {horizon} --json (best of {repeat}, warm kernel cache)")  # fmt: skip
    print(f"{'what':40s} {'best s':>7} {'median s':>9}")
    print(f"{'paper workload':40s} {min(work):7.2f} {statistics.median(work):9.2f}")
    print(f"{'start-up (1 run of 1 slot)':40s} {min(start):7.2f} {statistics.median(start):9.2f}")


def wide(repeat: int) -> None:
    import numpy as np

    from corraoi.engine.simulation import Simulation
    from corraoi.model.instance import Instance
    from corraoi.policies import make_policy

    rng = np.random.default_rng(1)
    p = rng.dirichlet(np.ones(1024))
    Y = rng.random((256, 1024)) < 0.3
    inst = Instance("wide", p, Y.astype(np.int64))
    runs, T = 50, 2000
    best: dict[str, float] = {}
    for _ in range(repeat):
        for name in ("ucb", "cucb", "ts", "cts"):
            sim = Simulation(inst, make_policy(name), range(runs), T)
            s = time.perf_counter()
            sim.advance(T, record=False)
            best[name] = min(best.get(name, float("inf")), time.perf_counter() - s)
    print(f"\n3. wide instance (K = 256, n = 1024), {runs} runs, T = {T}, best of {repeat}")
    print(f"{'policy':10s} {'wall s':>8}  ratio")
    for a, b in (("ucb", "cucb"), ("ts", "cts")):
        print(f"{a:10s} {best[a]:8.3f}")
        print(f"{b:10s} {best[b]:8.3f}  {best[b] / best[a]:.2f} x {a} (target <= 1.5)")


def python_tier(runs: int, horizon: int, repeat: int) -> None:
    from corraoi.experiments.montecarlo import default_checkpoints, run_sweep
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policies

    spec = make_policies([f"{PLUGIN}:EpsilonGreedy"])
    inst = load_instance("I1")
    best = float("inf")
    for _ in range(repeat):
        s = time.perf_counter()
        run_sweep(inst, spec, runs=runs, horizon=horizon,
                  checkpoints=default_checkpoints(horizon))  # fmt: skip
        best = min(best, time.perf_counter() - s)
    print(f"\n4. plain-Python plug-in (eps_greedy.py) in sweep: I1, {runs} runs, T = {horizon},"
          f" best of {repeat}")  # fmt: skip
    print(f"wall {best:.3f} s, {runs * horizon / best:,.0f} run-slots/s (target >= 1,000,000)")


def peak_rss(horizon: int, runs: int, policies: str) -> float:
    code = (
        "import resource, sys\n"
        "from corraoi.model.instance import load_instance\n"
        "from corraoi.policies import make_policies\n"
        "from corraoi.experiments.montecarlo import run_sweep\n"
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
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--all-builtins", action="store_true", help="table 1 for every built-in")
    ap.add_argument("--memory-policies", default="ucb,cts")
    ap.add_argument("--skip-memory", action="store_true")
    ap.add_argument("--against", metavar="REV", default=None,
                    help="only: table 1 for the code at REV and this checkout, alternated")
    ap.add_argument("--instance", default="I1",
                    help="with --against: the instance (a name or file, or k16: "
                         "bench_sources.py's 16 channels)")  # fmt: skip
    args = ap.parse_args()
    load = os.getloadavg()[0]
    print(f"machine: {os.cpu_count()} cores, Python {sys.version.split()[0]}, "
          f"load average {load:.2f} at start")  # fmt: skip
    if args.against is not None:
        against(args.against, args.runs, args.horizon, args.repeat, args.instance)
        print(f"load average {os.getloadavg()[0]:.2f} at the end")
        return
    per_policy(args.runs, args.horizon, args.repeat, args.all_builtins)
    whole_process(args.runs, args.horizon, args.repeat)
    wide(args.repeat)
    python_tier(args.runs, args.horizon, args.repeat)
    if not args.skip_memory:
        small = peak_rss(10_000, args.runs, args.memory_policies)
        large = peak_rss(1_000_000, args.runs, args.memory_policies)
        print(
            f"\npeak memory ({args.memory_policies}, {args.runs} runs): T=10,000 {small:.1f} "
            f"MiB, T=1,000,000 {large:.1f} MiB, ratio {large / small:.3f}"
        )


if __name__ == "__main__":
    main()
