"""A GPU sweep's runs recorded again, slot by slot, with the GPU kernel's own streams and rule
(issue 20, item 3), on the emulated device (kernel.cu compiled for the host) and, where there
is one, on a CUDA GPU: what the kernel captures is the run the sweep counted."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

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
    libs = list((tmp_path / "cache").rglob("kernel-K*.so"))
    assert libs and all(Path(f"{lib}.sha256").is_file() for lib in libs)
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
