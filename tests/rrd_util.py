"""Reading .rrd files back in tests (rerun 0.41: ``rerun.chunk.RrdReader``)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from rerun.chunk import RrdReader

#: The rerun CLI bundled with rerun-sdk (rrd compare, verify, ...).
RERUN = str(Path(sys.executable).parent / "rerun")


@pytest.fixture(autouse=True)
def strict_rerun() -> Iterator[None]:
    """Rerun logs (instead of raising) on bad input unless strict: make mistakes fail.

    Autouse in every module that imports it."""
    old = rr.strict_mode()
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(old)


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
