"""Reading .rrd files back in tests (rerun 0.41: ``rerun.chunk.RrdReader``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader


def read_rrd(path: Path) -> dict[str, tuple[np.ndarray, list]]:
    """entity path -> (slots, values per slot) of every Scalars column in the recording."""
    found: dict[str, tuple[list[int], list]] = {}
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if "slot" not in batch.schema.names or "Scalars:scalars" not in batch.schema.names:
            continue
        slots, values = found.setdefault(chunk.entity_path, ([], []))
        slots.extend(batch.column("slot").to_pylist())
        values.extend(batch.column("Scalars:scalars").to_pylist())
    out = {}
    for entity, (slots, values) in found.items():
        order = np.argsort(slots, kind="stable")
        out[entity] = (np.asarray(slots)[order], [values[i] for i in order])
    return out
