"""Grid sweeps (corraoi.experiments.grid, corraoi.experiments.sweeps, corraoi.experiments.cluster):
the grid, experiment files,
resume and append, a Dask LocalCluster on 127.0.0.1, and the failures each get one line."""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.errors import ConfigError
from corraoi.experiments.grid import build_grid, grid_from_file

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")

PLUGINS = Path(__file__).parent / "plugins"


def run(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, [str(a) for a in args])


def results(folder: Path):  # type: ignore[no-untyped-def]
    from corraoi.recorder.sweeplog.results import read_results

    return read_results(folder / "results.parquet")


def one_line(res, code: int = 2) -> str:  # type: ignore[no-untyped-def]
    assert res.exit_code == code, res.output
    lines = [ln for ln in res.output.splitlines() if ln.startswith("corraoi: error:")]
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    return lines[0]


# ---------------------------------------------------------------------------- the grid


def test_a_grid_is_the_product_of_its_lists():
    grid = build_grid(instances=["I1", "I2"], policies=["ucb", "sw-ucb", "ts"],
                      horizons=[100, 200], params={"c": [1.0, 2.0], "window": [10.0, 50.0]},
                      runs=3)  # fmt: skip
    # per instance and horizon: ucb x c (2) + sw-ucb x window x c (4) + ts (1)
    assert len(grid.cells) == 2 * 2 * 7
    labels = grid.labels()
    group = grid.groups()[("I1", 100)]
    names = [labels[c.key] for c in group]
    assert names[:2] == ["ucb(c=1)", "ucb(c=2)"] and names[-1] == "ts"
    assert len(set(names)) == len(names)
    assert {c.policy.params["window"] for c in group if c.policy.name == "sw-ucb"} == {10, 50}


def test_a_value_given_twice_is_one_cell_in_python_as_on_the_command_line():
    # corraoi.sweep(["I1", "I1"]) and horizon=[50, 50] ended in "the grid names the same
    # cell twice" (no argument named), while -i I1,I1, -T 50,50, a policy or a number of
    # sources given twice ran each once
    grid = build_grid(instances=["I1", "I2", "I1"], policies=["ucb", "cucb", "ucb"],
                      horizons=[60, 50, 60], runs=3)  # fmt: skip
    cells = [(c.instance.name, c.policy.name, c.horizon) for c in grid.cells]
    assert len(cells) == len(set(cells)) == 2 * 2 * 2
    assert cells[:4] == [("I1", "ucb", 60), ("I1", "cucb", 60), ("I1", "ucb", 50),
                         ("I1", "cucb", 50)]  # fmt: skip
    runner = CliRunner()
    out = runner.invoke(main, ["sweep", "-i", "I1,I1", "-p", "ucb", "-T", "40,40", "-n", "2"])
    assert out.exit_code == 0, out.output
    assert out.output.count("instance I1, 2 runs") == 1  # one cell: one table,
    assert out.output.count("\nucb ") == 2  # its row and its runs worth watching


def test_chunks_cover_the_missing_runs():
    grid = build_grid(instances=["I1"], policies=["ucb"], horizons=[10], runs=10, chunk=4)
    cell = grid.cells[0]
    assert [(c.start, c.stop) for c in grid.chunks(cell)] == [(0, 4), (4, 8), (8, 10)]
    assert [(c.start, c.stop) for c in grid.chunks(cell, covered=[(0, 4), (8, 10)])] == [(4, 8)]
    # runs 0..5 done in an earlier, smaller sweep: the rest in chunks of 4
    assert [(c.start, c.stop) for c in grid.chunks(cell, covered=[(0, 6)])] == [(6, 10)]


def test_experiment_file_equals_the_command_line(tmp_path: Path):
    f = tmp_path / "exp.toml"
    f.write_text(
        'instances = ["I1", "I2"]\npolicies = ["ucb", "cucb"]\nhorizons = [300]\nruns = 6\n'
        "seed = 2\nchunk = 3\ncheckpoints = 10\n[params]\nc = [1.0, 2.0]\n"
    )
    a = run("sweep", f, "-o", tmp_path / "a")
    b = run("sweep", "-i", "I1,I2", "-p", "ucb,cucb", "-T", "300", "-n", "6", "-s", "2",
            "--chunk", "3", "--checkpoints", "10", "--param", "c=1,2",
            "-o", tmp_path / "b")  # fmt: skip
    assert a.exit_code == 0 and b.exit_code == 0, a.output + b.output
    assert results(tmp_path / "a").equals(results(tmp_path / "b"))
    for inst in ("I1", "I2"):
        assert (tmp_path / "a" / inst / "sweep.mcap").read_bytes() == (
            tmp_path / "b" / inst / "sweep.mcap"
        ).read_bytes()
    # the command line overrides the file
    grid = grid_from_file(f, runs=9)
    assert grid.runs == 9 and len(grid.cells) == 2 * 4


@pytest.mark.parametrize(
    ("content", "suffix", "needle"),
    [
        ('instances = ["I1"]\npolicies = ["ucb"]\nhorizon = [10]\n', ".toml",
         "unknown key 'horizon'"),
        ('instances = ["I1"\n', ".toml", "invalid TOML"),
        ('{"instances": ["I1"], "policies": ["ucb"], "runs": "many"}', ".json",
         "runs must be an integer, got 'many'"),
        ('policies = ["ucb"]\n', ".toml", "missing key 'instances'"),
        ('instances = ["I1"]\npolicies = ["ucb"]\n[params]\nc = ["x"]\n', ".toml",
         "params.c must be a number or a list of numbers"),
        ('instances = ["I1"]\npolicies = ["ucb"]\n[params]\nwindow = [3]\n', ".toml",
         "parameter window does not apply to ucb"),
        ("[" * 5000 + "]" * 5000, ".json", "nested too deeply"),
    ],
)
def test_a_malformed_experiment_file_gets_one_line(tmp_path: Path, content: str, suffix: str,
                                                   needle: str):  # fmt: skip
    f = tmp_path / f"exp{suffix}"
    f.write_text(content)
    line = one_line(run("sweep", f, "-o", tmp_path / "out"))
    assert needle in line and str(f) in line
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- resume, append


def test_appending_runs_policies_and_values_equals_running_them_all_at_once(tmp_path: Path):
    base = ["-i", "I1,I2", "-T", "400", "--chunk", "4", "--checkpoints", "12"]
    assert run("sweep", *base, "-p", "ucb", "-n", "5", "-o", tmp_path / "grow").exit_code == 0
    res = run("sweep", *base, "-p", "ucb,sw-ucb", "--param", "window=20,200", "-n", "11",
              "-o", tmp_path / "grow", "--resume")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "already done" in res.stdout
    once = run("sweep", *base, "-p", "ucb,sw-ucb", "--param", "window=20,200", "-n", "11",
               "-o", tmp_path / "once")  # fmt: skip
    assert once.exit_code == 0
    a, b = results(tmp_path / "grow"), results(tmp_path / "once")
    assert len(a) == 2 * 3 * 11 * a["t"].nunique()  # instances x cells x runs x checkpoints
    assert a.equals(b)
    for inst in ("I1", "I2"):
        assert (tmp_path / "grow" / inst / "sweep.mcap").read_bytes() == (
            tmp_path / "once" / inst / "sweep.mcap"
        ).read_bytes()
    from corraoi.recorder.style import config_colors, policy_color
    from corraoi.recorder.sweeplog.read import read_sweep

    colors = config_colors(read_sweep(tmp_path / "once" / "I1" / "sweep.mcap").config)
    shades = [rgb for name, rgb in colors.items() if name.startswith("sw-ucb(")]
    assert len(shades) == 2 and shades[0] != shades[1]  # one policy's values told apart
    assert colors["ucb"] == policy_color("ucb")


def test_a_sweep_killed_at_a_random_moment_then_resumed_equals_an_uninterrupted_one(
    tmp_path: Path,
):
    args = ["sweep", "-p", "ucb,cts,sw-ucb", "-n", "40", "-T", "3000", "--chunk", "4",
            "--checkpoints", "20", "-j", "1"]  # fmt: skip
    assert run(*args, "-o", tmp_path / "whole").exit_code == 0
    rng = random.Random(os.getpid())
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "corraoi", *args, "-o", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    deadline = time.monotonic() + 60
    while not (out / "parts").is_dir() and time.monotonic() < deadline:
        time.sleep(0.02)
    time.sleep(rng.uniform(0.0, 1.0))
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    res = run(*args, "-o", out, "--resume")
    assert res.exit_code == 0, res.output
    assert results(out).equals(results(tmp_path / "whole"))
    assert (out / "sweep.mcap").read_bytes() == (tmp_path / "whole" / "sweep.mcap").read_bytes()
    assert not list((out / "parts").glob("*.partial"))


def test_resume_refusals(tmp_path: Path):
    assert "needs -o DIR" in one_line(run("sweep", "-p", "ucb", "-n", "2", "-T", "10", "--resume"))
    line = one_line(run("sweep", "-p", "ucb", "-n", "2", "-T", "10", "-o", tmp_path / "n",
                        "--resume"))  # fmt: skip
    assert "no sweep to resume" in line
    assert run("sweep", "-p", "ucb", "-n", "2", "-T", "50", "-o", tmp_path / "s",
               "--chunk", "1").exit_code == 0  # fmt: skip
    line = one_line(run("sweep", "-p", "ucb", "-n", "2", "-T", "50", "-o", tmp_path / "s",
                        "--resume", "--chunk", "2"))  # fmt: skip
    assert "in chunks of 1 runs; --resume keeps them" in line


# ---------------------------------------------------------------------------- Dask


def test_a_local_cluster_gives_the_in_process_numbers_and_bytes(tmp_path: Path):
    plugin = f"{PLUGINS / 'eps_greedy.py'}:EpsilonGreedy"
    args = ["sweep", "-i", "I1,I2", "-p", f"ucb,cts,{plugin}", "-n", "12", "-T", "1500",
            "--chunk", "5", "--checkpoints", "15"]  # fmt: skip
    local = run(*args, "-o", tmp_path / "here")
    cluster = run(*args, "-o", tmp_path / "cluster", "--scheduler", "local:2")
    assert local.exit_code == 0 and cluster.exit_code == 0, cluster.output
    assert results(tmp_path / "cluster").equals(results(tmp_path / "here"))
    for inst in ("I1", "I2"):
        a = (tmp_path / "cluster" / inst / "sweep.mcap").read_bytes()
        assert a == (tmp_path / "here" / inst / "sweep.mcap").read_bytes()
        sa = json.loads((tmp_path / "cluster" / inst / "summary.json").read_text())
        sb = json.loads((tmp_path / "here" / inst / "summary.json").read_text())
        for name, entry in sa["policies"].items():
            assert entry["regret_mean"] == sb["policies"][name]["regret_mean"]


def test_a_dying_worker_is_retried_and_nothing_is_lost(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    plugin = f"{PLUGINS / 'dies_once.py'}:DiesOnce"
    args = ["sweep", "-p", plugin, "-n", "8", "-T", "200", "--chunk", "4", "--checkpoints", "5"]
    assert run(*args, "-o", tmp_path / "here").exit_code == 0  # no marker: never dies
    monkeypatch.setenv("CORRAOI_TEST_MARKER", str(tmp_path / "died"))
    res = run(*args, "-o", tmp_path / "cluster", "--scheduler", "local:2")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "died").exists()  # a worker did die
    assert results(tmp_path / "cluster").equals(results(tmp_path / "here"))


def test_a_chunk_that_always_kills_its_worker_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    plugin = f"{PLUGINS / 'dies_once.py'}:DiesOnce"
    monkeypatch.setenv("CORRAOI_TEST_MARKER", str(tmp_path / "died"))
    monkeypatch.setenv("CORRAOI_TEST_ALWAYS_DIE", "1")
    out = tmp_path / "c"
    res = run("sweep", "-p", plugin, "-n", "8", "-T", "200", "--chunk", "4", "--checkpoints", "5",
              "-o", out, "--scheduler", "local:2")  # fmt: skip
    line = one_line(res, code=1)
    assert "killed" in line and "--resume continues" in line
    assert len(list((out / "parts").glob("*.npz"))) == 1  # the healthy chunk is saved


def test_an_unreachable_scheduler_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setenv("CORRAOI_CONNECT_TIMEOUT", "2")
    import importlib

    import corraoi.experiments.cluster

    importlib.reload(corraoi.experiments.cluster)
    res = run("sweep", "-p", "ucb", "-n", "2", "-T", "10", "--scheduler", f"tcp://127.0.0.1:{port}")
    assert "cannot reach the scheduler" in one_line(res, code=1)
    for bad, needle in (("local:0", "expected local:N"), ("nowhere", "expected tcp://HOST:PORT")):
        assert needle in one_line(run("sweep", "-p", "ucb", "-n", "2", "-T", "10",
                                      "--scheduler", bad))  # fmt: skip


def test_the_default_sweep_never_imports_dask():
    code = (
        "import sys\n"
        "from corraoi.experiments.sweeps import sweep\n"
        "from corraoi.experiments.grid import build_grid\n"
        "sweep(build_grid(instances=['I1'], policies=['ucb'], horizons=[50], runs=2))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_library_sweep_with_a_client(tmp_path: Path):
    dd = pytest.importorskip("dask.distributed")
    from corraoi.experiments.sweeps import sweep

    grid = build_grid(instances=["I2"], policies=["cucb"], horizons=[300], runs=6, chunk=2)
    # an in-process cluster (inproc:// transport: no socket at all)
    with dd.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                         dashboard_address=None) as cluster:  # fmt: skip
        with dd.Client(cluster) as client:
            remote = sweep(grid, client=client)
    here = sweep(grid)
    a, b = remote.summaries[0]["policies"]["cucb"], here.summaries[0]["policies"]["cucb"]
    for key in ("regret_mean", "regret_ci95", "estimator_mean", "best_arm_share", "pulls_mean"):
        assert a[key] == b[key], key
    with pytest.raises(ConfigError, match="grid has no cell"):
        from corraoi.experiments.grid import Grid

        Grid((), runs=1)
    assert np.isfinite(here.summaries[0]["policies"]["cucb"]["regret_mean"])


def test_a_folder_another_sweep_is_writing_is_refused_naming_it(tmp_path: Path):
    from corraoi.files.locks import folder_lock

    out = tmp_path / "busy"
    out.mkdir()
    with folder_lock(out, "sweep folder"):  # this process holds it, as a running sweep would
        line = one_line(run("sweep", "-p", "ucb", "-n", "2", "-T", "20", "-o", out), code=2)
    assert f"process {os.getpid()} is writing this sweep folder right now" in line
    assert list(out.iterdir()) == []
    assert run("sweep", "-p", "ucb", "-n", "2", "-T", "20", "-o", out).exit_code == 0
