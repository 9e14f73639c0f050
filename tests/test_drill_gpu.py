"""A GPU sweep's runs recorded again, slot by slot, with the GPU kernel's own streams and rule
(issue 20, item 3), on the emulated device (kernel.cu compiled for the host) and, where there
is one, on a CUDA GPU: what the kernel captures is the run the sweep counted."""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from corraoi.engine.block import RunConfig
from corraoi.errors import GpuUnavailable
from corraoi.gpu.device import DEVICE_ENV, CudaDevice, Device, EmulatedDevice, host_compiler
from corraoi.gpu.runner import capture_run, simulate
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log

needs_cxx = pytest.mark.skipif(
    host_compiler() is None, reason="no C++ compiler: the emulated GPU device cannot be built"
)

I2 = load_instance("I2")
POLICIES = ("ucb", "cucb", "aoi-aware-cts", "ts-gauss")


@pytest.fixture(scope="module", params=["emulate", "cuda"])
def device(request: pytest.FixtureRequest) -> Device:
    """The emulated device, then a CUDA GPU (skipped, with the reason, where there is none)."""
    if request.param == "emulate":
        if host_compiler() is None:
            pytest.skip("no C++ compiler: the emulated GPU device cannot be built")
        return EmulatedDevice()
    try:
        return CudaDevice()
    except GpuUnavailable as exc:
        pytest.skip(f"no CUDA GPU with CuPy here ({exc})")


@pytest.mark.parametrize("name", POLICIES)
def test_every_captured_run_ends_where_the_device_sweep_counted_it(
    device: Device, name: str
) -> None:
    """1,000 runs of each of 4 policies: the captured final regret, estimator and best-arm
    pulls equal the device's per-run finals."""
    policy = make_policy(name)
    runs, horizon, seed0 = 1000, 300, 40
    swept = simulate(I2, policy, seed0=seed0, runs=runs, horizon=horizon, checkpoints=[100],
                     device=device)  # fmt: skip
    finals, estimators, best = [], [], []
    for r in range(runs):
        *_, last = capture_run(I2, policy, seed=seed0 + r, horizon=horizon, block=128,
                               device=device)  # fmt: skip
        finals.append(last.regret[-1])
        estimators.append(last.estimator[-1])
        best.append(last.pulls[-1, 3])  # I2's best arm is arm 4
    np.testing.assert_array_equal(np.asarray(finals, dtype=np.float64), swept.regret_final)
    np.testing.assert_allclose(estimators, swept.estimator_final, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(best, swept.best_pulls_final)


def test_a_captured_run_holds_together_slot_by_slot(device: Device) -> None:
    """The columns obey the model: ages, regret, pulls and means agree with the arms and
    successes captured; the arm is a candidate unless the AoI-aware rule overrode."""
    blocks = list(capture_run(I2, make_policy("aoi-aware-cucb"), seed=7, horizon=2500,
                              block=1000, device=device))  # fmt: skip
    assert [len(b) for b in blocks] == [1000, 1000, 500]
    b = blocks[0].concat(blocks)
    assert np.array_equal(b.t, np.arange(1, 2501))
    Y = np.asarray(I2.Y)
    assert np.array_equal(b.success, Y[b.arm, b.x] == 1)
    age = np.where(b.success, 1, np.concatenate([[1], b.aoi[:-1]]) + 1)
    assert np.array_equal(b.aoi, age)
    assert np.array_equal(b.regret, np.cumsum(b.aoi - b.oracle_aoi))
    assert np.array_equal(b.pulls.sum(axis=1), b.t)
    assert np.array_equal(b.pulls[-1], np.bincount(b.arm, minlength=4))
    wins = np.bincount(b.arm[b.success], minlength=4)
    np.testing.assert_allclose(b.mu_hat[-1], wins / b.pulls[-1])
    assert b.override.any() and not b.override.all()
    chosen = b.candidates[np.arange(len(b)), b.arm]
    assert chosen[~b.override].all()
    assert (~b.candidates.all(axis=1)).any()  # the correlated set left arms out


#: A policy of each family and form: the why-this-arm fields of its captured runs are checked.
WHY = ("ucb", "cucb", "aoi-aware-cucb", "aoi-aware-q-ucb", "cts", "aoi-aware-ts-gauss",
       "sw-ucb", "aoi-aware-d-ts")  # fmt: skip


def _cpu_hook(policy_name: str, hook: str) -> Any:
    """The CPU engine's hook of a built-in as plain Python (its numba function's py_func)."""
    module, _, name = getattr(make_policy(policy_name).resolve(), hook).partition(":")
    return getattr(importlib.import_module(module), name).py_func


@pytest.mark.parametrize("name", WHY)
def test_a_captured_run_says_why_as_the_cpu_record_does(
    device: Device, name: str, tmp_path: Path
) -> None:
    """Issue 40: a captured run has score, forced and (AoI-aware) override_threshold, defined
    as the CPU engine's record defines them. On a trace channel the CPU engine and the kernel
    see one hidden path, so up to the first slot where their random draws part (that slot
    included: its state is still the same) every field is the CPU's, an index policy's scores
    within float32's tolerance. Over the whole run: the threshold is 1 / max mu_hat before the slot,
    the score is NaN exactly off the candidates and at slots forced or overridden, the arm
    maximises it elsewhere, and an index policy's score is the CPU's index of the captured
    state."""
    from corraoi.engine.problem import Problem
    from corraoi.engine.simulation import simulate_run
    from corraoi.model.channels import parse_channel

    horizon = 1500
    path = tmp_path / "states.txt"
    rng = np.random.default_rng(3)
    path.write_text("\n".join(str(v) for v in rng.integers(1, 5, horizon)) + "\n")
    channel = parse_channel(f"trace:{path}", I2)
    policy = make_policy(name)
    aware = name.startswith("aoi-aware")
    gpu_blocks = list(capture_run(I2, policy, seed=5, horizon=horizon, channel=channel,
                                  block=600, device=device))  # fmt: skip
    g = gpu_blocks[0].concat(gpu_blocks)
    cpu_blocks = list(simulate_run(I2, policy, 5, horizon, channel=channel))
    c = cpu_blocks[0].concat(cpu_blocks)
    assert g.score is not None and g.forced is not None
    assert g.score.dtype == np.float32 and g.score.shape == (horizon, 4)
    assert (g.override_threshold is not None) == aware == (c.override_threshold is not None)
    assert np.array_equal(g.x, c.x)
    # the same slots while the decisions agree (and at the first that differs)
    parted = np.flatnonzero(g.arm != c.arm)
    n = int(parted[0]) + 1 if parted.size else horizon
    assert np.array_equal(g.forced[:n], c.forced[:n])
    if "ts" in name:  # a sample: the two engines draw from streams of their own
        assert np.array_equal(np.isnan(g.score[:n]), np.isnan(c.score[:n]))
    else:
        np.testing.assert_allclose(g.score[:n], c.score[:n], rtol=1e-5, equal_nan=True)
    if aware:
        np.testing.assert_allclose(g.override_threshold[:n], c.override_threshold[:n],
                                   rtol=1e-6)  # fmt: skip
    # the whole captured run: each field from the state before the slot
    one = np.eye(4, dtype=np.int64)[g.arm]
    pulls = np.cumsum(one, axis=0) - one
    succ = np.cumsum(one * g.success[:, None], axis=0) - one * g.success[:, None]
    mu = np.where(pulls > 0, succ / np.maximum(pulls, 1), 0.0)
    if aware:
        top = mu.max(axis=1)
        want = np.where(top > 0, 1.0 / np.where(top > 0, top, 1.0), np.inf)
        np.testing.assert_allclose(g.override_threshold, want.astype(np.float32), rtol=1e-6)
    scored = ~g.forced & ~g.override
    assert scored.any()
    assert np.array_equal(np.isnan(g.score), ~(scored[:, None] & g.candidates))
    chosen = g.score[np.arange(horizon), g.arm]
    assert np.array_equal(chosen[scored], np.nanmax(g.score[scored], axis=1))
    if name.removeprefix("aoi-aware-").removeprefix("c") in ("ucb", "q-ucb"):
        assert not (g.forced & g.override).any()
        if "q-ucb" not in name:  # UCB forces each arm once; Q-UCB also explores at random
            assert np.array_equal(g.forced, (pulls == 0).any(axis=1) & ~g.override)
        score = _cpu_hook(name, "score")
        params = Problem.of(I2, policy, horizon, channel).params
        vals = np.zeros(4)
        for j in np.flatnonzero(scored):
            cand = g.candidates[j]
            score(j + 1, 4, pulls[j], succ[j], mu[j], cand, vals, params, None, None, None)
            np.testing.assert_allclose(g.score[j][cand], vals[cand].astype(np.float32),
                                       rtol=1e-5, err_msg=f"slot {j + 1}")  # fmt: skip


def test_two_policies_on_one_seed_share_the_hidden_path(device: Device) -> None:
    runs = [list(capture_run(I2, make_policy(n), seed=11, horizon=800, device=device))
            for n in ("ucb", "cts")]  # fmt: skip
    assert np.array_equal(runs[0][0].x, runs[1][0].x)
    assert not np.array_equal(runs[0][0].arm, runs[1][0].arm)


def test_the_run_config_says_whose_streams(tmp_path: Path) -> None:
    config = RunConfig(I2, make_policy("cucb"), 5, 100, streams="gpu-emulated")
    assert config.to_dict()["streams"] == "gpu-emulated" and config.label == "cucb-I2-s5-gpu"
    assert RunConfig.from_dict(config.to_dict()) == config
    assert "streams" not in RunConfig(I2, make_policy("cucb"), 5, 100).to_dict()
    assert config.format_version == 2  # an older reader refuses it rather than misread it
    from corraoi.errors import ConfigError

    with pytest.raises(ConfigError, match="streams 'tpu': expected one of cpu, gpu-cuda"):
        RunConfig(I2, make_policy("cucb"), 5, 100, streams="tpu")


@needs_cxx
def test_a_captured_run_shows_why_unless_its_scores_are_left_out() -> None:
    """RunConfig.scored holds for a GPU sweep's captured run (its views show why this arm),
    and score=False leaves the captured scores out, as it does on the CPU."""
    from corraoi.face.slots import slots_of

    config = RunConfig(I2, make_policy("cucb"), 5, 300, streams="gpu-emulated")
    assert config.scored
    assert all(b.score is not None and b.forced is not None for b in slots_of(config))
    off = RunConfig(I2, make_policy("cucb"), 5, 300, streams="gpu-emulated", score=False)
    assert not off.scored
    assert all(b.score is None and b.forced is None for b in slots_of(off))


def _corraoi(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**__import__("os").environ, DEVICE_ENV: "emulate"}
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


@needs_cxx
def test_record_from_a_gpu_sweep_is_the_run_it_counted(tmp_path: Path) -> None:
    pytest.importorskip("rerun", reason="a sweep folder's sweep.rrd needs rerun-sdk")
    pytest.importorskip("pyarrow")
    import corraoi

    sweep = _corraoi("sweep", "-i", "I2", "-p", "cucb,aoi-aware-cts", "--runs", "200", "-T",
                     "2000", "--backend", "gpu", "-o", "g", cwd=tmp_path)  # fmt: skip
    assert sweep.returncode == 0, sweep.stderr
    named = json.loads((tmp_path / "g" / "summary.json").read_text())["notable"]
    out = _corraoi("record", "--from", "g", "--run", "widest-gap", "--no-rrd", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "captured from the GPU kernel compiled for this CPU" in out.stderr
    gap = named["pairs"][0]
    logs = {open_log(p).config.policy.name: p for p in (tmp_path / "runs").glob("*.mcap")}
    assert sorted(logs) == sorted(gap["policies"])
    runs = corraoi.load(tmp_path / "g").runs
    x = []
    for name, path in logs.items():
        log = open_log(path)
        assert log.config.streams == "gpu-emulated" and log.config.seed == gap["seed"]
        regret = np.concatenate([b.regret for b in log.blocks()])
        row = runs[(runs.policy == name) & (runs.run == gap["run"]) & (runs.t == 2000)]
        assert regret[-1] == row["regret"].item()
        x.append(np.concatenate([b.x for b in log.blocks()]))
    assert np.array_equal(x[0], x[1])
    info = _corraoi("info", next(iter(logs.values())), cwd=tmp_path)
    assert "streams                gpu-emulated: a GPU sweep's run" in info.stdout


@needs_cxx
def test_bad_requests_on_a_gpu_sweep_are_one_line(tmp_path: Path) -> None:
    pytest.importorskip("rerun", reason="a sweep folder's sweep.rrd needs rerun-sdk")
    sweep = _corraoi("sweep", "-i", "I1", "-p", "ucb", "--runs", "20", "-T", "100", "--backend",
                     "gpu", "-o", "g", cwd=tmp_path)  # fmt: skip
    assert sweep.returncode == 0, sweep.stderr
    plugin = str(Path(__file__).parent / "plugins" / "eps_greedy.py") + ":EpsilonGreedy"
    for args, says in (
        (["--run", "20"], "--run 20: out of range; the sweep in g has runs 0..19"),
        (["--run", "3", "-p", f"ucb,{plugin}"], "policy eps-greedy has a plain-Python policy "
         "(the GPU backend runs the built-ins): a GPU sweep's runs are recorded with the GPU "
         "kernel"),
    ):  # fmt: skip
        out = _corraoi("record", "--from", "g", "--no-rrd", *args, cwd=tmp_path)
        lines = out.stderr.strip().splitlines()
        assert out.returncode != 0 and len(lines) == 1 and says in lines[0], out.stderr
    assert not (tmp_path / "runs").exists()


@needs_cxx
def test_a_damaged_emulation_library_is_rebuilt_and_a_killed_record_never_blocks(
    tmp_path: Path,
) -> None:
    """Issue 32, case 3: a truncated GPU-emulation library in the kernel cache made `record
    --from` die of SIGBUS, and the `.mcap.partial` it left blocked the next attempt. The
    library is checked before it is loaded (rebuilt, one notice), and a `.partial` a killed
    attempt at the same run left is written over."""
    pytest.importorskip("rerun", reason="a sweep folder's sweep.rrd needs rerun-sdk")
    env = {**os.environ, DEVICE_ENV: "emulate", "CORRAOI_CACHE_DIR": str(tmp_path / "cache")}

    def cli(*args: object) -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=tmp_path,
                              env=env, capture_output=True, text=True, timeout=600)  # fmt: skip

    res = cli("sweep", "-p", "ucb", "-n", 4, "-T", 200, "--backend", "gpu", "-o", "sw")
    assert res.returncode == 0, res.stderr
    # record --from builds the capture library (CAI_CAPTURE=1) beside the sweep's
    res = cli("record", "--from", "sw", "--run", 1, "--no-rrd", "-o", "first.mcap")
    assert res.returncode == 0, res.stderr
    libs = list((tmp_path / "cache").rglob("kernel-K*.so"))
    assert len(libs) == 2 and all(Path(f"{lib}.sha256").is_file() for lib in libs)
    for lib in libs:  # cut short, as a full disk or a kill during its copy would leave it
        lib.write_bytes(lib.read_bytes()[:4096])
    res = cli("record", "--from", "sw", "--run", 2, "--no-rrd", "-o", "r.mcap")
    assert res.returncode == 0, res.stderr  # never SIGBUS
    assert "is damaged or unverified; rebuilding it" in res.stderr
    log = open_log(tmp_path / "r.mcap")
    assert log.status == "complete" and log.config.streams == "gpu-emulated"
    assert log.provenance["backend"] == "gpu-emulated"
    # what a record --from killed mid-run leaves: its log cut short at its .partial name
    data = (tmp_path / "r.mcap").read_bytes()
    (tmp_path / "r.mcap").unlink()
    (tmp_path / "r.mcap.partial").write_bytes(data[: len(data) // 2])
    res = cli("record", "--from", "sw", "--run", 2, "--no-rrd", "-o", "r.mcap")
    assert res.returncode == 0, res.stderr  # not blocked: the same run, written again
    assert open_log(tmp_path / "r.mcap").read_all().equals(log.read_all())
    assert not (tmp_path / "r.mcap.partial").exists()
