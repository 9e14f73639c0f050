"""What bench_record.py and bench_replay.py share: the instance for ``--arms K`` and the
``--baseline DIR`` rounds (this checkout and another one, alternately, in child processes).

The children run the benchmark script of this checkout with ``--json`` and the code of the
checkout being timed (``git worktree add /tmp/base <commit>`` or ``git archive <commit> |
tar -x -C /tmp/base``; ``checkouts.pythonpath``: its corraoi, recorder and viewer, in
either layout, never the installed ones), each with a kernel cache of its own; the
two alternate, round after round, so that both see the same machine, and each row keeps
its best time.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from checkouts import pythonpath

ROOT = Path(__file__).resolve().parent.parent


def instance_for(arms: int) -> Any:
    """The instance of a K-arm benchmark: the paper's I1 for 4 arms, else a random one with
    K arms and max(8, K / 4) states (seeded: the same in every checkout)."""
    import numpy as np

    from corraoi.model.instance import Instance, load_instance

    if arms == 4:
        return load_instance("I1")
    n = max(8, arms // 4)
    rng = np.random.default_rng(arms)
    Y = (rng.uniform(size=(arms, n)) < rng.uniform(0.1, 0.5, size=(arms, 1))).astype(int)
    Y[np.arange(arms), rng.integers(n, size=arms)] = 1
    return Instance.from_dict({"name": f"R{arms}", "p": list(rng.dirichlet(np.ones(n))),
                               "Y": Y.tolist()})  # fmt: skip


def code_root() -> Path:
    """The checkout whose packages this process runs (PYTHONPATH's, else this one)."""
    import corraoi

    return Path(corraoi.__file__).resolve().parent.parent


def alternate(script: Path, argv: list[str], baseline: Path, rounds: int,
              work: Path) -> dict[str, dict[str, float]]:  # fmt: skip
    """``{"now": {row: seconds}, "before": {...}}``: the best of ``rounds`` runs of
    ``script argv --json`` with this checkout's packages and with ``baseline``'s."""
    roots = {"before": baseline.resolve(), "now": ROOT}
    best: dict[str, dict[str, float]] = {k: {} for k in roots}
    for i in range(rounds):
        # which goes first changes every round: the first of a pair ran faster here
        for key, root in list(roots.items())[:: 1 if i % 2 == 0 else -1]:
            env = {**os.environ, "PYTHONPATH": pythonpath(root),
                   "CORRAOI_CACHE_DIR": str(work / f"cache-{key}"), "RUST_LOG": "off"}
            proc = subprocess.run([sys.executable, str(script), *argv, "--json"], env=env,
                                  capture_output=True, text=True)  # fmt: skip
            if proc.returncode != 0:
                raise SystemExit(f"{root}: {script.name} failed:\n{proc.stderr[-3000:]}")
            times = json.loads(proc.stdout.strip().splitlines()[-1])
            for row, seconds in times.items():
                best[key][row] = min(seconds, best[key].get(row, float("inf")))
            print(f"  {key}: " + ", ".join(f"{r} {v:.3f}" for r, v in times.items()
                                          if not r.endswith("[CPU]")), file=sys.stderr)
    return best


def print_comparison(best: dict[str, dict[str, float]], per: int, unit: str,
                     baseline: Path) -> None:  # fmt: skip
    """The rows of both checkouts side by side, ``per`` items (slots) a time unit."""
    print(f"{'row':44s} {'now ' + unit:>12s} {'before ' + unit:>12s} {'now/before':>10s}")
    for row, now in best["now"].items():
        before = best["before"].get(row)
        if before is None:
            continue
        print(f"{row:44s} {now / per * 1e6:12.3f} {before / per * 1e6:12.3f} "
              f"{now / before:10.3f}")
    print(f"(before: {baseline})")


__all__ = ["alternate", "code_root", "instance_for", "print_comparison"]
