"""corraoi.Logger and corraoi.gym, measured (issue 42's speed figures).

* ``Logger.slot`` one slot at a time, and ``Logger.slots`` in blocks of 1,000, to MCAP
  (no Rerun recording), against ``corraoi record``'s own rate for CUCB on I1;
* the environment's ``step`` on ``env.unwrapped`` (no wrappers, ``record=None``), and the
  vector form's for 256 sub-environments, in environment-steps per second.

    python benchmarks/bench_gym.py [SLOTS]
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import corraoi
import corraoi.gym


def rate(slots: int, start: float) -> float:
    return slots / (time.perf_counter() - start)


def main(slots: int = 200_000) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        start = time.perf_counter()
        corraoi.record("cucb", "I1", horizon=slots, path=out / "cucb.mcap", rrd=False)
        record = rate(slots, start)
        run = corraoi.load(out / "cucb.mcap").log.read_all()
        arms, success, x = (run.arm + 1).tolist(), run.success.tolist(), (run.x + 1).tolist()
        with corraoi.Logger(out / "warm.mcap", instance="I1", horizon=10) as log:
            log.slot(arms[0], success[0], x=x[0])  # imports and first file made, not timed
        start = time.perf_counter()
        with corraoi.Logger(out / "one.mcap", instance="I1", horizon=slots) as log:
            for a, s, h in zip(arms, success, x, strict=True):
                log.slot(a, s, x=h)
        one = rate(slots, start)
        start = time.perf_counter()
        with corraoi.Logger(out / "blocks.mcap", instance="I1", horizon=slots) as log:
            for i in range(0, slots, 1000):
                log.slots(run.arm[i:i + 1000] + 1, run.success[i:i + 1000],
                          x=run.x[i:i + 1000] + 1)  # fmt: skip
        blocks = rate(slots, start)
    env = corraoi.gym.CorrelatedAoIEnv("I1", 10**9)
    env.reset(seed=0)
    picks = (run.arm[:slots]).tolist()
    start = time.perf_counter()
    for a in picks:
        env.step(a)
    plain = rate(len(picks), start)
    N = 256
    envs = corraoi.gym.CorrelatedAoIVectorEnv(N, "I1", 10**9)
    envs.reset(seed=0)
    actions = np.random.default_rng(0).integers(0, 4, (max(slots // N, 100), N))
    envs.step(actions[0])
    start = time.perf_counter()
    for a in actions:
        envs.step(a)
    vector = rate(actions.size, start)
    print(f"corraoi record (cucb, I1)     {record:>12,.0f} slots/s")
    print(f"Logger.slot, one at a time    {one:>12,.0f} slots/s")
    print(
        f"Logger.slots, blocks of 1000  {blocks:>12,.0f} slots/s ({blocks / record:.0%} of record)"
    )
    print(f"env.unwrapped.step            {plain:>12,.0f} steps/s")
    print(f"vector form, {N} envs         {vector:>12,.0f} env-steps/s ({vector / plain:.1f}x)")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200_000)
