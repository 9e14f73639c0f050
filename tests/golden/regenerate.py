"""Regenerate tests/golden/builtins.json: a short run of every built-in policy on fixed seeds;
and the field table of docs/log-format.md, from the slot record's declaration.

    python tests/golden/regenerate.py

Run it only when a change to the engine or a policy changes the random streams on purpose,
and say so in the changelog: the golden file pins every built-in's decisions slot by slot.
(The table changes with corraoi/engine/slot_record.py: run it after a change there.)

tests/golden/before-score.mcap is never regenerated: a slot log written by corraoi before
the score existed (commit 2347ea6; aoi-aware-cucb on I1, seed 5, 1200 slots), which today's
reader must keep reading (tests/test_slot_record.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from corraoi.engine.simulation import simulate
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import builtins, make_policy

HERE = Path(__file__).parent
HORIZON = 400
SEEDS = [3, 4]


def wide() -> Instance:
    rng = np.random.default_rng(7)
    p = rng.dirichlet(np.ones(12))
    Y = (rng.random((6, 12)) < 0.35).astype(np.int64)
    Y[2, int(np.argmax(p))] = 1
    return Instance("golden-wide", p, Y)


def instances() -> list[Instance]:
    return [load_instance("I1"), load_instance("I2"), wide()]


def golden() -> dict[str, object]:
    out: dict[str, object] = {"horizon": HORIZON, "seeds": SEEDS, "runs": {}}
    runs: dict[str, object] = {}
    for inst in instances():
        for name in builtins():
            blk = next(simulate(inst, make_policy(name), SEEDS, HORIZON, block=HORIZON))
            runs[f"{inst.name}/{name}"] = {
                "arms": ["".join(chr(ord("a") + int(a)) for a in row) for row in blk.arm],
                "regret": [int(r) for r in blk.regret[:, -1]],
                "overrides": [int(v) for v in blk.override.sum(axis=1)],
                "candidates": [int(v) for v in blk.candidates.sum(axis=(1, 2))],
            }
    out["runs"] = runs
    return out


def write_docs_table() -> Path:
    """The slot record's table between its markers in docs/log-format.md."""
    from corraoi.engine.slot_record import markdown_table

    doc = HERE.parent.parent / "docs" / "log-format.md"
    begin, end = "<!-- slot-record: begin -->\n", "<!-- slot-record: end -->"
    text = doc.read_text(encoding="utf-8")
    head, rest = text.split(begin, 1)
    doc.write_text(head + begin + markdown_table() + end + rest.split(end, 1)[1], encoding="utf-8")
    return doc


if __name__ == "__main__":
    print(f"wrote {write_docs_table()}")
    path = HERE / "builtins.json"
    path.write_text(json.dumps(golden(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {path}")
