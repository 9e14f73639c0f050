"""Recorder benchmark: ``corraoi record`` throughput and memory (cucb on I1).

Prints slots per second for the MCAP sink alone, the Rerun sink alone (.rrd file) and
both, beside the floor: the raw ``mcap`` writer writing the same messages pre-encoded
(what any MCAP writer in Python pays). The simulation is included (it is ~0.1 us a slot).
Then the peak memory (max RSS of a fresh process recording with both sinks) for
100,000 slots against 1,000,000: streaming means the ratio should stay near 1.

    python benchmarks/bench_record.py [--horizon 100000] [--repeat 3] [--no-memory]

Targets (issue 3): MCAP only within 1.5x the floor; both sinks >= 100,000 slots/s; peak
memory at 1,000,000 slots <= 1.2x that at 100,000.
"""

from __future__ import annotations

import argparse
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path

RECORD = """
import resource, sys, os
sys.path.insert(0, {root!r})
os.environ.setdefault("RUST_LOG", "off")
from corraoi.block import RunConfig
from corraoi.engine import set_workers, simulate_run
from corraoi.instance import load_instance
from corraoi.policies import make_policy
from recorder.mcap_sink import McapSink
from recorder.rerun_sink import RerunSink, RrdOutput
set_workers(1)
config = RunConfig(load_instance("I1"), make_policy("cucb"), 0, {horizon})
with McapSink({mcap!r}, config, overwrite=True) as mcap, \\
        RrdOutput(config, rrd_path={rrd!r}, overwrite=True) as out:
    sink = RerunSink(out.recording, config.label, config)
    for block in simulate_run(config.instance, config.policy, 0, {horizon}):
        mcap.write(block)
        sink.write(block)
    sink.close()
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def peak_rss_mib(horizon: int, tmp: Path) -> float:
    root = str(Path(__file__).resolve().parent.parent)
    code = RECORD.format(
        root=root, horizon=horizon, mcap=str(tmp / "mem.mcap"), rrd=str(tmp / "mem.rrd")
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0


def best_of(repeat: int, fn: Callable[[], None]) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizon", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory runs")
    args = ap.parse_args()
    T = args.horizon

    import os

    os.environ.setdefault("RUST_LOG", "off")
    import rerun as rr
    from mcap.writer import CompressionType, Writer

    from corraoi.block import RunConfig
    from corraoi.engine import set_workers, simulate_run
    from corraoi.instance import load_instance
    from corraoi.policies import make_policy
    from recorder.format import FLUSH_EVERY, NS_PER_SLOT, BlockEncoder
    from recorder.mcap_sink import McapSink
    from recorder.rerun_sink import RerunSink, RrdOutput

    config = RunConfig(load_instance("I1"), make_policy("cucb"), 0, T)
    set_workers(1)  # as corraoi record does: one run, no use for the engine's threads

    def blocks():  # type: ignore[no-untyped-def]
        return simulate_run(config.instance, config.policy, config.seed, T)

    list(blocks())  # warm up the compiled engine
    encoder = BlockEncoder(config.instance.K)
    pre = [(b.t.tolist(), encoder.encode(b)) for b in blocks()]
    size = sum(len(m) for _, ms in pre for m in ms) / T

    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)

        def floor() -> None:
            with open(tmp / "floor.mcap", "wb") as f:
                w = Writer(f, compression=CompressionType.ZSTD, chunk_size=64 << 20)
                w.start()
                schema = w.register_schema("s", "jsonschema", b"{}")
                channel = w.register_channel("/corraoi/slot", "json", schema)
                for ts, messages in pre:
                    for t, data in zip(ts, messages, strict=True):
                        w.add_message(channel, t * NS_PER_SLOT, data, t * NS_PER_SLOT, t)
                        if t % FLUSH_EVERY == 0:
                            w.flush()
                w.finish()

        def mcap_only() -> None:
            with McapSink(tmp / "m.mcap", config, overwrite=True) as sink:
                for b in blocks():
                    sink.write(b)

        def rerun_only() -> None:
            with RrdOutput(config, rrd_path=tmp / "r.rrd", overwrite=True) as out:
                sink = RerunSink(out.recording, config.label, config)
                for b in blocks():
                    sink.write(b)
                sink.close()

        def both() -> None:
            with (
                McapSink(tmp / "b.mcap", config, overwrite=True) as mc,
                RrdOutput(config, rrd_path=tmp / "b.rrd", overwrite=True) as out,
            ):
                sink = RerunSink(out.recording, config.label, config)
                for b in blocks():
                    mc.write(b)
                    sink.write(b)
                sink.close()

        rows = [
            ("floor: raw mcap writer, pre-encoded", floor),
            ("MCAP only (McapSink)", mcap_only),
            ("Rerun only (RerunSink -> .rrd)", rerun_only),
            ("both sinks", both),
        ]
        times = {name: best_of(args.repeat, fn) for name, fn in rows}
        mcap_size = (tmp / "m.mcap").stat().st_size
        rrd_size = (tmp / "r.rrd").stat().st_size
        memory = None
        if not args.no_memory:
            memory = (peak_rss_mib(T, tmp), peak_rss_mib(10 * T, tmp))

    floor_t = times[rows[0][0]]
    print(
        f"corraoi record: cucb on I1, {T:,} slots, best of {args.repeat}; Python "
        f"{platform.python_version()}, mcap {version('mcap')}, rerun-sdk {rr.__version__}, "
        f"{os.cpu_count()} cores"
    )
    print(f"messages: {size:.0f} bytes of JSON a slot; files: {mcap_size / T:.0f} bytes a slot "
          f"(.mcap), {rrd_size / T:.0f} bytes a slot (.rrd)")  # fmt: skip
    print(f"{'':38s} {'slots/s':>10} {'us/slot':>8} {'x floor':>8}")
    for name, _ in rows:
        dt = times[name]
        print(f"{name:38s} {T / dt:10,.0f} {dt / T * 1e6:8.2f} {dt / floor_t:8.2f}")
    mc, bo = times[rows[1][0]], times[rows[3][0]]
    print(
        f"targets: MCAP only <= 1.5x floor: {mc / floor_t:.2f}x "
        f"{'ok' if mc / floor_t <= 1.5 else 'MISSED'}; both >= 100,000 slots/s: "
        f"{T / bo:,.0f} {'ok' if T / bo >= 100_000 else 'MISSED'}"
    )
    if memory is not None:
        small, large = memory
        ratio = large / small
        print(
            f"peak memory, both sinks (max RSS of a fresh process): {T:,} slots {small:.0f} MiB, "
            f"{10 * T:,} slots {large:.0f} MiB: ratio {ratio:.2f} "
            f"{'ok' if ratio <= 1.2 else 'MISSED'} (target <= 1.2)"
        )


if __name__ == "__main__":
    main()
