"""A sweep folder's files beyond the core's are written by the outputs its caller hands the
sweep (issue 23): the core writes the parts, manifest and summaries, and calls the outputs
with the finished groups; by default they are the viewer's FolderOutputs (every file)."""

from __future__ import annotations

import json
from pathlib import Path

from corraoi.experiments.grid import build_grid
from corraoi.experiments.sweeps import DEFAULT_OUTPUTS, default_outputs, sweep
from corraoi.face.outputs import FolderOutputs


class Recorded:
    def __init__(self) -> None:
        self.calls: list[tuple[str, object]] = []

    def write_results(self, folder, grid, parts, labels, *, warn):  # type: ignore[no-untyped-def]
        self.calls.append(("results", sorted(labels.values())))

    def write_group(self, folder, grid, cells, summary, *, warn):  # type: ignore[no-untyped-def]
        self.calls.append(("group", (folder.name, [c.label for c in cells], summary["runs"])))

    def finish(self, *, warn):  # type: ignore[no-untyped-def]
        self.calls.append(("finish", None))


def _grid():  # type: ignore[no-untyped-def]
    return build_grid(instances=["I1", "I2"], policies=["ucb", "cucb"], horizons=[200],
                      runs=6)  # fmt: skip


def test_the_callers_outputs_get_every_group_and_the_core_writes_the_summaries(tmp_path: Path):
    mine = Recorded()
    outcome = sweep(_grid(), out=tmp_path / "s", outputs=mine, workers=1)
    assert mine.calls == [("results", ["cucb", "cucb", "ucb", "ucb"]),
                          ("group", ("I1", ["ucb", "cucb"], 6)),
                          ("group", ("I2", ["ucb", "cucb"], 6)),
                          ("finish", None)]  # fmt: skip
    for folder, summary in zip(outcome.folders, outcome.summaries, strict=True):
        assert json.loads((folder / "summary.json").read_text()) == summary
        assert (folder / "summary.md").read_text().startswith("# Sweep:")
        assert not (folder / "sweep.mcap").exists() and not (folder / "figure.png").exists()
    assert json.loads((tmp_path / "s" / "manifest.json").read_text())["status"] == "complete"


def test_by_default_every_file_is_written(tmp_path: Path):
    assert DEFAULT_OUTPUTS == "corraoi.face.outputs:FolderOutputs"
    assert isinstance(default_outputs(), FolderOutputs)
    outcome = sweep(_grid(), out=tmp_path / "s", workers=1)
    for folder in outcome.folders:
        names = {p.name for p in folder.iterdir()}
        assert {"sweep.mcap", "sweep.rrd", "summary.json", "summary.md"} <= names
    assert (tmp_path / "s" / "results.parquet").is_dir()
