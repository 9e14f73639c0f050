"""Plug-in policies: from a file, a module and an entry point; both tiers; failures.

The plug-ins live in tests/plugins/ (eps_greedy.py is the example of docs/extending.md).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.engine.simulation import Simulation
from corraoi.model.instance import load_instance
from corraoi.policies import make_policies, make_policy
from corraoi.recorder.slotlog.reader import open_log

PLUGINS = Path(__file__).parent / "plugins"
I1 = load_instance("I1")


def run(*args: str):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line(res) -> str:  # type: ignore[no-untyped-def]
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert "Traceback" not in res.output, res.output
    errors = [ln for ln in lines if ln.startswith("corraoi: error:")]
    assert len(errors) == 1, res.output
    return errors[0]


@pytest.fixture
def plugdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    for f in PLUGINS.glob("*.py"):
        shutil.copy(f, tmp_path / f.name)
    monkeypatch.chdir(tmp_path)
    return tmp_path


# ---------------------------------------------------------------------------- the Python tier


def test_file_plugin_records_replays_diffs_and_reads_without_the_plugin(plugdir: Path):
    res = run("record", "-p", "eps_greedy.py:EpsilonGreedy", "--param", "epsilon=0.05",
              "-T", "3000", "-s", "4", "--no-rrd", "-o", "eps.mcap")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert run("record", "-p", "ucb", "-T", "3000", "-s", "4", "--no-rrd",
               "-o", "ucb.mcap").exit_code == 0  # fmt: skip
    log = open_log(plugdir / "eps.mcap")
    spec = log.config.policy
    assert (spec.name, dict(spec.params)) == ("eps-greedy", {"epsilon": 0.05})
    assert spec.qualname == f"file:{plugdir / 'eps_greedy.py'}:EpsilonGreedy"
    assert spec.version.startswith("sha256:") and spec.tier == "python"
    assert log.format_version == 2 and log.status == "complete"
    # the plug-in sees the hidden path built-ins see on the same seed
    eps, ucb = log.read_all(), open_log(plugdir / "ucb.mcap").read_all()
    assert np.array_equal(eps.x, ucb.x) and not np.array_equal(eps.arm, ucb.arm)
    # a run recorded twice is identical
    assert run("record", "-p", "eps_greedy.py:EpsilonGreedy", "--param", "epsilon=0.05",
               "-T", "3000", "-s", "4", "--no-rrd", "-o", "again.mcap").exit_code == 0  # fmt: skip
    assert run("diff", "eps.mcap", "again.mcap").exit_code == 0
    # without the plug-in, in a fresh process: info, replay, compare and diff still work
    (plugdir / "eps_greedy.py").unlink()
    for args, code in (
        (["info", "eps.mcap", "--json"], 0),
        (["replay", "eps.mcap", "--rrd", "r.rrd"], 0),
        (["compare", "eps.mcap", "ucb.mcap", "--no-rrd", "--json"], 0),
        (["diff", "eps.mcap", "ucb.mcap"], 1),
    ):
        out = subprocess.run([sys.executable, "-m", "corraoi", *args], cwd=plugdir,
                             capture_output=True, text=True)  # fmt: skip
        assert out.returncode == code, (args, out.stderr)
        assert "Traceback" not in out.stderr
    info = json.loads(subprocess.run([sys.executable, "-m", "corraoi", "info", "eps.mcap",
                                      "--json"], cwd=plugdir, capture_output=True,
                                     text=True).stdout)  # fmt: skip
    assert "eps-greedy" in json.dumps(info)


def test_python_tier_values_greedy_and_uniform(plugdir: Path):
    from corraoi.engine.simulation import simulate

    # epsilon = 0: after the first K slots every arm is an argmax of mu_hat before the slot
    spec = make_policies(["eps_greedy.py:EpsilonGreedy"], {"epsilon": 0.0})[0]
    blk = next(simulate(I1, spec, list(range(20)), 400, block=400))
    before = blk.mu_hat[:, :-1]  # state after slot t-1 = before slot t
    chosen = np.take_along_axis(before, blk.arm[:, 1:, None], axis=2)[..., 0]
    assert np.all(chosen[:, 4:] == before[:, 4:].max(axis=2))
    # epsilon = 1: uniform over the four arms (counts within 5 sigma of T/4)
    spec = make_policies(["eps_greedy.py:EpsilonGreedy"], {"epsilon": 1.0})[0]
    blk = next(simulate(I1, spec, list(range(50)), 400, block=400))
    counts = np.bincount(blk.arm.ravel(), minlength=4)
    n = blk.arm.size
    assert np.all(np.abs(counts - n / 4) < 5 * np.sqrt(n * 3 / 16)), counts
    # bookkeeping as the built-ins': pulls, ages and regret follow the arms and the path
    assert np.array_equal(blk.pulls[:, -1].sum(axis=1), np.full(50, 400))
    ok = I1.Y[blk.arm, blk.x] == 1
    assert np.array_equal(blk.success, ok)


def test_python_tier_runs_are_independent_of_their_batch(plugdir: Path):
    spec = make_policy("eps_greedy.py:EpsilonGreedy")
    batch = Simulation(I1, spec, [10, 11, 12], 500)
    b = batch.advance(500)
    single = Simulation(I1, spec, [12], 500).advance(500)
    assert b is not None and single is not None
    assert np.array_equal(b.arm[2], single.arm[0]) and np.array_equal(b.regret[2], single.regret[0])


def test_python_tier_sweeps_with_builtins(plugdir: Path):
    res = run("sweep", "-p", "ucb,eps_greedy.py:EpsilonGreedy", "-n", "20", "-T", "500",
              "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert set(out["policies"]) == {"ucb", "eps-greedy"}
    assert out["policies"]["eps-greedy"]["params"] == {"epsilon": 0.1}


# ---------------------------------------------------------------------------- compiled tier


def test_compiled_plugin_follows_its_index(plugdir: Path):
    res = run("record", "-p", "compiled_greedy.py:BonusUCB", "--param", "a=0.5", "-T", "1500",
              "-s", "2", "--no-rrd", "-o", "b.mcap")  # fmt: skip
    assert res.exit_code == 0, res.output
    run_ = open_log(plugdir / "b.mcap").read_all()
    assert open_log(plugdir / "b.mcap").config.policy.tier == "compiled"
    for i in range(4, len(run_)):
        t = i + 1
        pulls, mu = run_.pulls[i - 1], run_.mu_hat[i - 1]
        index = mu + 0.5 * np.sqrt(np.log(t) / pulls)
        assert index[run_.arm[i]] == index.max(), t
    ucb = next(iter(Simulation(I1, make_policy("ucb"), [2], 1500).advance(1500).run(0).x[None]))
    assert np.array_equal(run_.x, ucb)


def test_module_plugin_and_entry_points(tmp_path: Path):
    pkg = tmp_path / "site"
    (pkg / "myplug").mkdir(parents=True)
    shutil.copy(PLUGINS / "eps_greedy.py", pkg / "myplug" / "__init__.py")
    dist = pkg / "myplug-1.2.3.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: myplug\nVersion: 1.2.3\n")
    (dist / "top_level.txt").write_text("myplug\n")
    (dist / "entry_points.txt").write_text(
        "[corraoi.policies]\neps = myplug:EpsilonGreedy\nbroken = myplug:DoesNotExist\n"
    )
    env = {**os.environ, "PYTHONPATH": f"{pkg}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}

    def corraoi(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "corraoi", *args], cwd=tmp_path, env=env,
                              capture_output=True, text=True)  # fmt: skip

    listing = json.loads(corraoi("policies", "--json").stdout)["policies"]
    by_name = {e["name"]: e for e in listing}
    assert by_name["eps"]["status"] == "ok" and by_name["eps"]["tier"] == "python"
    assert by_name["broken"]["status"] == "broken"
    assert "DoesNotExist" in by_name["broken"]["error"]
    assert by_name["cucb"]["status"] == "ok"  # the rest still works
    for ref, label in (("eps", "ep"), ("myplug:EpsilonGreedy", "mod")):
        out = corraoi("record", "-p", ref, "-T", "500", "--no-rrd", "-o", f"{label}.mcap")
        assert out.returncode == 0, out.stderr
    log = open_log(tmp_path / "mod.mcap")
    assert log.config.policy.qualname == "myplug:EpsilonGreedy"
    assert log.config.policy.version == "1.2.3"
    assert open_log(tmp_path / "ep.mcap").read_all().equals(log.read_all())
    bad = corraoi("record", "-p", "broken", "-T", "50", "--no-rrd", "-o", "x.mcap")
    assert bad.returncode == 2 and "entry point myplug:DoesNotExist is broken" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1 and not (tmp_path / "x.mcap").exists()


# ---------------------------------------------------------------------------- failures


@pytest.mark.parametrize(
    ("ref", "needle"),
    [
        ("bad_plugins.py:OutOfRange",
         "policy out-of-range, slot 5: select returned arm 4 for run 0"),
        ("bad_plugins.py:NaNArm", "policy nan-arm, slot 3: select returned NaN"),
        ("bad_plugins.py:WrongShape", "policy wrong-shape, slot 1: select returned shape (1, 2)"),
        ("bad_plugins.py:Raises", "policy raises, slot 7: select raised ZeroDivisionError: boom"),
    ],
)
def test_a_misbehaving_plugin_leaves_a_partial_marked_failed(plugdir: Path, ref: str, needle: str):
    res = run("record", "-p", ref, "-T", "3000", "--no-rrd", "-o", "bad.mcap")
    assert res.exit_code == 1
    line = one_line(res)
    assert needle in line, line
    assert not (plugdir / "bad.mcap").exists()
    partial = plugdir / "bad.mcap.partial"
    if "slot 1:" in needle:  # failed before its first slot: nothing worth keeping
        assert not partial.exists()
        return
    assert "marked failed" in line and str(partial.name) in line
    log = open_log(partial)
    assert log.status == "failed" and log.end["error"].startswith(needle.split(":")[0])
    assert log.n_slots == int(needle.split("slot ")[1].split(":")[0]) - 1


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["-p", "broken_import.py:Anything"], "importing broken_import.py failed: "
         "ModuleNotFoundError: No module named 'this_module_does_not_exist'"),
        (["-p", "bad_plugins.py:NotAPolicy"], "is not a policy class"),
        (["-p", "bad_plugins.py:Missing"], "bad_plugins.py has no class Missing"),
        (["-p", "nofile.py:X"], "no such file nofile.py"),
        (["-p", "no_such_module_xyz:X"], "cannot import module no_such_module_xyz"),
        (["-p", "bad_plugins.py:Raises", "--param", "nope=1"], "parameter nope does not apply"),
        (["-p", "bad_plugins.py:Raises", "--param", "at=0"],
         "parameter at=0 must be an integer in [1, inf)"),
        (["-p", "eps_greedy.py:EpsilonGreedy", "--param", "epsilon=2"], "epsilon=2 must be in"),
    ],
)
def test_bad_plugins_and_parameters_get_one_line(plugdir: Path, args: list[str], needle: str):
    res = run("record", *args, "-T", "100", "--no-rrd", "-o", "x.mcap")
    assert res.exit_code == 2
    assert needle in one_line(res)
    assert not list(plugdir.glob("x.mcap*"))


# ---------------------------------------------------------------------------- the kernel cache


def test_composed_kernels_load_from_the_disk_cache_in_a_new_process(tmp_path: Path):
    code = (
        "import sys\n"
        "from corraoi.engine import kernel_cache\n"
        "from corraoi.engine.simulation import Simulation\n"
        "from corraoi.model.instance import load_instance\n"
        "from corraoi.policies import make_policy\n"
        "notes = []\n"
        "kernel_cache.on_compile = notes.append\n"
        "sim = Simulation(load_instance('I1'), make_policy('cts-gauss'), [0], 10)\n"
        "sim.advance(10)\n"
        "stats = sim.kernel(True).stats\n"
        "print(len(notes), sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))\n"
    )
    env = {**os.environ, "CORRAOI_CACHE_DIR": str(tmp_path / "cache")}
    first = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    second = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    assert first.stdout.split() == ["1", "0", "1"]  # a notice, compiled once
    assert second.stdout.split() == ["0", "1", "0"]  # no notice, loaded from the cache
    generated = list((tmp_path / "cache").glob("kernels-*/corraoi_*.py"))
    assert [g.name.split("_")[1] for g in generated] == ["record"]  # no sweep kernel compiled
