"""benchmarks/checkouts.py: a benchmark's child process runs the code of the checkout it
times (corraoi, and the recorder and viewer mapped into it), never the installed code."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("checkouts", ROOT / "benchmarks" / "checkouts.py")
assert _spec is not None and _spec.loader is not None
checkouts = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(checkouts)


def _child(pythonpath: str, code: str, cwd: Path) -> dict[str, str]:
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": pythonpath},
                         cwd=cwd, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    found: dict[str, str] = json.loads(out.stdout.strip().splitlines()[-1])
    return found


def test_a_copy_of_this_checkout_runs_its_own_recorder_and_viewer(tmp_path):
    """The copy's folder on PYTHONPATH alone gave its corraoi with the installed checkout's
    recorder and viewer (an editable install maps them); through pythonpath, all its own."""
    copy = tmp_path / "copy"
    for pkg in ("corraoi", *checkouts.MAPPED):
        shutil.copytree(ROOT / pkg, copy / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    assert not checkouts.old_layout(copy)
    code = ("import json, corraoi, corraoi.recorder, corraoi.viewer\n"
            "import corraoi.recorder.slotlog.chunks, corraoi.viewer.diffs\n"
            "mods = (corraoi, corraoi.recorder, corraoi.viewer,\n"
            "        corraoi.recorder.slotlog.chunks, corraoi.viewer.diffs)\n"
            "print(json.dumps({m.__name__: m.__file__ for m in mods}))\n")  # fmt: skip
    found = _child(checkouts.pythonpath(copy), code, tmp_path)
    assert set(found) == {"corraoi", "corraoi.recorder", "corraoi.viewer",
                          "corraoi.recorder.slotlog.chunks", "corraoi.viewer.diffs"}  # fmt: skip
    for name, file in found.items():
        assert Path(file).resolve().is_relative_to(copy.resolve()), (name, file)
    assert Path(found["corraoi.recorder"]).parent == (copy / "recorder").resolve()


def test_a_checkout_of_the_older_layout_is_read_through_its_top_level_packages(tmp_path):
    """Before the one-package layout, recorder/ and viewer/ were top-level packages:
    corraoi.recorder.x is that checkout's recorder.x, the same module."""
    old = tmp_path / "old"
    for pkg in ("corraoi", *checkouts.MAPPED):
        (old / pkg).mkdir(parents=True)
        (old / pkg / "__init__.py").write_text("")
    (old / "recorder" / "sub.py").write_text("VALUE = 41\n")
    (old / "corraoi" / "engine.py").write_text("from recorder import sub\n")
    assert checkouts.old_layout(old)
    code = ("import json, corraoi.recorder.sub as new, recorder.sub as top, corraoi.engine\n"
            "print(json.dumps({'new': new.__file__, 'same': str(new is top),"
            " 'value': str(new.VALUE), 'corraoi': corraoi.__file__}))")  # fmt: skip
    found = _child(checkouts.pythonpath(old), code, tmp_path)
    top = old.resolve()
    assert found == {"new": str(top / "recorder" / "sub.py"), "same": "True", "value": "41",
                     "corraoi": str(top / "corraoi" / "__init__.py")}  # fmt: skip


def test_a_folder_without_corraoi_is_refused(tmp_path):
    with pytest.raises(SystemExit, match="no corraoi/ package there"):
        checkouts.pythonpath(tmp_path)
