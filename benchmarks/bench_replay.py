"""Benchmark of the viewer: replay, compare, diff and info against the floor of decoding.

    python benchmarks/bench_replay.py [--slots 100000] [--runs 12] [--run-slots 10000]

Records (untimed) one ``--slots`` log of cucb on I1 and ``--runs`` logs of ``--run-slots``
slots (the twelve policies, one seed), then times, best of ``--repeat``
interleaved rounds:

* the floor: every message of the long log read with ``mcap.stream_reader.StreamReader``
  and decoded with ``orjson.loads`` (nothing else);
* ``viewer.replay`` of the long log to an .rrd (read, check, decode, RerunSink, file),
  with its ratio to the floor (target: at most 1.5);
* ``viewer.compare`` of the short logs into one .rrd (target: under 2 s), and the same
  two commands end to end as ``corraoi`` processes (interpreter and imports included);
* ``viewer.diff`` and ``viewer.log_info`` of the long log, for reference.

A benchmark, not a test: it prints a table and never fails on a number.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import orjson
from mcap.records import Message
from mcap.stream_reader import StreamReader

POLICIES = (
    "ucb", "ts", "ts-gauss", "cucb", "cts", "cts-gauss",
    "aoi-aware-ucb", "aoi-aware-ts", "aoi-aware-ts-gauss",
    "aoi-aware-cucb", "aoi-aware-cts", "aoi-aware-cts-gauss",
)  # fmt: skip


def record(path: Path, policy: str, horizon: int, seed: int = 0) -> Path:
    from corraoi.engine.block import RunConfig
    from corraoi.engine.simulation import simulate_run
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy
    from recorder.slotlog.sink import McapSink

    config = RunConfig(load_instance("I1"), make_policy(policy), seed, horizon)
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
    opts = ap.parse_args()
    os.environ.setdefault("RUST_LOG", "off")

    # submodules, not ``import viewer``: an editable install made before the packages had
    # an __init__.py maps them as namespace packages outside the checkout
    from viewer.compare import compare
    from viewer.diffs import diff
    from viewer.info import log_info
    from viewer.replay import replay

    with tempfile.TemporaryDirectory(prefix="bench-replay-") as tmp:
        d = Path(tmp)
        long_log = record(d / "long.mcap", "cucb", opts.slots)
        short = [
            record(d / f"{i:02d}-{POLICIES[i % 12]}.mcap", POLICIES[i % 12], opts.run_slots)
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
        # interleaved rounds: every task sees the same machine (other processes come and go)
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in tasks}
        for _ in range(opts.repeat):
            for name, fn in tasks.items():
                times[name].append(best(fn, 1))
            times.setdefault("cli replay", []).append(
                cli(["replay", str(long_log), "--rrd", str(d / "cli.rrd"), "--force"], d)
            )
            times.setdefault("cli compare", []).append(
                cli(["compare", *map(str, short), "-o", str(d / "cli-compare.rrd"), "--force"], d)
            )
        t = {k: min(v) for k, v in times.items()}
        f_wall, f_cpu = t["floor"]

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
