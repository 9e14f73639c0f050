"""Recorder benchmark: ``corraoi record`` throughput, stage by stage, and memory (cucb).

First the stages alone, each on data the previous stage made beforehand: the engine, the
JSON encoding of the slot messages (``BlockEncoder``), MCAP framing and compression of
those messages (``ChunkWriter``, one chunk per 1,000 slots), and the Rerun send
(``RerunSink`` to an .rrd file, from ready blocks). Then the sinks as ``corraoi record``
runs them, engine included: MCAP alone, Rerun alone, both (McapSink encodes and frames a
block at once, ``BlockEncoder.encode_framed`` and ``ChunkWriter.frame``, which a baseline
checkout may lack: the stage rows time the per-message calls). For reference, mcap's own
``Writer`` writing the same pre-encoded messages one ``add_message`` at a time (the path
McapSink used before it framed whole chunks). Then the peak memory (max RSS of a fresh
process recording with both sinks) for T slots against 10 T.

    python benchmarks/bench_record.py [--horizon 200000] [--repeat 5] [--no-memory]
                                      [--arms K] [--baseline DIR [--rounds 3]]

``--arms K``: on an instance of K arms (benchmarks/alternate.py: I1 for 4, else a seeded
random one). ``--baseline DIR``: time this checkout and another one (its packages on
PYTHONPATH) alternately, ``--rounds`` times each, and print their rows side by side.

Targets (issue 10): both sinks >= 250,000 slots/s, best of 5; peak memory at 10 T
<= 1.2x that at T. Issue 35: record within 5% of 224f28d at K = 4, at most 1.5x at K = 256.
Measure with a low ``uptime`` load: the figures move with other jobs.
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from importlib.metadata import version
from pathlib import Path

from alternate import alternate, code_root, instance_for, print_comparison

RECORD = """
import json, resource, sys, os
sys.path.insert(0, {root!r})
os.environ.setdefault("RUST_LOG", "off")
from corraoi.engine.block import RunConfig
from corraoi.engine.simulation import simulate_run
from corraoi.engine.threads import set_workers
from corraoi.model.instance import Instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.recorder.rerun.sink import RerunSink
from corraoi.recorder.rerun.output import RrdOutput
set_workers(1)
config = RunConfig(Instance.from_dict(json.loads({inst!r})), make_policy("cucb"), 0, {horizon})
with McapSink({mcap!r}, config, overwrite=True) as mcap, \\
        RrdOutput(config, rrd_path={rrd!r}, overwrite=True) as out:
    sink = RerunSink(out.recording, config.label, config)
    for block in simulate_run(config.instance, config.policy, 0, {horizon}):
        mcap.write(block)
        sink.write(block)
    sink.close()
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def peak_rss_mib(horizon: int, tmp: Path, inst: str) -> float:
    code = RECORD.format(root=str(code_root()), horizon=horizon, inst=inst,
                         mcap=str(tmp / "mem.mcap"), rrd=str(tmp / "mem.rrd"))  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1024.0


#: CPU seconds of this process (every thread: Rerun's writer too) of the last best_of call.
CPU: dict[str, float] = {}


def best_of(repeat: int, fn: Callable[[], None], name: str = "") -> float:
    """The fastest of ``repeat`` calls (wall seconds); its CPU seconds go to CPU[name]."""
    best = float("inf")
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = time.perf_counter() - t0
        if wall < best:
            best, CPU[name] = wall, time.process_time() - c0
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--horizon", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-memory", action="store_true", help="skip the peak-memory runs")
    ap.add_argument("--arms", type=int, default=4, help="K: the instance's arms [4: I1]")
    ap.add_argument("--baseline", type=Path, help="another checkout to time beside this one")
    ap.add_argument("--rounds", type=int, default=3, help="with --baseline: rounds of each")
    ap.add_argument("--json", action="store_true", help="print the times as one JSON object")
    ap.add_argument("--only", help="with --json or --baseline: the rows whose names start so "
                    "(a comma list), for more rounds in the same time")  # fmt: skip
    args = ap.parse_args()
    T = args.horizon
    if args.only and not (args.json or args.baseline):
        ap.error("--only goes with --json or --baseline")
    if args.baseline is not None:
        with tempfile.TemporaryDirectory(prefix="bench-record-") as work:
            argv = ["--horizon", str(T), "--repeat", str(args.repeat), "--arms",
                    str(args.arms), "--no-memory", *(["--only", args.only] if args.only else [])]
            both = alternate(Path(__file__), argv, args.baseline, args.rounds, Path(work))
        print(f"corraoi record: cucb on {instance_for(args.arms).name} ({args.arms} arms), "
              f"{T:,} slots, best of {args.rounds} rounds x {args.repeat}")
        print_comparison(both, T, "us/slot", args.baseline)
        return

    import os

    os.environ.setdefault("RUST_LOG", "off")
    import numpy as np
    import rerun as rr
    from mcap.records import Channel, Schema
    from mcap.writer import CompressionType, Writer

    from corraoi.engine.block import RunConfig
    from corraoi.engine.simulation import simulate_run
    from corraoi.engine.threads import set_workers
    from corraoi.policies import make_policy
    from corraoi.recorder.rerun.output import RrdOutput
    from corraoi.recorder.rerun.sink import RerunSink
    from corraoi.recorder.slotlog.chunks import ChunkWriter
    from corraoi.recorder.slotlog.encode import BlockEncoder
    from corraoi.recorder.slotlog.sink import McapSink
    from corraoi.recorder.vocab import NS_PER_SLOT
    from corraoi.recorder.vocab import SLOT_FLUSH_EVERY as FLUSH_EVERY

    inst = instance_for(args.arms)
    config = RunConfig(inst, make_policy("cucb"), 0, T)
    set_workers(1)  # as corraoi record does: one run, no use for the engine's threads

    def blocks():  # type: ignore[no-untyped-def]
        return simulate_run(config.instance, config.policy, config.seed, T)

    ready = list(blocks())  # also warms up the compiled engine
    encoder = BlockEncoder(config.instance.K)
    pre = [(b.t.tolist(), encoder.encode(b)) for b in ready]
    size = sum(len(m) for _, ms in pre for m in ms) / T
    assert all(len(b) == FLUSH_EVERY for b in ready[:-1]), "blocks of one chunk each"

    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)

        def engine() -> None:
            for _ in blocks():
                pass

        def encode() -> None:
            for b in ready:
                encoder.encode(b)

        def framing() -> None:
            with open(tmp / "frame.mcap", "wb") as f:
                w = ChunkWriter(
                    f,
                    schema=Schema(id=1, name="s", encoding="jsonschema", data=b"{}"),
                    channel=Channel(
                        id=1,
                        topic="/corraoi/slot",
                        message_encoding="json",
                        schema_id=1,
                        metadata={},
                    ),  # fmt: skip
                    library="bench",
                )
                w.start()
                for ts, messages in pre:
                    t = np.asarray(ts, dtype=np.uint64)
                    w.add_messages(t * np.uint64(NS_PER_SLOT), t, messages)
                    w.flush()
                w.finish()

        def rerun_send() -> None:
            with RrdOutput(config, rrd_path=tmp / "s.rrd", overwrite=True) as out:
                sink = RerunSink(out.recording, config.label, config)
                for b in ready:
                    sink.write(b)
                sink.close()

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

        stages = [
            ("engine (simulate_run)", engine),
            ("JSON encode (BlockEncoder)", encode),
            ("MCAP framing + zstd (ChunkWriter)", framing),
            ("Rerun send (RerunSink -> .rrd)", rerun_send),
            ("mcap Writer.add_message, pre-encoded", floor),
        ]
        rows = [
            ("MCAP only (McapSink)", mcap_only),
            ("Rerun only (RerunSink -> .rrd)", rerun_only),
            ("both sinks", both),
        ]
        if args.only:  # a few rows, for many rounds (with --json or --baseline)
            keep = [w.strip() for w in args.only.split(",") if w.strip()]
            stages = [(n, f) for n, f in stages if any(n.startswith(k) for k in keep)]
            rows = [(n, f) for n, f in rows if any(n.startswith(k) for k in keep)]
        stage_times = {name: best_of(args.repeat, fn, name) for name, fn in stages}
        times = {name: best_of(args.repeat, fn, name) for name, fn in rows}
        if args.json:  # wall seconds, and CPU seconds of the same calls
            cpu = {f"{name} [CPU]": CPU[name] for name in (*stage_times, *times)}
            print(json.dumps({**stage_times, **times, **cpu}))
            return
        mcap_size = (tmp / "m.mcap").stat().st_size
        rrd_size = (tmp / "r.rrd").stat().st_size
        memory = None
        if not args.no_memory:
            text = json.dumps(inst.to_dict())
            memory = (peak_rss_mib(T, tmp, text), peak_rss_mib(10 * T, tmp, text))

    print(
        f"corraoi record: cucb on {inst.name} ({inst.K} arms), {T:,} slots, best of "
        f"{args.repeat}; Python "
        f"{platform.python_version()}, mcap {version('mcap')}, rerun-sdk {rr.__version__}, "
        f"{os.cpu_count()} cores"
    )
    print(f"messages: {size:.0f} bytes of JSON a slot; files: {mcap_size / T:.0f} bytes a slot "
          f"(.mcap), {rrd_size / T:.0f} bytes a slot (.rrd)")  # fmt: skip
    print(f"{'stage (alone, on ready input)':40s} {'us/slot':>8} {'slots/s':>12}")
    for name, _ in stages:
        dt = stage_times[name]
        print(f"{name:40s} {dt / T * 1e6:8.2f} {T / dt:12,.0f}")
    print(f"{'record (engine included)':40s} {'us/slot':>8} {'slots/s':>12}")
    for name, _ in rows:
        dt = times[name]
        print(f"{name:40s} {dt / T * 1e6:8.2f} {T / dt:12,.0f}")
    bo = times[rows[2][0]]
    print(
        f"target: both sinks >= 250,000 slots/s: {T / bo:,.0f} "
        f"{'ok' if T / bo >= 250_000 else 'MISSED'}"
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
