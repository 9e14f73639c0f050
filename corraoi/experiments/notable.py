"""The runs of a sweep worth watching, named from the per-run final regrets it already holds.

Per cell: the run with the largest final regret (``worst``), the smallest (``best``) and the
median (the lower median: with 200 runs the 100th smallest); for a cell of several sources
also the run with the most collisions (``most-collisions``: a collision storm). Per pair of
cells that share an instance, horizon and channel (their run ``i`` is one hidden path, seed
``seed + i``): the run with the widest paired difference ``regret(a) - regret(b)`` in either
direction. With a baseline the pairs are every cell against it; without one every pair while
a group has at most :data:`MAX_PAIRED_CELLS` cells (a parameter grid of hundreds of cells
would name tens of thousands of pairs: give it a baseline).

Ties go to the lowest run index, so the choice does not depend on the chunking or on the
order chunks finished in. Nothing here holds more than the finals (one number per run).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from corraoi.stats import CELL_RUNS

#: What ``--run`` accepts besides a run index: a cell's runs, or a pair's widest gap.
CHOICES = (*CELL_RUNS[:3], "widest-gap", *CELL_RUNS[3:])

#: Cells in a group above which pairs are named only against a baseline.
MAX_PAIRED_CELLS = 24


def _entry(finals: np.ndarray, run: int, seed: int) -> dict[str, Any]:
    return {"run": int(run), "seed": int(seed + run), "regret": float(finals[run])}


def cell_runs(finals: np.ndarray, seed: int,
              collisions: np.ndarray | None = None) -> dict[str, dict[str, Any]]:  # fmt: skip
    """worst, best and median run of one cell from its per-run final regrets (run order);
    with ``collisions`` (each run's, several sources) the run with the most of them too."""
    finals = np.asarray(finals, dtype=np.float64)
    k = (finals.size - 1) // 2
    median = np.partition(finals, k)[k]
    out = {
        "worst": _entry(finals, int(np.argmax(finals)), seed),
        "best": _entry(finals, int(np.argmin(finals)), seed),
        "median": _entry(finals, int(np.flatnonzero(finals == median)[0]), seed),
    }
    if collisions is not None:
        run = int(np.argmax(collisions))
        out["most-collisions"] = {**_entry(finals, run, seed),
                                  "collisions": int(collisions[run])}  # fmt: skip
    return out


def widest_gap(a: np.ndarray, b: np.ndarray, seed: int) -> dict[str, Any]:
    """The run where ``regret(a) - regret(b)`` is widest in absolute value."""
    diff = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    run = int(np.argmax(np.abs(diff)))
    return {"run": run, "seed": int(seed + run), "difference": float(diff[run]),
            "regret": [float(a[run]), float(b[run])]}  # fmt: skip


def notable_runs(
    labels: Sequence[str],
    finals: Sequence[np.ndarray],
    paired_with: Sequence[Any],
    *,
    seed: int,
    baseline: str | None = None,
    collisions: Sequence[np.ndarray | None] | None = None,
) -> dict[str, Any]:
    """The notable runs of one group: ``labels[i]``'s per-run finals are ``finals[i]``; cells
    whose ``paired_with`` values are equal share hidden paths (the channel). ``baseline`` is
    the label pairs are taken against (when the group has it); ``collisions[i]``: each run's
    collisions of a cell of several sources (None for one source)."""
    hits = list(collisions) if collisions is not None else [None] * len(labels)
    cells = {label: cell_runs(f, seed, c)
             for label, f, c in zip(labels, finals, hits, strict=True)}  # fmt: skip
    n = len(labels)
    if baseline is not None and baseline in labels:
        b = labels.index(baseline)
        pairs = [(i, b) for i in range(n) if i != b]
    elif n <= MAX_PAIRED_CELLS:
        pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    else:
        pairs = []
    gaps = []
    for i, j in pairs:
        if paired_with[i] != paired_with[j] or finals[i].shape != finals[j].shape:
            continue
        gaps.append({"policies": [labels[i], labels[j]], **widest_gap(finals[i], finals[j], seed)})
    gaps.sort(key=lambda g: -abs(g["difference"]))  # stable: grid order among equal gaps
    return {"cells": cells, "pairs": gaps}


def pick_pair(
    pairs: Sequence[dict[str, Any]], among: Sequence[str] | None
) -> dict[str, Any] | None:
    """The widest gap between two of ``among`` (any two when None), or None."""
    for gap in pairs:  # widest first
        if among is None or (gap["policies"][0] in among and gap["policies"][1] in among):
            return gap
    return None


def well_formed(notable: Any, want: Sequence[str] = ()) -> bool:
    """A summary's runs worth watching (as read back from JSON) hold an entry for every cell
    in ``want`` and well-formed pairs, each of two cells it names (of ``want``, when given):
    a hand-edited or damaged summary is not trusted."""
    if not isinstance(notable, dict):
        return False
    cells, pairs = notable.get("cells"), notable.get("pairs", [])
    if not isinstance(cells, dict) or not isinstance(pairs, list):
        return False
    def run(e: Any, value: str) -> bool:
        return (isinstance(e, dict) and all(type(e.get(k)) is int for k in ("run", "seed"))
                and isinstance(e.get(value), (int, float)) and not isinstance(e[value], bool))

    for w in want:
        entry = cells.get(w)
        if not isinstance(entry, dict) or not all(run(entry.get(k), "regret")
                                                  for k in ("worst", "best", "median")):
            return False  # fmt: skip
    known = set(want) if want else set(cells)  # a pair names two of the sweep's cells
    return all(run(g, "difference") and isinstance(g.get("policies"), list)
               and len(g["policies"]) == 2 and all(isinstance(n, str) and n in known
                                                   for n in g["policies"])
               and g["policies"][0] != g["policies"][1]
               for g in pairs)  # fmt: skip
