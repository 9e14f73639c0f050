"""A sweep folder's figures drawn by a forked worker (viewer/figure_worker.py, issue 22):
``corraoi sweep -o`` uses it and its figures are the bytes drawn in-process, nothing is lost
when the worker dies, and without matplotlib each figure is one warning.

The worker forks only a process with no other thread (a pytest-xdist worker has some), so
each case runs in a fresh interpreter."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

_SCRIPT = r"""
import json, os, signal, sys
from pathlib import Path
how, out = sys.argv[1], Path(sys.argv[2])
if how == "no-matplotlib":
    sys.modules["matplotlib"] = None  # as on a machine without the plot extra
from corraoi.experiments.sweeps import sweep
from corraoi.experiments.grid import build_grid
from corraoi.viewer.figure_worker import FigureWorker
from corraoi.face.outputs import FolderOutputs

grid = build_grid(instances=["I1", "I2"], policies=["ucb", "cts"], horizons=[300], runs=8)
notes = []
worker = FigureWorker.start()
started = worker is not None and worker.process.pid
if how == "killed":
    os.kill(worker.process.pid, signal.SIGKILL)  # dead before it draws anything
    worker.process.join()
with worker:
    sweep(grid, out=out, outputs=FolderOutputs(worker), workers=1, warn=notes.append)
started = started and not worker.process.is_alive()
print(json.dumps({"notes": notes, "started_and_stopped": bool(started)}))
"""


def _run(how: str, out: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", _SCRIPT, how, str(out)], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    result: dict = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _drawn_here(folder: Path, tmp_path: Path) -> bytes:
    """The figure of a group's sweep log as drawn in this process."""
    from corraoi.recorder.sweeplog.read import read_sweep
    from corraoi.viewer.figure import draw_figure

    out = tmp_path / f"here-{folder.name}.png"
    return draw_figure(read_sweep(folder / "sweep.mcap"), out).read_bytes()


def test_sweep_o_draws_its_figures_in_the_worker_as_they_are_drawn_in_process(tmp_path: Path):
    code = ("import sys, corraoi.viewer.figure_worker as w; calls = []\n"
            "real = w.FigureWorker.draw\n"
            "def draw(self, log, out):\n    calls.append(str(out)); real(self, log, out)\n"
            "w.FigureWorker.draw = draw\n"
            "import atexit; atexit.register(lambda: print('DRAWN', len(calls)))\n"
            "sys.argv = ['corraoi', 'sweep', '-i', 'I1,I2', '-p', 'ucb,cts', '-T', '300',"
            " '-n', '8', '-o', sys.argv[1]]\n"
            "from corraoi.cli import run; run()\n")  # fmt: skip
    folder = tmp_path / "cli"
    done = subprocess.run([sys.executable, "-c", code, str(folder)],
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "DRAWN 2" in done.stdout  # the command forked the worker and it drew both
    for group in ("I1", "I2"):
        fig = (folder / group / "figure.png").read_bytes()
        assert fig[:8] == b"\x89PNG\r\n\x1a\n" and fig == _drawn_here(folder / group, tmp_path)
        assert (folder / group / "sweep.rrd").exists()
    assert json.loads((folder / "manifest.json").read_text())["status"] == "complete"
    assert not list(folder.rglob("*.partial"))


def test_figures_a_dead_worker_did_not_draw_are_drawn_here(tmp_path: Path):
    got = _run("killed", tmp_path / "s")
    assert got["started_and_stopped"] and got["notes"] == []
    for group in ("I1", "I2"):
        folder = tmp_path / "s" / group
        assert (folder / "figure.png").read_bytes() == _drawn_here(folder, tmp_path)
    manifest = json.loads((tmp_path / "s" / "manifest.json").read_text())
    assert manifest["status"] == "complete"


def test_without_matplotlib_the_worker_path_warns_once_per_figure(tmp_path: Path):
    got = _run("no-matplotlib", tmp_path / "s")
    assert len(got["notes"]) == 2, got["notes"]
    for group, note in zip(("I1", "I2"), got["notes"], strict=True):
        assert note.startswith(f"{tmp_path / 's' / group / 'figure.png'} not written:")
        assert "plot" in note  # names the extra to install
        assert (tmp_path / "s" / group / "sweep.rrd").exists()
        assert not (tmp_path / "s" / group / "figure.png").exists()


_ORPHAN = r"""
import sys, time
import corraoi.viewer.figure_worker as fw
from corraoi.recorder.rerun.worker import RerunWorker
fw.draw_from_log = lambda log, out: time.sleep(60)  # a figure that takes a minute
figures = fw.FigureWorker.start()
figures.draw("sweep.mcap", "figure.png")  # busy: it does not read the pipe meanwhile
rerun = RerunWorker.start(lambda: time.sleep(60))  # busy before it imports Rerun
print(figures.process.pid, rerun.process.pid, flush=True)
time.sleep(60)  # killed long before
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"  # a zombie is dead
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_worker_dies_with_its_parent(tmp_path: Path):
    """A SIGKILLed sweep's figure worker used to finish its figure and publish it into the
    folder a resumed sweep was writing (and to hold the folder's inherited lock meanwhile);
    both workers, busy, die with the parent."""
    import signal
    import time

    proc = subprocess.Popen([sys.executable, "-c", _ORPHAN], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        pids = [int(p) for p in proc.stdout.readline().split()]
        assert len(pids) == 2 and all(_alive(p) for p in pids)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 10
        while any(_alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(_alive(p) for p in pids), "a worker outlived its parent"
    finally:
        proc.kill()


def test_a_figure_another_process_is_writing_is_refused_and_left_alone(tmp_path: Path):
    """draw_figure writes through the recorder's locked .partial: a second writer of the same
    figure is told who holds it instead of renaming the other's file away."""
    from corraoi.errors import CorraoiError
    from corraoi.experiments.grid import build_grid
    from corraoi.experiments.sweeps import sweep
    from corraoi.face.outputs import FolderOutputs
    from corraoi.recorder.sweeplog.read import read_sweep
    from corraoi.viewer.figure import draw_figure

    grid = build_grid(instances=["I1"], policies=["ucb"], horizons=[200], runs=4)
    sweep(grid, out=tmp_path / "sw", workers=1, outputs=FolderOutputs())
    log = read_sweep(tmp_path / "sw" / "sweep.mcap")
    out = tmp_path / "fig.png"
    holder = subprocess.Popen(
        [sys.executable, "-c", "import fcntl, sys, time; f = open(sys.argv[1], 'wb'); "
         "f.write(b'theirs'); f.flush(); fcntl.flock(f, fcntl.LOCK_EX); print(1, flush=True); "
         "time.sleep(60)", str(out) + ".partial"],
        stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "1"
        busy = rf"fig\.png\.partial: is being written by process {holder.pid}"
        with pytest.raises(CorraoiError, match=busy):
            draw_figure(log, out)
        assert (tmp_path / "fig.png.partial").read_bytes() == b"theirs" and not out.exists()
    finally:
        holder.kill()
        holder.wait()
    assert draw_figure(log, out).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # then it is ours
    assert not (tmp_path / "fig.png.partial").exists()


_BROKEN = r"""
import sys
import corraoi.viewer.figure as figure
def broken(*args, **kwargs):
    raise ValueError("the data broke\nthe drawing")
figure.draw_figure = broken  # read when each figure is drawn, in the worker or here
sys.argv = ["corraoi", "sweep", "-i", "I1,I2", "-p", "ucb", "-T", "200", "-n", "4", "-o",
            sys.argv[1]]
from corraoi.cli import run; run()
"""


def test_a_figure_that_fails_to_draw_is_one_line_after_the_folder_is_complete(tmp_path: Path):
    # it was the drawing's own traceback, and the folder was left without its manifest's
    # "complete" nor its kept plug-ins though every result was written
    folder = tmp_path / "s"
    done = subprocess.run([sys.executable, "-c", _BROKEN, str(folder)], capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    line = done.stderr.strip()
    assert "\n" not in line, line
    assert line == (f"corraoi: error: {folder / 'I1' / 'figure.png'} not written: ValueError: "
                    "the data broke the drawing (the sweep's results are complete; redraw it: "
                    f"corraoi figure {folder / 'I1' / 'sweep.mcap'} -o "
                    f"{folder / 'I1' / 'figure.png'}); and 1 more figure")  # fmt: skip
    assert json.loads((folder / "manifest.json").read_text())["status"] == "complete"
    for group in ("I1", "I2"):
        assert (folder / group / "sweep.rrd").exists()
        assert (folder / group / "summary.json").exists()
        assert not (folder / group / "figure.png").exists()
    assert not list(folder.rglob("*.partial"))
