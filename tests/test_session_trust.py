"""Trust inside one long session (issue 45, items 1 and 2): the code that ran decides whether a
run on disk is the run asked for, whatever ran earlier in the same process; re-running a
notebook cell is the normal case; a sweep's kept code never leaks into the session.

A notebook cell is emulated as IPython runs one: its text compiled under a file name of its
own, registered in ``linecache``, and executed in the session's ``__main__`` namespace."""

from __future__ import annotations

import hashlib
import itertools
import linecache
import os
import sys
import time
from pathlib import Path
from typing import Any

import pytest

import corraoi
from corraoi.errors import CodeChanged, ConfigError, OutputError
from corraoi.recorder.slotlog.reader import open_log

CELL = '''
import numpy as np
from corraoi import Policy


class RoundRobin(Policy):
    name = "round-robin"

    def select(self, t, state):
        return np.full(state.runs, (t - 1) % state.arms)
'''
#: the cell edited: its select plays arm 1 only
EDITED = CELL.replace("(t - 1) % state.arms", "0")

PLUGIN = CELL.replace('"round-robin"', '"rr-file"')
PLUGIN_EDITED = EDITED.replace('"round-robin"', '"rr-file"')

_cells = itertools.count(1)


def run_cell(text: str, namespace: dict[str, Any], *, linecache_entry: bool = True) -> Any:
    """Execute ``text`` as IPython runs a cell (its own file name, kept in linecache); without
    ``linecache_entry``, as ``exec`` does (no source text anywhere). Returns the class."""
    name = f"<cell-{os.getpid()}-{next(_cells)}>"
    if linecache_entry:
        linecache.cache[name] = (len(text), None, text.splitlines(True), name)
    exec(compile(text, name, "exec"), namespace)
    return namespace["RoundRobin"]


def _pulls(run: Any) -> tuple[int, ...]:
    return tuple(int(p) for p in corraoi.load(run.path).summary.pulls)


def named(text: str, name: str) -> str:
    """``text`` with its policy called ``name`` (a session registers each name once)."""
    return text.replace('"round-robin"', f'"{name}"').replace('"rr-file"', f'"{name}"')


@pytest.fixture
def session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_an_edited_cell_class_is_another_run_never_the_old_one(session: Path):
    # classes defined in the session's __main__ (which has a __file__ here, as under
    # `python script.py`, `%run` or pytest): the file's bytes are not the class's code
    ns: dict[str, Any] = {"__name__": "__main__"}
    first = corraoi.record(run_cell(CELL, ns), horizon=200, path="runs/rr.mcap", rrd=False)
    assert _pulls(first) == (50, 50, 50, 50)
    edited = run_cell(EDITED, ns)
    with pytest.raises(OutputError) as info:
        corraoi.record(edited, horizon=200, path="runs/rr.mcap", rrd=False)
    said = str(info.value)
    assert "force=True" in said and "--force" not in said and "code" in said, said
    assert _pulls(corraoi.load("runs/rr.mcap")) == (50, 50, 50, 50)  # untouched
    again = corraoi.record(edited, horizon=200, path="runs/rr.mcap", rrd=False, force=True)
    assert _pulls(again) == (200, 0, 0, 0)
    # the edited cell run once more, and the run is up to date: nothing runs
    before = os.stat("runs/rr.mcap").st_mtime_ns
    same = corraoi.record(run_cell(EDITED, ns), horizon=200, path="runs/rr.mcap", rrd=False)
    assert same.path == again.path and os.stat("runs/rr.mcap").st_mtime_ns == before
    # an instance of the first class is the first code again: another run, refused
    with pytest.raises(OutputError):
        corraoi.record(run_cell(CELL, ns)(), horizon=200, path="runs/rr.mcap", rrd=False)


def test_an_exec_defined_class_is_known_by_its_code(session: Path):
    ns: dict[str, Any] = {"__name__": "cells_without_source"}  # no module, no linecache
    cell, edited = named(CELL, "rr-exec"), named(EDITED, "rr-exec")
    cls = run_cell(cell, ns, linecache_entry=False)
    first = corraoi.record(cls, horizon=200, path="runs/x.mcap", rrd=False)
    sha = open_log(first.path).config.policy.sha256
    assert len(sha) == 64  # the log names the code, even without a source text
    # the same code defined again: the same run, up to date
    same = corraoi.record(run_cell(cell, ns, linecache_entry=False), horizon=200,
                          path="runs/x.mcap", rrd=False)  # fmt: skip
    assert open_log(same.path).config.policy.sha256 == sha
    with pytest.raises(OutputError, match="force=True"):
        corraoi.record(run_cell(edited, ns, linecache_entry=False), horizon=200,
                       path="runs/x.mcap", rrd=False)  # fmt: skip
    again = corraoi.record(ns["RoundRobin"], horizon=200, path="runs/x.mcap", rrd=False,
                           force=True)  # fmt: skip
    assert _pulls(again) == (200, 0, 0, 0)
    assert open_log(again.path).config.policy.sha256 != sha


def test_a_module_edited_and_reloaded_is_another_run(session: Path):
    import importlib

    (session / "rrmod.py").write_text(named(PLUGIN, "rr-mod"))
    sys.path.insert(0, str(session))
    try:
        mod = importlib.import_module("rrmod")
        corraoi.record(mod.RoundRobin, horizon=200, path="runs/m.mcap", rrd=False)
        (session / "rrmod.py").write_text(named(PLUGIN_EDITED, "rr-mod") + "\n# edited\n")
        mod = importlib.reload(mod)
        with pytest.raises(OutputError, match="force=True"):
            corraoi.record(mod.RoundRobin, horizon=200, path="runs/m.mcap", rrd=False)
        with pytest.raises(OutputError, match="force=True"):
            corraoi.record("rrmod:RoundRobin", horizon=200, path="runs/m.mcap", rrd=False)
    finally:
        sys.path.remove(str(session))
        sys.modules.pop("rrmod", None)


def test_a_log_of_other_engine_sources_is_not_up_to_date(
    session: Path, monkeypatch: pytest.MonkeyPatch
):
    import corraoi.provenance as provenance

    real = provenance.versions()
    older = {**real, "kernel_sources": "sha256:" + "0" * 64}
    with monkeypatch.context() as m:  # a log as an older corraoi wrote it
        m.setattr(provenance, "versions", lambda: older)
        corraoi.record("ucb", horizon=100, path="runs/u.mcap", rrd=False)
    with pytest.raises(OutputError) as info:
        corraoi.record("ucb", horizon=100, path="runs/u.mcap", rrd=False)
    said = str(info.value)
    assert "engine" in said and "sha256:0000000000000000" in said and "force=True" in said, said
    fresh = corraoi.record("ucb", horizon=100, path="runs/u.mcap", rrd=False, force=True)
    assert open_log(fresh.path).provenance["kernel_sources"] == real["kernel_sources"]
    assert corraoi.record("ucb", horizon=100, path="runs/u.mcap", rrd=False).path == fresh.path


# ---------------------------------------------------------------------------- sweeps


def _sweep(policies: Any, out: str, **kw: Any) -> corraoi.Sweep:
    return corraoi.sweep("I1", policies, runs=4, horizon=200, checkpoints=10, out=out, **kw)


def test_a_cell_run_twice_records_its_run_once(session: Path):
    ns: dict[str, Any] = {"__name__": "__main__"}
    cls = run_cell(CELL, ns)
    sw = _sweep(["ucb", cls], "sw")
    first = sw.record("worst", policy=cls, rrd=False)
    before = os.stat(first.path).st_mtime_ns
    again = corraoi.load("sw").record("worst", policy=cls, rrd=False)  # the cell run again
    assert again.path == first.path and os.stat(first.path).st_mtime_ns == before
    with pytest.raises(ConfigError) as info:  # Python's words, not the command line's
        sw.record(99, policy=cls)
    assert str(info.value).startswith("which=99: out of range") and "--" not in str(info.value)
    runs = sw.record_each("worst", folder="each")
    assert [r.path for r in sw.record_each("worst", folder="each")] == [r.path for r in runs]


def test_sweeping_into_a_complete_folder_of_the_same_sweep_returns_it(session: Path):
    first = _sweep(["ucb", "cucb"], "sw")
    stamps = {p: p.stat().st_mtime_ns for p in Path("sw").rglob("*") if p.is_file()}
    start = time.perf_counter()
    second = _sweep(["ucb", "cucb"], "sw")
    quick = time.perf_counter() - start
    assert second.folder == first.folder
    assert second.summary == first.summary
    assert second.runs.equals(first.runs)
    assert {p: p.stat().st_mtime_ns for p in Path("sw").rglob("*") if p.is_file()} == stamps
    assert quick < 1.5, quick  # read, not run
    resumed = _sweep(["ucb", "cucb"], "sw", resume=True)
    assert resumed.summary == first.summary
    assert {p: p.stat().st_mtime_ns for p in Path("sw").rglob("*") if p.is_file()} == stamps
    with pytest.raises(ConfigError) as info:  # another sweep: Python's words, not the CLI's
        _sweep(["ucb"], "sw")
    said = str(info.value)
    assert "resume=True" in said and "force=True" in said and "--" not in said, said


def test_resume_after_an_edit_in_one_process_is_refused(session: Path):
    ns: dict[str, Any] = {"__name__": "__main__"}
    _sweep(run_cell(CELL, ns), "sw")
    manifest = Path("sw/manifest.json").read_bytes()
    with pytest.raises(CodeChanged) as info:
        corraoi.sweep("I1", run_cell(EDITED, ns), runs=6, horizon=200, checkpoints=10,
                      out="sw", resume=True)  # fmt: skip
    assert "--" not in str(info.value), str(info.value)
    assert Path("sw/manifest.json").read_bytes() == manifest  # no second cell
    # a plug-in file edited in the same session: the same refusal as in a fresh process
    Path("rr.py").write_text(PLUGIN)
    _sweep("rr.py:RoundRobin", "sf")
    Path("rr.py").write_text(PLUGIN_EDITED)
    with pytest.raises(CodeChanged):
        corraoi.sweep("I1", "rr.py:RoundRobin", runs=6, horizon=200, checkpoints=10, out="sf",
                      resume=True)  # fmt: skip


def test_kept_code_stays_in_its_sweep_and_a_later_call_runs_the_file(session: Path):
    Path("rr.py").write_text(PLUGIN)
    sw = _sweep("rr.py:RoundRobin", "sw")
    Path("rr.py").write_text(PLUGIN_EDITED)
    kept = sw.record("worst", kept_code=True, path="runs/kept.mcap", rrd=False)
    old, new = (hashlib.sha256(t.encode()).hexdigest() for t in (PLUGIN, PLUGIN_EDITED))
    assert open_log(kept.path).config.policy.sha256 == old
    assert _pulls(kept) == (50, 50, 50, 50)
    now = corraoi.record("rr.py:RoundRobin", horizon=200, path="runs/now.mcap", rrd=False)
    assert open_log(now.path).config.policy.sha256 == new
    assert _pulls(now) == (200, 0, 0, 0)
    log = open_log(now.path)
    assert log.attachments[0][2] == PLUGIN_EDITED.encode()  # the bytes that ran: the file's
    with pytest.raises(CodeChanged):  # and without kept_code, the edited file is refused
        sw.record("worst", path="runs/again.mcap", rrd=False)


def test_a_kept_copy_that_registers_itself_never_replaces_the_users_class(session: Path):
    text = named(PLUGIN, "rr-registers").replace(
        "from corraoi import Policy", "from corraoi import Policy, register"
    )
    text = text.replace("class RoundRobin", "@register\nclass RoundRobin")
    Path("rr.py").write_text(text)
    sw = _sweep("rr.py:RoundRobin", "sw")
    Path("rr.py").write_text(text.replace("(t - 1) % state.arms", "0"))
    corraoi.record("rr.py:RoundRobin", horizon=200, path="runs/a.mcap", rrd=False)
    sw.record("worst", kept_code=True, path="runs/kept.mcap", rrd=False)
    by_name = corraoi.record("rr-registers", horizon=200, path="runs/b.mcap", rrd=False)
    assert _pulls(by_name) == (200, 0, 0, 0)  # the user's registration, the file's code


@pytest.mark.slow
def test_an_edited_cell_in_a_kernel_is_another_run(tmp_path: Path):
    """The same in a real notebook kernel (nbclient): the edited cell's run is refused, never
    the old run returned; with force=True it records the edited code; the cell run once more
    is up to date."""
    for name in ("nbclient", "nbformat", "ipykernel"):
        pytest.importorskip(name, reason=f'{name} is not installed (pip install -e ".[notebook]")')
    import nbformat
    from nbclient import NotebookClient

    root = Path(__file__).resolve().parent.parent
    record = ("try:\n    r = corraoi.record(RoundRobin, horizon=200, path='runs/rr.mcap', "
              "rrd=False{})\n    print('pulls', tuple(int(p) for p in r.summary.pulls))\n"
              "except corraoi.OutputError as exc:\n    print('refused', exc)")  # fmt: skip
    cells = [f"import sys; sys.path.insert(0, {str(root)!r})\nimport corraoi", CELL,
             record.format(""), EDITED, record.format(""), record.format(", force=True"),
             record.format("")]  # fmt: skip
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in cells])
    NotebookClient(nb, timeout=120, kernel_name="python3",
                   resources={"metadata": {"path": str(tmp_path)}}).execute()  # fmt: skip
    said = ["".join(o.get("text", "") for o in c.outputs).strip() for c in nb.cells]
    assert said[2] == "pulls (50, 50, 50, 50)", said
    assert said[4].startswith("refused runs/rr.mcap: already exists and holds another run "
                              "(the policy's code is sha256:"), said  # fmt: skip
    assert said[5] == "pulls (200, 0, 0, 0)" and said[6] == "pulls (200, 0, 0, 0)", said
