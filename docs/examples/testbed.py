"""A testbed's stream replayed into a corraoi recording (docs/logging.md).

The testbed logged, slot by slot, the channel its scheduler tried and whether the update
was delivered, as a CSV of ``slot,channel,delivered`` (channels numbered from 1). It does
not know the hidden state, so the log holds the age, the pulls, the empirical means and the
paper's estimator on instance I1 (the testbed's four channels), and leaves the oracle and
the regret absent.

    python docs/examples/testbed.py docs/examples/testbed.csv runs/testbed.mcap
    rerun runs/testbed.rrd            # the recording, in the Rerun viewer
    corraoi info runs/testbed.mcap

The CSV is read in blocks of 1,000 rows and each block goes to the log at once.
"""

from __future__ import annotations

import csv
import sys
from itertools import islice
from pathlib import Path

import numpy as np

import corraoi


def replay(source: Path, out: Path, *, instance: str = "I1") -> corraoi.Run:
    """The CSV ``source`` into the slot log ``out`` and its recording beside it."""
    with open(source, newline="") as f:
        rows = csv.DictReader(f)
        slots = sum(1 for _ in rows)
    with open(source, newline="") as f:
        rows = csv.DictReader(f)
        with corraoi.Logger(out, instance=instance, horizon=slots, policy="testbed",
                            source=f"testbed CSV {source.name}", rrd=True) as log:  # fmt: skip
            while block := list(islice(rows, 1000)):
                log.slots(
                    t=np.array([int(r["slot"]) for r in block]),
                    arm=np.array([int(r["channel"]) for r in block]),
                    success=np.array([r["delivered"] == "1" for r in block]),
                )
    return corraoi.load(out)


if __name__ == "__main__":
    run = replay(Path(sys.argv[1]), Path(sys.argv[2]))
    print(f"{run.path}: {run.log.n_slots} slots, recording {run.rrd}")
    print(f"mean age {run.slots['aoi'].mean():.2f} slots; pulls {run.summary.pulls}")
