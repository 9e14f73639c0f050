"""`corraoi sweep -o DIR` and `corraoi reproduce`: streamed logs, summaries, figure, refusals."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.engine.simulation import Simulation
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.sweeplog.read import read_sweep


def run(*args: str):
    return CliRunner().invoke(main, list(args))


def test_sweep_out_writes_logs_summary_and_figure(tmp_path: Path):
    out = tmp_path / "s"
    res = run("sweep", "-i", "I2", "-p", "cucb,aoi-aware-cts", "-n", "6", "-T", "400",
              "-s", "2", "-o", str(out), "--checkpoints", "20")  # fmt: skip
    assert res.exit_code == 0, res.output
    for name in ("sweep.mcap", "sweep.rrd", "summary.json", "summary.md", "figure.png"):
        assert (out / name).is_file(), name
    assert not list(out.glob("*.partial"))
    summary = json.loads((out / "summary.json").read_text())
    # the summary is the library's own result for the same seeds
    sim = Simulation(load_instance("I2"), make_policy("cucb"), list(range(2, 8)), 400)
    sim.advance(400, record=False)
    assert summary["policies"]["cucb"]["regret_mean"] == float(np.mean(sim.regret))
    assert summary["theory"]["C"] == 0
    # the log's last checkpoint of each policy is that final figure too
    log = read_sweep(out / "sweep.mcap")
    assert log.policies == ["cucb", "aoi-aware-cts"]
    for name in log.policies:
        curve = log.curves[name]
        assert curve.t[-1] == 400 and np.all(np.diff(curve.t) > 0)
        assert curve.regret_mean[-1] == summary["policies"][name]["regret_mean"]
    md = (out / "summary.md").read_text()
    assert "| 1 |" in md and "Theorem 2 (CUCB)" in md
    assert (out / "figure.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a second run into the same DIR is refused, and --force overwrites
    again = run("sweep", "-i", "I2", "-p", "cucb", "-n", "2", "-T", "50", "-o", str(out))
    assert again.exit_code == 2 and "already holds a sweep" in again.output
    assert json.loads((out / "summary.json").read_text()) == summary
    forced = run("sweep", "-i", "I2", "-p", "cucb", "-n", "2", "-T", "50", "-o", str(out),
                 "--force")  # fmt: skip
    assert forced.exit_code == 0
    assert json.loads((out / "summary.json").read_text())["horizon"] == 50


def test_sweep_out_under_a_file_is_refused(tmp_path: Path):
    afile = tmp_path / "plain"
    afile.write_text("x")
    res = run("sweep", "-p", "ucb", "-n", "2", "-T", "10", "-o", str(afile / "sub"))
    assert res.exit_code == 2
    assert "cannot create the folder" in res.output and "Traceback" not in res.output


def test_identical_arms_are_a_stated_result(tmp_path: Path):
    same = tmp_path / "same.txt"
    same.write_text("0.5 0.5\n1 0\n1 0\n")
    res = run("sweep", "-i", str(same), "-p", "ucb,cts", "-n", "5", "-T", "200", "--json")
    assert res.exit_code == 0
    assert "every arm has the same mean" in res.stderr
    d = json.loads(res.stdout)
    # identical arms: the pathwise regret is exactly 0 in every run
    assert all(p["regret_mean"] == 0.0 for p in d["policies"].values())
    assert d["theory"]["bounds"]["cucb"]["value"] is None


def test_reproduce_small(tmp_path: Path):
    out = tmp_path / "paper"
    res = run("reproduce", "-o", str(out), "-n", "3", "-T", "200")
    assert res.exit_code == 0, res.output
    for inst in ("I1", "I2"):
        s = json.loads((out / inst / "summary.json").read_text())
        assert s["instance"]["name"] == inst and len(s["policies"]) == 12 and s["runs"] == 3
    text = (out / "summary.md").read_text()
    assert "Sweep: instance I1" in text and "Sweep: instance I2" in text
    stamp = (out / "I1" / "summary.json").stat().st_mtime_ns
    again = run("reproduce", "-o", str(out), "-n", "3", "-T", "200")  # up to date: read, not run
    assert again.exit_code == 0, again.output
    assert (out / "I1" / "summary.json").stat().st_mtime_ns == stamp
    other = run("reproduce", "-o", str(out), "-n", "4", "-T", "200")  # another sweep: refused
    assert other.exit_code == 2 and "already holds a sweep" in other.output
    assert "--resume" in other.output and "--force" in other.output


def test_an_instance_that_cannot_be_simulated_writes_nothing(tmp_path: Path):
    dead = tmp_path / "dead.txt"
    dead.write_text("1.0\n0\n0\n")
    out = tmp_path / "s"
    res = run("sweep", "-i", str(dead), "-n", "2", "-T", "10", "-o", str(out))
    assert res.exit_code == 2
    assert res.output.strip() == (
        "corraoi: error: instance dead: every arm has mean 0, the AoI grows without bound "
        "and regret is not defined"
    )
    assert not out.exists()


def test_empty_instance_name():
    res = run("instance", "show", "")
    assert res.exit_code == 2 and "empty instance name" in res.output


def test_an_interrupted_forced_sweep_keeps_its_chunks_and_resumes(tmp_path: Path, monkeypatch):
    import corraoi.experiments.chunks

    out = tmp_path / "s"
    args = ["sweep", "-p", "ucb,cts", "-n", "4", "-T", "300", "-o", str(out), "--checkpoints", "10",
            "--chunk", "2"]  # fmt: skip
    assert run(*args).exit_code == 0
    complete = (out / "sweep.mcap").read_bytes()
    real = corraoi.experiments.chunks.run_chunk
    calls = []

    def stop_midway(task, on_slots=None):  # type: ignore[no-untyped-def]
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(task, on_slots)

    monkeypatch.setattr(corraoi.experiments.chunks, "run_chunk", stop_midway)
    res = run(*args, "--force")
    assert res.exit_code == 130
    assert f"finished chunks are saved in {out}: --resume continues" in res.stderr
    # the old sweep's files are gone; the two finished chunks are kept
    assert sorted(p.name for p in out.iterdir()) == ["manifest.json", "parts"]
    assert len(list((out / "parts").glob("*.npz"))) == 2
    # an unfinished sweep is a sweep: refused without --force or --resume
    monkeypatch.setattr(corraoi.experiments.chunks, "run_chunk", real)
    again = run(*args)
    assert again.exit_code == 2 and "--resume to continue" in again.output
    resumed = run(*args, "--resume")
    assert resumed.exit_code == 0 and "(2 chunks run, 2 already done)" in resumed.stdout
    assert (out / "sweep.mcap").read_bytes() == complete
