"""ruff and mypy are part of the suite: the three folders stay clean.

mypy reads the package as installed: recorder/ and viewer/ are corraoi.recorder and
corraoi.viewer (pyproject.toml's package-dir), which mypy cannot map from the checkout's
folders, so it reads a tree of links (corraoi/ with recorder/ and viewer/ linked in) made in a
temporary folder; ``mypy corraoi recorder viewer`` in the checkout would check recorder/ as a
package ``recorder`` and leave every ``corraoi.recorder`` import untyped."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FOLDERS = ["corraoi", "recorder", "viewer"]
#: where pyproject.toml's package-dir installs recorder/ and viewer/ (tests/test_packaging.py)
INSTALLED_AS = {"recorder": "corraoi/recorder", "viewer": "corraoi/viewer"}


def _tool(name: str) -> str:
    exe = Path(sys.executable).parent / name
    found = str(exe) if exe.exists() else shutil.which(name)
    if not found:
        pytest.skip(f"{name} is not installed (pip install -e '.[test]')")
    return found


def test_ruff_clean():
    res = subprocess.run(
        [_tool("ruff"), "check", *FOLDERS, "tests", "benchmarks"],
        cwd=ROOT, capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr


def installed_tree(where: Path) -> Path:
    """``where/corraoi``: links to what corraoi/ holds, and the folders pyproject.toml's
    package-dir puts under it (corraoi/recorder -> recorder/, corraoi/viewer -> viewer/)."""
    tree = where / "corraoi"
    tree.mkdir()
    for entry in (ROOT / "corraoi").iterdir():
        if entry.name != "__pycache__":
            (tree / entry.name).symlink_to(entry)
    for folder, installed in INSTALLED_AS.items():
        (where / installed).symlink_to(ROOT / folder)
    return tree


def test_mypy_clean_and_reading_the_recorder_as_corraoi_recorder(tmp_path: Path):
    """mypy on the whole package finds nothing but a probe's two deliberate errors: the tree
    is the installed package, so a wrong type across the folders is an error (one mypy run
    for both, as each takes about 35 s from an empty cache here)."""
    tree = installed_tree(tmp_path)
    (tree / "_probe.py").write_text(
        "from corraoi.recorder.vocab import SLOT_TOPIC\n"
        "from corraoi.viewer.diffs import diff\n"
        "topic: int = SLOT_TOPIC\n"
        "report: int = diff\n"
    )
    res = subprocess.run(
        [_tool("mypy"), "--config-file", str(ROOT / "pyproject.toml"),
         "--cache-dir", str(ROOT / ".mypy_cache"), "-p", "corraoi"],
        cwd=tmp_path, capture_output=True, text=True,
    )  # fmt: skip
    errors = [line for line in res.stdout.splitlines() if ": error:" in line]
    assert [e.split(": error:")[0].rsplit("/", 1)[-1] for e in errors] == [
        "_probe.py:3", "_probe.py:4"], res.stdout + res.stderr  # fmt: skip
    assert all("Incompatible types" in e for e in errors), res.stdout
    assert res.returncode == 1, res.stdout + res.stderr


#: The main road of a run (issue 41): the face, the slot record's declaration and the sinks'
#: protocol (corraoi.recorder.sink and every sink of a run or a sweep), checked with
#: ``mypy --strict``; what they import is read (its types used) but not itself held to --strict.
STRICT_MODULES = [
    "corraoi.face",
    *(f"corraoi.face.{p.stem}" for p in sorted((ROOT / "corraoi" / "face").glob("*.py"))
      if p.stem != "__init__"),
    "corraoi.engine.slot_record",
    "corraoi.recorder.sink",
    "corraoi.recorder.slotlog.sink",
    "corraoi.recorder.rerun.sink",
    "corraoi.recorder.rerun.output",
    "corraoi.recorder.rerun.worker",
    "corraoi.recorder.live.foxglove",
    "corraoi.recorder.sweeplog.log",
    "corraoi.recorder.sweeplog.recording",
]  # fmt: skip


def _mypy(tmp_path: Path, cache: str, *args: str) -> subprocess.CompletedProcess[str]:
    """mypy on the tree of links in ``tmp_path``, with its own cache (other options)."""
    return subprocess.run(
        [_tool("mypy"), "--config-file", str(ROOT / "pyproject.toml"),
         "--cache-dir", str(ROOT / ".mypy_cache" / cache), *args],
        cwd=tmp_path, capture_output=True, text=True,
    )  # fmt: skip


def test_mypy_strict_on_the_main_road(tmp_path: Path):
    installed_tree(tmp_path)
    modules = [arg for name in STRICT_MODULES for arg in ("-m", name)]
    # untyped third-party calls: IPython.display.display (the notebook viewer's only call into
    # IPython) and mcap's Writer (flush, finish: the sweep log's MCAP writer)
    res = _mypy(tmp_path, "strict", "--strict", "--follow-imports=silent",
                "--untyped-calls-exclude=IPython", "--untyped-calls-exclude=mcap",
                *modules)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr


#: A wrong value on the main road, one per line: each must be a type error, so the run's
#: configuration (a RunConfig) and its blocks (SlotBlock) are typed from the face to every sink.
MAIN_ROAD_PROBE = """\
from pathlib import Path

from corraoi.engine.block import RunConfig, SlotBlock
from corraoi.face.live import FoxgloveChoice
from corraoi.face.recording import Outlets, Plan, Recorded, record_run
from corraoi.face.slots import slots_of
from corraoi.recorder.rerun.sink import LocalRecording
from corraoi.recorder.rerun.worker import RerunWorker
from corraoi.recorder.sink import RunRecording, Sink
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.stats import SweepPoint

def probe(config: RunConfig, block: SlotBlock, worker: RerunWorker, point: SweepPoint,
          recording: RunRecording, done: Recorded, live: FoxgloveChoice) -> None:
    record_run("I1", "a.mcap")
    slots_of("I1")
    for b in slots_of(config): b.nothing
    Plan(config.label, mcap=Path("a.mcap"), rrd=None)
    worker.open(config.seed, rrd_path="a.rrd")
    LocalRecording(config.policy)
    McapSink("a.mcap", config).write(point)
    recording.write(point)
    record_run(config, "a.mcap", sinks=[McapSink("b.mcap", config), Sink[SweepPoint]()])
    record_run(config, "a.mcap", on_block=lambda b: b.nothing)
    record_run(config, "a.mcap", rerun=live)
    Outlets(live=worker)
    done.summary.nothing
    live.sink(config, lambda: False).nothing
"""


def test_the_main_road_is_typed(tmp_path: Path):
    """Each line of the probe after the definition passes a wrong value along the road."""
    tree = installed_tree(tmp_path)
    (tree / "_road.py").write_text(MAIN_ROAD_PROBE)
    res = _mypy(tmp_path, "road", "--follow-imports=silent", str(tree / "_road.py"))
    lines = MAIN_ROAD_PROBE.splitlines()
    first = lines.index("def probe(config: RunConfig, block: SlotBlock, worker: RerunWorker, "
                        "point: SweepPoint,") + 3  # fmt: skip
    wrong = {n for n in range(first, len(lines) + 1)}
    flagged = {int(n) for n in re.findall(r"_road\.py:(\d+): error:", res.stdout)}
    assert wrong - flagged == set(), res.stdout
