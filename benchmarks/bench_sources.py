"""Many sources against one (issue 43's speed target): a run of M sources costs at most M
times a single-source run of the base policy, plus 20%.

For each multi-source form and M in --sources, on a pinned random instance of K = 16
channels and 64 hidden states: the sweep kernel of many sources
(``corraoi.engine.sources.simulate_sources``) over --runs runs of --horizon slots, against
the single-source sweep kernel of its base policy on the same seeds (``Simulation``), best
of --repeat each, kernels compiled or loaded before timing. The single-source run and each M
are timed alternately, round after round (the machine's speed drifts: each ratio compares
times taken side by side). Prints the table; the ratio column is
t(M sources) / (M x t(one source)), the target <= 1.20.

    python benchmarks/bench_sources.py [--runs 200] [--horizon 10000] [--repeat 3]

On a machine others share, ``--workers 1 --cpu`` times the process's CPU time instead of
the wall clock (one engine thread: the two are the same work).
"""

from __future__ import annotations

import argparse
import functools
import time

import numpy as np

TARGET = 1.20


def instance_k16():
    """K = 16 channels, 64 hidden states, pinned (seed 16)."""
    from corraoi.model.instance import Instance

    rng = np.random.default_rng(16)
    p = rng.dirichlet(np.ones(64))
    Y = (rng.random((16, 64)) < 0.35).astype(np.int64)
    Y[3, int(np.argmax(p))] = 1
    return Instance("k16", p, Y)


def best_alternating(repeat: int, works: dict, clock=time.perf_counter) -> dict:
    """The best of ``repeat`` times of each of ``works``, timed in turn round after round."""
    best = dict.fromkeys(works, float("inf"))
    for _ in range(repeat):
        for key, work in works.items():
            start = clock()
            work()
            best[key] = min(best[key], clock() - start)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--horizon", type=int, default=10_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sources", type=int, nargs="+", default=[2, 4, 8])
    ap.add_argument("--policy", nargs="+",
                    default=["rhorand-ucb", "rhorand-cucb", "rhorand-ts", "mctopm-ucb",
                             "centralized-ucb"])  # fmt: skip
    ap.add_argument("--workers", type=int, default=None, help="engine threads (default: all)")
    ap.add_argument("--cpu", action="store_true", help="time CPU seconds, not the wall clock")
    args = ap.parse_args()

    from corraoi.engine.simulation import Simulation
    from corraoi.engine.sources import simulate_sources
    from corraoi.engine.threads import set_workers
    from corraoi.policies import make_policy

    workers = set_workers(args.workers)
    inst = instance_k16()
    seeds = range(args.runs)
    T = args.horizon
    clock = time.process_time if args.cpu else time.perf_counter
    print(
        f"K = 16, {args.runs} runs x {T} slots, {workers} threads, best of {args.repeat} "
        f"({'CPU' if args.cpu else 'wall'} s); "
        f"ratio = t(M) / (M t(1)), target <= {TARGET:.2f}"
    )
    print(f"{'policy':18s} {'M':>3} {'t(1) s':>8} {'t(M) s':>8} {'ratio':>6}  ok")
    worst = 0.0
    for name in args.policy:
        spec = make_policy(name)
        base = make_policy(spec.resolve().__mro__[1].name)  # the class it is a form of
        Simulation(inst, base, [0], 2).advance(2, record=False)  # compile or load first
        simulate_sources(inst, spec, [0], 2, 2)

        def single(base=base) -> None:
            Simulation(inst, base, seeds, T).advance(T, record=False)

        def many(M: int, spec=spec) -> None:
            simulate_sources(inst, spec, seeds, T, M)

        # the single-source kernel's key is no M: --sources 1 times the kernel of many sources
        works = {"single": single} | {M: functools.partial(many, M) for M in args.sources}
        best = best_alternating(args.repeat, works, clock)
        t1 = best["single"]
        for M in args.sources:
            tm = best[M]
            ratio = tm / (M * t1)
            worst = max(worst, ratio)
            print(
                f"{name:18s} {M:3d} {t1:8.3f} {tm:8.3f} {ratio:6.2f}  "
                f"{'yes' if ratio <= TARGET else 'NO'}"
            )
    print(f"worst ratio {worst:.2f} (target <= {TARGET:.2f})")


if __name__ == "__main__":
    main()
