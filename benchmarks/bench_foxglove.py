"""Foxglove live-stream benchmark: slots/s through ``FoxgloveSlotSink`` (encode + publish)
with no client, with a client that reads everything, and with a client that reads nothing
(stalled), and how much the process grew meanwhile (cucb on I1, blocks made beforehand).
The clients run in this process (threads): the reading one competes with the publisher for
the GIL, so its row is a floor, not what a separate Foxglove app costs.

    python benchmarks/bench_foxglove.py [--slots 200000] [--repeat 3]

The stalled client shows the bound: the run does not wait for it, and memory stays flat
(the SDK queues at most BACKLOG messages per client and drops the oldest).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
warnings.filterwarnings("ignore", "connect\\(\\) must be used", DeprecationWarning)

from corraoi.engine.block import RunConfig, SlotBlock  # noqa: E402
from corraoi.engine.simulation import simulate_run  # noqa: E402
from corraoi.model.instance import load_instance  # noqa: E402
from corraoi.policies import make_policy  # noqa: E402
from corraoi.recorder.live.foxglove import TOPIC, Address, FoxgloveServer  # noqa: E402


def _rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def _client(url: str, *, read: bool) -> tuple[object, threading.Thread | None, list[int]]:
    from websockets.sync.client import connect

    ws = connect(url, subprotocols=["foxglove.sdk.v1"], max_queue=None if read else 1)
    got = [0]
    while True:
        msg = json.loads(ws.recv(timeout=5))
        if msg["op"] == "advertise":
            ids = [c["id"] for c in msg["channels"] if c["topic"] == TOPIC]
            if ids:
                ws.send(
                    json.dumps(
                        {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": ids[0]}]}
                    )
                )
                break
    if not read:
        return ws, None, got

    def pump() -> None:
        try:
            while True:
                frame = ws.recv(timeout=2)
                if isinstance(frame, bytes):
                    got[0] += 1
        except Exception:
            return

    thread = threading.Thread(target=pump, daemon=True)
    thread.start()
    return ws, thread, got


def run(kind: str, blocks: list[SlotBlock], config: RunConfig) -> tuple[float, float, int]:
    with FoxgloveServer(Address("127.0.0.1", 0)) as server:
        sink = server.slot_sink(config)
        ws = None
        got = [0]
        if kind != "no client":
            ws, _, got = _client(server.url, read=kind == "reading client")
            while not sink.subscribed():
                time.sleep(0.01)
        before = _rss_mib()
        start = time.perf_counter()
        for b in blocks:
            sink.write(b)
        wall = time.perf_counter() - start
        grown = _rss_mib() - before
        time.sleep(0.5)
        if ws is not None:
            ws.close()  # type: ignore[attr-defined]
    return len(blocks) * len(blocks[0]) / wall, grown, got[0]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--slots", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    config = RunConfig(load_instance("I1"), make_policy("cucb"), 0, args.slots)
    blocks = list(simulate_run(config.instance, config.policy, 0, args.slots))
    print(f"{args.slots:,} slots, best of {args.repeat}")
    print(f"{'':16} {'slots/s':>12} {'RSS growth':>12} {'client got':>12}")
    for kind in ("no client", "reading client", "stalled client"):
        best = max((run(kind, blocks, config) for _ in range(args.repeat)), key=lambda r: r[0])
        rate, grown, got = best
        print(f"{kind:16} {rate:>12,.0f} {grown:>10.1f} MB {got:>12,}")


if __name__ == "__main__":
    main()
