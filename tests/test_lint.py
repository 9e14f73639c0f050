"""ruff and mypy are part of the suite: the three folders stay clean.

mypy reads the package as installed: recorder/ and viewer/ are corraoi.recorder and
corraoi.viewer (pyproject.toml's package-dir), which mypy cannot map from the checkout's
folders, so it reads a tree of links (corraoi/ with recorder/ and viewer/ linked in) made in a
temporary folder; ``mypy corraoi recorder viewer`` in the checkout would check recorder/ as a
package ``recorder`` and leave every ``corraoi.recorder`` import untyped."""

from __future__ import annotations

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


def test_mypy_clean(tmp_path: Path):
    installed_tree(tmp_path)
    res = subprocess.run(
        [_tool("mypy"), "--config-file", str(ROOT / "pyproject.toml"),
         "--cache-dir", str(ROOT / ".mypy_cache"), "-p", "corraoi"],
        cwd=tmp_path, capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr


def test_mypy_reads_the_recorder_as_corraoi_recorder(tmp_path: Path):
    """The tree is the installed package: a wrong type across the folders is an error."""
    tree = installed_tree(tmp_path)
    (tree / "_probe.py").write_text(
        "from corraoi.recorder.vocab import SLOT_TOPIC\n"
        "from corraoi.viewer.diffs import diff\n"
        "topic: int = SLOT_TOPIC\n"
        "report: int = diff\n"
    )
    res = subprocess.run(
        [_tool("mypy"), "--config-file", str(ROOT / "pyproject.toml"),
         "--cache-dir", str(tmp_path / "cache"), str(tree / "_probe.py")],
        cwd=tmp_path, capture_output=True, text=True,
    )  # fmt: skip
    assert "_probe.py:3: error: Incompatible types" in res.stdout, res.stdout
    assert "_probe.py:4: error: Incompatible types" in res.stdout, res.stdout
