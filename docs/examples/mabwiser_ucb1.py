"""MABWiser's UCB1 acting in corraoi's Gymnasium environment, beside corraoi's own ``ucb``.

An agent from another library plays the paper's model through ``corraoi/CorrelatedAoI-v0``;
``reset(seed=s)`` draws the hidden path of ``corraoi record --seed s``, so its regret is
paired, seed by seed, with corraoi's ``ucb`` on the same paths. UCB1 is the same algorithm
as corraoi's ``ucb`` (each arm once, then the largest mean + sqrt(2 ln t / n)): the mean
paired difference of their final regrets should be within 1.96 standard errors of zero.

    pip install "corraoi[gym]" mabwiser
    python docs/examples/mabwiser_ucb1.py [--seeds 200] [--horizon 10000] [--instance I1]
                                          [--record runs/mabwiser-{episode}.mcap]

Two known differences, both small: MABWiser's log counts the observations so far (t - 1 at
slot t), corraoi's ``ucb`` uses ln t; MABWiser breaks ties by the lowest arm, corraoi's ``ucb``
uniformly at random (they tie only while means are equal).
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
from pathlib import Path

import gymnasium
from mabwiser.mab import MAB, LearningPolicy

import corraoi


def mabwiser_regret(instance: str, seed: int, horizon: int, record: str | None = None) -> int:
    """The pathwise AoI regret of MABWiser's UCB1 over one episode of seed ``seed``."""
    env = gymnasium.make("corraoi.gym:corraoi/CorrelatedAoI-v0", instance=instance,
                         horizon=horizon, record=record, force=True)  # fmt: skip
    K = int(env.action_space.n)
    env.reset(seed=seed)
    decisions, rewards = [], []
    info: dict = {}
    for arm in range(K):  # UCB1 starts by playing each arm once
        obs, _, _, _, info = env.step(arm)
        decisions.append(arm)
        rewards.append(int(obs[0]))
    agent = MAB(arms=list(range(K)), learning_policy=LearningPolicy.UCB1(alpha=1.0), seed=seed)
    agent.fit(decisions=decisions, rewards=rewards)
    truncated = horizon <= K
    while not truncated:
        arm = int(agent.predict())
        obs, _, _, truncated, info = env.step(arm)
        agent.partial_fit(decisions=[arm], rewards=[int(obs[0])])
    env.close()
    return int(info["regret"])


def corraoi_regret(instance: str, seed: int, horizon: int, folder: Path) -> int:
    """The pathwise AoI regret of corraoi's ``ucb`` on the same hidden path."""
    run = corraoi.record("ucb", instance, seed=seed, horizon=horizon,
                         path=folder / f"ucb-s{seed}.mcap", rrd=False)  # fmt: skip
    regret = run.summary.regret
    assert regret is not None
    return int(regret)


def compare(instance: str, seeds: int, horizon: int,
            record: str | None = None) -> dict[str, float]:  # fmt: skip
    """MABWiser's UCB1 against corraoi's ``ucb`` over ``seeds`` paired seeds: each one's mean
    final regret, and the mean paired difference with its standard error."""
    with tempfile.TemporaryDirectory() as tmp:
        theirs = [mabwiser_regret(instance, s, horizon, record) for s in range(seeds)]
        ours = [corraoi_regret(instance, s, horizon, Path(tmp)) for s in range(seeds)]
    diffs = [a - b for a, b in zip(theirs, ours, strict=True)]
    se = statistics.stdev(diffs) / math.sqrt(len(diffs)) if len(diffs) > 1 else math.inf
    return {"mabwiser": statistics.fmean(theirs), "corraoi": statistics.fmean(ours),
            "difference": statistics.fmean(diffs), "se": se}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--horizon", type=int, default=10_000)
    ap.add_argument("--instance", default="I1")
    ap.add_argument("--record", help="log each MABWiser episode ({episode} numbers them)")
    args = ap.parse_args()
    got = compare(args.instance, args.seeds, args.horizon, args.record)
    z = got["difference"] / got["se"] if got["se"] > 0 else 0.0
    print(f"{args.instance}, {args.seeds} seeds x {args.horizon} slots, final pathwise regret")
    print(f"  MABWiser UCB1  {got['mabwiser']:10.1f}")
    print(f"  corraoi ucb    {got['corraoi']:10.1f}")
    print(f"  paired difference {got['difference']:+.1f} +- {got['se']:.1f} (1 s.e.), "
          f"{z:+.2f} standard errors: " + ("the same algorithm" if abs(z) <= 1.96
                                           else "they differ"))  # fmt: skip


if __name__ == "__main__":
    main()
