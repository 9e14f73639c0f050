"""Start-up benchmark: what a person waits for, as whole processes (issue 22).

Times each command as a user types it, best of --repeat (and the median), warm kernel cache
unless the row says "empty cache". With ``--baseline DIR`` (another checkout, for example
``git worktree add /tmp/base <commit>``) every command is also timed with that checkout's
code (``checkouts.pythonpath``: its corraoi, recorder and viewer in either layout, never the
installed ones; this checkout's likewise), alternating the two so that both see the same
machine; the table then has a column for each.

    python benchmarks/bench_start.py [--repeat 5] [--baseline /tmp/base | --against REV]
                                     [--skip-cold] [--no-workers] [--only ROW,ROW] [--keep DIR]

``--against REV`` times the code of a git revision (its ``corraoi``, ``recorder`` and
``viewer``, extracted with ``git archive``) as the baseline; that copy is no git checkout, so
its logs record no commit and it never asks git (``--baseline`` with ``git worktree add``
times that too). The order of the checkouts flips
every repeat. Each row is also timed in CPU seconds (user + system of the command and the
processes it waited for), a second table: on a machine that others load, CPU time moves far
less than wall time. ``--keep DIR`` keeps the kernel caches and logs in DIR and reuses them
next time (nothing compiles again; the empty-cache rows still start empty).

``--no-workers`` times every command a second time with ``CORRAOI_WORKERS=0`` (no forked
worker: the Rerun writer of ``record``, the figure drawer of ``sweep -o`` and the log
reader of ``replay`` and ``compare`` do their jobs in the command's own process),
alternating with the default, in a column of its own: what each worker buys.
``--only`` keeps the rows whose name starts with one of the words given.

Python's bytecode is compiled first (``compileall``) for both checkouts, as an installed
package has it: a sandbox with PYTHONDONTWRITEBYTECODE would otherwise pay for parsing
every module in every process.
"""

from __future__ import annotations

import argparse
import compileall
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from checkouts import pythonpath

ROOT = Path(__file__).resolve().parent.parent
PAPER = ["sweep", "-i", "I1", "-p", "all", "--runs", "200", "-T", "10000", "--json"]
BUILTINS = ("ucb,ts,ts-gauss,cucb,cts,cts-gauss,q-ucb,cq-ucb,q-ts,cq-ts,sw-ucb,d-ts,aoi-aware-ucb,"
            "aoi-aware-ts,aoi-aware-ts-gauss,aoi-aware-cucb,aoi-aware-cts,aoi-aware-cts-gauss,"
            "aoi-aware-q-ucb,aoi-aware-cq-ucb,aoi-aware-q-ts,aoi-aware-cq-ts,aoi-aware-sw-ucb,"
            "aoi-aware-d-ts")  # fmt: skip
ALL24 = ["sweep", "-i", "I1", "-p", BUILTINS, "--runs", "20", "-T", "1000", "--json"]


def corraoi(
    root: Path,
    args: list[str],
    cache: Path,
    cwd: Path,
    ok: tuple[int, ...] = (0,),
    env_extra: dict[str, str] | None = None,
) -> tuple[float, float]:
    env = {**os.environ, "PYTHONPATH": pythonpath(root), "CORRAOI_CACHE_DIR": str(cache),
           **(env_extra or {})}  # fmt: skip
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "corraoi.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True)  # fmt: skip
    took = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode not in ok:
        raise SystemExit(f"{root}: corraoi {' '.join(args)} failed:\n{proc.stderr}")
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return took, cpu


def checkout_of(rev: str, into: Path) -> Path:
    """The packages of the git revision ``rev`` extracted into ``into`` (made once)."""
    if not (into / "corraoi").is_dir():
        into.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "corraoi", "recorder",
                                  "viewer"], capture_output=True, check=True)  # fmt: skip
        subprocess.run(["tar", "-x", "-C", str(into)], input=archive.stdout, check=True)
    return into


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--baseline", type=Path, help="another checkout to time beside this one")
    ap.add_argument("--skip-cold", action="store_true", help="leave out the empty-cache rows")
    ap.add_argument("--no-workers", action="store_true",
                    help="also time every command with CORRAOI_WORKERS=0 (no forked worker)")
    ap.add_argument("--only", default="", help="rows whose name starts with these words")
    ap.add_argument("--against", metavar="REV", help="a git revision to time beside this one")
    ap.add_argument("--keep", type=Path, help="keep the caches and logs here, reused next time")
    args = ap.parse_args()
    if args.keep is not None:
        work = args.keep.resolve()
        work.mkdir(parents=True, exist_ok=True)
    else:
        work = Path(tempfile.mkdtemp(prefix="corraoi-bench-start-"))
    if args.against is not None:
        args.baseline = checkout_of(args.against, work / f"rev-{args.against}")
    roots = {"now": ROOT}
    if args.baseline is not None:
        roots = {"before": args.baseline.resolve(), "now": ROOT}
    if args.no_workers:
        roots["no workers"] = ROOT
    envs = {k: ({"CORRAOI_WORKERS": "0"} if k == "no workers" else {}) for k in roots}
    only = tuple(w.strip() for w in args.only.split(",") if w.strip())
    for root in roots.values():
        for pkg in ("corraoi", "recorder", "viewer"):
            compileall.compile_dir(str(root / pkg), quiet=1)
    checkouts = list(dict.fromkeys(roots.values()))  # "now" and "no workers" share one
    caches = {k: work / f"cache-{checkouts.index(root)}" for k, root in roots.items()}
    rows: dict[str, dict[str, list[float]]] = {}
    cpus: dict[str, dict[str, list[float]]] = {}

    def add(row: str, key: str, seconds: tuple[float, float]) -> None:
        rows.setdefault(row, {}).setdefault(key, []).append(seconds[0])
        cpus.setdefault(row, {}).setdefault(key, []).append(seconds[1])

    def order(i: int) -> list[tuple[str, Path]]:
        """The checkouts in the order of repeat ``i``: flipped every repeat."""
        pairs = list(roots.items())
        return pairs if i % 2 == 0 else pairs[::-1]

    try:
        if not args.skip_cold and not only:
            for i in range(max(1, args.repeat // 2)):
                for key, root in order(i):
                    cold = work / f"cold-{key}"
                    shutil.rmtree(cold, ignore_errors=True)
                    add("first record --policy cucb (empty cache)", key,
                        corraoi(root, ["record", "--policy", "cucb", "-o", "c.mcap", "--force"],
                                cold, work))  # fmt: skip
                    add("then the paper workload (same cache)", key,
                        corraoi(root, PAPER, cold, work))  # fmt: skip
                    shutil.rmtree(cold, ignore_errors=True)
                    add("paper workload (empty cache)", key, corraoi(root, PAPER, cold, work))
                    shutil.rmtree(cold, ignore_errors=True)
                    add("all 24 built-ins (empty cache)", key, corraoi(root, ALL24, cold, work))
                    shutil.rmtree(cold, ignore_errors=True)
        for key, root in roots.items():  # warm each cache and make the logs
            name = key.replace(" ", "-")
            if key == next(k for k in roots if roots[k] == root):  # once per cache
                corraoi(root, ALL24, caches[key], work)
            for pol in ("ucb", "cucb"):
                corraoi(root, ["record", "--policy", pol, "-T", "3000", "-o", f"{pol}-{name}.mcap",
                               "--no-rrd", "--force"], caches[key], work)  # fmt: skip
        commands = {
            "record --policy cucb (10,000 slots, MCAP + .rrd)":
                lambda k: ["record", "--policy", "cucb", "-o", f"q-{k}.mcap", "--force"],
            "record -T 10 --no-rrd":
                lambda k: ["record", "--policy", "cucb", "-T", "10", "--no-rrd",
                           "-o", f"n-{k}.mcap", "--force"],
            "info (3,000-slot log)": lambda k: ["info", f"cucb-{k}.mcap"],
            "diff (two 3,000-slot logs)":
                lambda k: ["diff", f"ucb-{k}.mcap", f"cucb-{k}.mcap"],
            "replay to .rrd": lambda k: ["replay", f"cucb-{k}.mcap", "-o", f"r-{k}.rrd",
                                         "--force"],
            "compare to .rrd": lambda k: ["compare", f"ucb-{k}.mcap", f"cucb-{k}.mcap",
                                          "-o", f"c-{k}.rrd", "--force"],
            "paper workload": lambda k: PAPER,
            "sweep -o, small (2 policies x 40 runs x 500 slots)":
                lambda k: ["sweep", "-p", "ucb,cucb", "-n", "40", "-T", "500",
                           "-o", f"s-{k}", "--force"],
            "sweep --policy all -o (the README's)":
                lambda k: ["sweep", "--policy", "all", "-o", f"a-{k}", "--force"],
            "--help": lambda k: ["--help"],
        }  # fmt: skip
        if only:
            commands = {r: m for r, m in commands.items() if r.startswith(only)}
        for i in range(args.repeat):
            for row, make in commands.items():
                for key, root in order(i):
                    ok = (0, 1) if row.startswith("diff") else (0,)  # diff: 1 = they differ
                    name = key.replace(" ", "-")
                    add(row, key, corraoi(root, make(name), caches[key], work, ok=ok,
                                          env_extra=envs[key]))  # fmt: skip
    finally:
        if args.keep is None:
            shutil.rmtree(work, ignore_errors=True)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"\nwhole processes, {cores} cores, best of {args.repeat} (median in brackets); "
          "empty-cache rows best of " + str(max(1, args.repeat // 2)))  # fmt: skip
    for title, table in (("wall seconds", rows), ("CPU seconds", cpus)):
        head = f"{'what the user does (' + title + ')':50s}" + "".join(f" {k:>17s}" for k in roots)
        print(head)
        print("-" * len(head))
        for row, per in table.items():
            cells = "".join(
                f" {min(per[k]):7.2f} s ({statistics.median(per[k]):5.2f})" for k in roots
            )
            print(f"{row:50s}{cells}")
        print()


if __name__ == "__main__":
    main()
