"""Sweep folders under hostile conditions (issue 32): manifests and summaries edited by hand
or damaged, folders left in any state by a sweep that failed or was killed, foreign files
under the names a sweep writes, a full disk, and drill-downs aimed at the sweep's own files.
Whatever came before, a folder is resumed or refused in one line; nothing is written
half-way under a final name; no file of a sweep is overwritten by its own drill-down."""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner, Result

from corraoi.cli import main
from corraoi.experiments.grid import build_grid
from corraoi.experiments.sweeps import sweep
from corraoi.face.outputs import FolderOutputs

pytest.importorskip("pyarrow")


def run(*args: object) -> Result:
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_or_ok(res: Result) -> str | None:
    """None when the command succeeded; else its one error line (never a traceback)."""
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    if res.exit_code == 0:
        return None
    lines = [ln for ln in res.output.splitlines() if ln.startswith("corraoi: error: ")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    return lines[0]


def refused(res: Result, code: int = 2) -> str:
    line = one_line_or_ok(res)
    assert line is not None and res.exit_code == code, res.output
    return line


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("hostile") / "sw"
    grid = build_grid(instances=["I1"], policies=["ucb", "cucb"], horizons=[300], runs=4,
                      seed=7, chunk=2, checkpoints=20)  # fmt: skip
    sweep(grid, out=out, workers=1, outputs=FolderOutputs())
    return out


@pytest.fixture
def folder(finished: Path, tmp_path: Path) -> Path:
    out = tmp_path / "sw"
    shutil.copytree(finished, out)
    return out


SWEEP = ["sweep", "-i", "I1", "-p", "ucb,cucb", "-n", 4, "-T", 300, "--seed", 7, "--chunk", 2,
         "--checkpoints", 20, "-j", 1]  # fmt: skip


def _results(folder: Path) -> Any:
    from corraoi.recorder.sweeplog.results import read_results

    return read_results(folder / "results.parquet").sort_values(["policy", "run", "t"])


# ---------------------------------------------------------------------------- manifests


@pytest.mark.parametrize("version", ["x", None, [1], 1.5, True, -1, 0])
def test_a_manifest_whose_format_version_is_not_a_number_is_one_line(folder: Path, version):
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["format_version"] = version
    (folder / "manifest.json").write_text(json.dumps(manifest))
    want = (f"corraoi: error: {folder / 'manifest.json'}: manifest format_version "
            f"{json.dumps(version)}: expected a whole number from 1 to 1 (a damaged manifest)")
    for args in (["info", folder], ["record", "--from", folder, "--run", 0, "--no-rrd", "-o",
                 folder.parent / "r.mcap"], ["compare", "--from", folder, "--no-rrd"],
                 [*SWEEP, "-o", folder, "--resume"]):  # fmt: skip
        assert refused(run(*args)) == want, args
    assert not (folder.parent / "r.mcap").exists()


def _mutations() -> list[tuple[str, Any]]:
    hostile: list[Any] = [None, "x", [], {}, -1, 10**30, 1e308, True, [[[[]]]], "\x1b[2J"]
    paths = ["grid", "grid.runs", "grid.seed", "grid.chunk", "grid.checkpoints", "grid.cells",
             "grid.cells.0", "grid.cells.0.horizon", "grid.cells.0.policy",
             "grid.cells.0.policy.name", "grid.cells.0.policy.params",
             "grid.cells.0.instance", "grid.cells.0.instance.p", "grid.cells.0.instance.Y",
             "grid.backend", "grid.baseline", "groups", "status", "provenance",
             "provenance.plugins"]  # fmt: skip
    return [(p, v) for p in paths for v in hostile]


@pytest.mark.parametrize(("where", "value"), _mutations(), ids=lambda x: repr(x)[:20])
def test_a_hostile_manifest_is_refused_in_one_line_or_read(folder: Path, where: str, value):
    manifest = json.loads((folder / "manifest.json").read_text())
    node: Any = manifest
    *up, last = where.split(".")
    for key in up:
        node = node[int(key)] if isinstance(node, list) else node[key]
    node[int(last) if isinstance(node, list) else last] = value
    (folder / "manifest.json").write_text(json.dumps(manifest))
    for args in (["info", folder], ["record", "--from", folder, "--run", 1, "--no-rrd", "-o",
                 folder.parent / "r.mcap", "--force"]):  # fmt: skip
        one_line_or_ok(run(*args))


def test_a_manifest_nested_too_deep_or_not_json_is_one_line(folder: Path):
    (folder / "manifest.json").write_text("[" * 100_000 + "]" * 100_000)
    assert "unreadable manifest" in refused(run("info", folder))
    (folder / "manifest.json").write_bytes(b"\xff\xfe\x00garbage")
    assert "unreadable manifest" in refused(run("record", "--from", folder, "--run", 0))


# ---------------------------------------------------------------------------- summaries


def test_a_summary_naming_a_policy_the_sweep_never_ran_is_not_trusted(folder: Path):
    summary = json.loads((folder / "summary.json").read_text())
    gap = summary["notable"]["pairs"][0]
    gap["policies"] = ["ucb", "not-swept"]
    (folder / "summary.json").write_text(json.dumps(summary))
    out = folder.parent / "g.mcap"
    res = run("record", "--from", folder, "--run", "widest-gap", "--no-rrd", "-o",
              str(folder.parent / "{from}.mcap"))  # fmt: skip
    assert one_line_or_ok(res) is None, res.output  # the runs named from the parts instead
    logs = sorted(p.name for p in folder.parent.glob("*.mcap"))
    assert len(logs) == 2 and all("widest-gap" in n for n in logs) and not out.exists()
    assert one_line_or_ok(run("info", folder)) is None


# ---------------------------------------------------------------------------- drill-down


@pytest.mark.parametrize("target", ["manifest.json", "sweep.mcap", "summary.json", "sweep.rrd",
                                    "parts/x.mcap", "results.parquet/x.mcap",
                                    "plugins/x.mcap"])  # fmt: skip
def test_no_file_of_a_sweep_is_overwritten_by_its_own_drill_down(folder: Path, target: str):
    before = {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()}
    path = folder / target
    opt = "--rrd" if target.endswith(".rrd") else "-o"
    args = ["record", "--from", folder, "--run", 0, "--cell", "ucb", opt, path, "--force"]
    if opt == "--rrd":
        args += ["-o", folder.parent / "r.mcap"]
    line = refused(run(*args))
    assert line.startswith(f"corraoi: error: {path}: is a file of the sweep in ")
    assert "not written over by the" in line
    assert {p: p.read_bytes() for p in folder.rglob("*") if p.is_file()} == before
    if target == "sweep.rrd":
        line = refused(run("compare", "--from", folder, "-o", path, "--force"))
        assert "is a file of the sweep" in line


# ---------------------------------------------------------------------------- any state


def _stale_partials(folder: Path) -> None:
    for name in ("sweep.mcap", "sweep.rrd", "summary.json", "summary.md", "figure.png",
                 "manifest.json"):  # fmt: skip
        (folder / f"{name}.partial").write_bytes(b"cut short by a kill")
    (folder / "results.parquet.partial").mkdir()
    (folder / "results.parquet.partial" / "junk").write_bytes(b"x")
    part = next((folder / "parts").glob("*.npz"))
    (part.parent / f"{part.name}.partial").write_bytes(part.read_bytes()[:100])


def _running(folder: Path) -> None:
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["status"] = "running"
    (folder / "manifest.json").write_text(json.dumps(manifest))


def _truncated_part(folder: Path) -> None:
    part = next((folder / "parts").glob("*.npz"))
    part.write_bytes(part.read_bytes()[: part.stat().st_size // 2])


def _missing_part(folder: Path) -> None:
    next((folder / "parts").glob("*.npz")).unlink()


def _outputs_gone(folder: Path) -> None:
    for name in ("sweep.mcap", "sweep.rrd", "summary.json", "figure.png"):
        (folder / name).unlink()
    shutil.rmtree(folder / "results.parquet")


def _copies_gone(folder: Path) -> None:
    shutil.rmtree(folder / "parts")


STATES = {"running": _running, "stale partials": _stale_partials,
          "truncated part": _truncated_part, "missing part": _missing_part,
          "outputs gone": _outputs_gone, "parts folder gone": _copies_gone}  # fmt: skip


@pytest.mark.parametrize("state", list(STATES))
def test_a_folder_left_in_any_state_resumes_to_the_same_results(folder: Path, finished: Path,
                                                                state: str):  # fmt: skip
    _running(folder)
    STATES[state](folder)
    res = run(*SWEEP, "-o", folder, "--resume")
    assert one_line_or_ok(res) is None, res.output
    assert json.loads((folder / "manifest.json").read_text())["status"] == "complete"
    assert _results(folder).reset_index(drop=True).equals(
        _results(finished).reset_index(drop=True))  # fmt: skip
    assert (folder / "sweep.mcap").read_bytes() == (finished / "sweep.mcap").read_bytes()
    assert not [p for p in folder.rglob("*.partial")]


@pytest.mark.parametrize("what", ["dir", "fifo"])
@pytest.mark.parametrize("name", ["sweep.mcap", "summary.json.partial", "results.parquet"])
def test_a_foreign_file_under_an_output_name_is_refused_in_one_line(folder: Path, name: str,
                                                                    what: str):  # fmt: skip
    target = folder / name
    if target.is_dir():
        shutil.rmtree(target)
    else:
        target.unlink(missing_ok=True)
    if what == "dir" and name != "results.parquet":
        target.mkdir()
    elif what == "fifo":
        os.mkfifo(target)
    else:  # a regular file where a folder (the dataset) goes
        target.write_bytes(b"not a dataset")
    res = run(*SWEEP, "-o", folder, "--resume")
    line = refused(res, res.exit_code)
    assert str(target) in line and res.exit_code in (1, 2), line
    res = run(*SWEEP, "-o", folder, "--resume")  # the same again: never stuck on itself
    assert refused(res, res.exit_code) == line


# ---------------------------------------------------------------------------- full disk


def test_a_full_disk_leaves_no_cut_short_recording_under_its_final_name(tmp_path: Path):
    """Issue 32, case 5: the Rerun file writer stopped by a full disk (the file size limit
    here; the recording passes it, nothing else does): one line, no sweep.rrd, and the folder
    resumes once there is room."""

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    args = ["sweep", "-p", "all", "-n", 4, "-T", 10_000, "-o", "sw"]
    res = subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=tmp_path,
                         capture_output=True, text=True, preexec_fn=limit, timeout=600)
    assert res.returncode == 1, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if not ln.startswith("corraoi: compiling")
             and not ln.startswith("corraoi:   ")]  # fmt: skip
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("corraoi: error: sw/sweep.rrd.partial: Rerun could not write "
                               "the whole recording")  # fmt: skip
    sw = tmp_path / "sw"
    assert not (sw / "sweep.rrd").exists()
    assert json.loads((sw / "manifest.json").read_text())["status"] == "running"
    again = subprocess.run([sys.executable, "-m", "corraoi", *map(str, args), "--resume"],
                           cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    from rerun.chunk import RrdReader

    assert RrdReader(str(sw / "sweep.rrd")).store() is not None  # whole: its footer reads
    assert not list(sw.glob("*.partial"))
