"""Benchmark of the viewer: replay, compare, diff and info against the floor of decoding.

    python benchmarks/bench_replay.py [--slots 100000] [--runs 12] [--run-slots 10000]
                                      [--arms K] [--baseline DIR [--rounds 3]]

Records (untimed) one ``--slots`` log of cucb on I1 and ``--runs`` logs of ``--run-slots``
slots (the twelve policies, one seed), then times, best of ``--repeat``
interleaved rounds:

* the floor: every message of the long log read with ``mcap.stream_reader.StreamReader``
  and decoded with ``orjson.loads`` (nothing else);
* ``corraoi.viewer.replay`` of the long log to an .rrd (read, check, decode, RerunSink, file),
  with its ratio to the floor (target: at most 1.5);
* ``corraoi.viewer.compare`` of the short logs into one .rrd (target: under 2 s), and the same
  two commands end to end as ``corraoi`` processes (interpreter and imports included);
* ``corraoi.viewer.diff`` and ``corraoi.viewer.info.log_info`` of the long log, for reference.

``--arms K``: the logs are of an instance of K arms (benchmarks/alternate.py).
``--baseline DIR``: this checkout and another one, alternately, side by side (issue 35:
replay within 5% of 224f28d at K = 4, at most 1.5x at K = 256).

A benchmark, not a test: it prints a table and never fails on a number.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import orjson
from alternate import alternate, instance_for, print_comparison
from mcap.records import Message
from mcap.stream_reader import StreamReader

POLICIES = (
    "ucb", "ts", "ts-gauss", "cucb", "cts", "cts-gauss",
    "aoi-aware-ucb", "aoi-aware-ts", "aoi-aware-ts-gauss",
    "aoi-aware-cucb", "aoi-aware-cts", "aoi-aware-cts-gauss",
)  # fmt: skip


def record(path: Path, policy: str, horizon: int, seed: int = 0, arms: int = 4) -> Path:
    from corraoi.engine.block import RunConfig
    from corraoi.engine.simulation import simulate_run
    from corraoi.policies import make_policy
    from corraoi.recorder.slotlog.sink import McapSink

    config = RunConfig(instance_for(arms), make_policy(policy), seed, horizon)
    with McapSink(path, config, overwrite=True, fsync=False) as sink:
        for block in simulate_run(config.instance, config.policy, seed, horizon):
            sink.write(block)
    return path


def floor(path: Path) -> int:
    """Read and decode every message: the least any replay has to do."""
    n = 0
    loads = orjson.loads
    with path.open("rb") as f:
        for rec in StreamReader(f).records:
            if isinstance(rec, Message):
                loads(rec.data)
                n += 1
    return n


def best(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """(wall, CPU) seconds of the fastest of ``repeat`` calls.

    CPU counts every thread and the reader processes that replay and compare fork.
    """
    runs = []
    for _ in range(repeat):
        wall, before = time.perf_counter(), os.times()
        fn()
        after = os.times()
        cpu = sum(b - a for a, b in zip(before[:4], after[:4], strict=True))
        runs.append((time.perf_counter() - wall, cpu))
    return min(runs)


def cli(args: list[str], cwd: Path) -> tuple[float, float]:
    exe = [sys.executable, "-m", "corraoi.cli"]
    start, before = time.perf_counter(), os.times()
    res = subprocess.run([*exe, *args], cwd=cwd, capture_output=True, text=True)
    wall, after = time.perf_counter() - start, os.times()
    if res.returncode != 0:
        raise SystemExit(f"corraoi {' '.join(args)} failed: {res.stderr}")
    cpu = (after.children_user - before.children_user) + (
        after.children_system - before.children_system
    )
    return wall, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--slots", type=int, default=100_000)
    ap.add_argument("--runs", type=int, default=12)
    ap.add_argument("--run-slots", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--arms", type=int, default=4, help="K: the instance's arms [4: I1]")
    ap.add_argument("--baseline", type=Path, help="another checkout to time beside this one")
    ap.add_argument("--rounds", type=int, default=3, help="with --baseline: rounds of each")
    ap.add_argument("--json", action="store_true", help="print the times as one JSON object")
    ap.add_argument("--only", help="with --json or --baseline: only these rows (comma list: "
                    "replay, compare, diff, info, cli replay, cli compare)")  # fmt: skip
    opts = ap.parse_args()
    if opts.only and not (opts.json or opts.baseline):
        ap.error("--only goes with --json or --baseline")
    os.environ.setdefault("RUST_LOG", "off")
    if opts.baseline is not None:
        with tempfile.TemporaryDirectory(prefix="bench-replay-base-") as work:
            both = alternate(Path(__file__), [
                "--slots", str(opts.slots), "--runs", str(opts.runs), "--run-slots",
                str(opts.run_slots), "--repeat", str(opts.repeat), "--arms", str(opts.arms),
                *(["--only", opts.only] if opts.only else []),
            ], opts.baseline, opts.rounds, Path(work))  # fmt: skip
        print(f"viewer: {opts.arms} arms ({instance_for(opts.arms).name}), replay of "
              f"{opts.slots:,} slots, compare of {opts.runs} x {opts.run_slots:,}; best of "
              f"{opts.rounds} rounds x {opts.repeat}; times per slot of the long log")
        print_comparison(both, opts.slots, "us/slot", opts.baseline)
        return

    # submodules, not ``import corraoi.viewer``: an editable install made before the packages had
    # an __init__.py maps them as namespace packages outside the checkout
    from corraoi.viewer.compare import compare
    from corraoi.viewer.diffs import diff
    from corraoi.viewer.info import log_info
    from corraoi.viewer.replay import replay

    with tempfile.TemporaryDirectory(prefix="bench-replay-") as tmp:
        d = Path(tmp)
        long_log = record(d / "long.mcap", "cucb", opts.slots, arms=opts.arms)
        short = [
            record(d / f"{i:02d}-{POLICIES[i % 12]}.mcap", POLICIES[i % 12], opts.run_slots,
                   arms=opts.arms)  # fmt: skip
            for i in range(opts.runs)
        ]
        n = floor(long_log)
        tasks: dict[str, Callable[[], object]] = {
            "floor": lambda: floor(long_log),
            "replay": lambda: replay(long_log, rrd_path=d / "replay.rrd", overwrite=True),
            "compare": lambda: compare(short, rrd_path=d / "compare.rrd", overwrite=True),
            "diff": lambda: diff(long_log, long_log),
            "info": lambda: log_info(long_log),
        }
        keep = [w.strip() for w in (opts.only or "").split(",") if w.strip()]
        if keep:  # a few rows, for many rounds (the floor is always timed)
            tasks = {k: f for k, f in tasks.items() if k == "floor" or k in keep}
        # interleaved rounds: every task sees the same machine (other processes come and go)
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in tasks}
        for _ in range(opts.repeat):
            for name, fn in tasks.items():
                times[name].append(best(fn, 1))
            if not keep or "cli replay" in keep:
                times.setdefault("cli replay", []).append(
                    cli(["replay", str(long_log), "--rrd", str(d / "cli.rrd"), "--force"], d)
                )
            if not keep or "cli compare" in keep:
                times.setdefault("cli compare", []).append(cli(
                    ["compare", *map(str, short), "-o", str(d / "cli-compare.rrd"), "--force"], d
                ))  # fmt: skip
        t = {k: min(v) for k, v in times.items()}
        f_wall, f_cpu = t["floor"]
        if opts.json:  # wall seconds, and CPU seconds (every thread and reader process)
            print(json.dumps({**{k: v[0] for k, v in t.items()},
                              **{f"{k} [CPU]": v[1] for k, v in t.items()}}))  # fmt: skip
            return

        def ratio(x: tuple[float, float]) -> str:
            return f"{x[0] / f_wall:.2f} x floor ({x[1] / f_cpu:.2f} x in CPU time)"

        rows: list[tuple[str, tuple[float, float], str]] = [
            (f"floor: StreamReader + orjson, {n:,} msgs", t["floor"],
             f"{f_wall / n * 1e6:.2f} us/msg"),
            (f"replay {opts.slots:,} slots -> .rrd", t["replay"],
             ratio(t["replay"]) + ", target <= 1.5"),
            (f"compare {opts.runs} x {opts.run_slots:,} slots -> .rrd", t["compare"],
             "target < 2 s"),
            (f"diff {opts.slots:,} slots (log with itself)", t["diff"], ratio(t["diff"])),
            (f"info {opts.slots:,} slots", t["info"], ratio(t["info"])),
            ("corraoi replay (process, end to end)", t["cli replay"], "imports included"),
            ("corraoi compare (process, end to end)", t["cli compare"], "imports included"),
        ]  # fmt: skip

    print(f"{'what':<44} {'wall s':>7} {'CPU s':>7}  note")
    for what, (wall, cpu), note in rows:
        print(f"{what:<44} {wall:7.3f} {cpu:7.3f}  {note}")
    print(
        f"({os.cpu_count()} cores, Python {platform.python_version()}, best of {opts.repeat}; "
        f"load average {os.getloadavg()[0]:.2f})"
    )


if __name__ == "__main__":
    main()
