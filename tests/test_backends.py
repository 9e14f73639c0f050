"""Backends behind one interface (issue 23): chosen in one place, each hands back chunk
results and never calls into the sweep; the in-process one gives the engine's own runs."""

from __future__ import annotations

import numpy as np
import pytest

from corraoi.engine.simulation import Simulation
from corraoi.errors import ConfigError
from corraoi.experiments import backends
from corraoi.experiments.grid import build_grid
from corraoi.gpu.device import DEVICE_ENV, host_compiler


def _grid(**kw):  # type: ignore[no-untyped-def]
    return build_grid(instances=["I1"], policies=["ucb", "cts"], horizons=[300], runs=12,
                      chunk=5, **kw)  # fmt: skip


def test_the_backend_is_chosen_in_one_place():
    grid = _grid()
    local = backends.choose(grid, workers=1)
    assert isinstance(local, backends.InProcess) and local.workers == 1
    dask = backends.choose(grid, client=object(), threads_per_worker=3)
    assert isinstance(dask, backends.OnDask) and dask.workers == 3 and dask.threads == 3
    assert backends.choose(grid, client=object()).workers == 1  # the workers' own default
    assert backends.settle(grid, "cpu").backend == "cpu"


def test_auto_falls_back_to_the_cpu_with_one_notice(monkeypatch):
    monkeypatch.delenv(DEVICE_ENV, raising=False)
    notes: list[str] = []
    grid = backends.settle(_grid(), "auto", warn=notes.append)
    try:
        import cupy  # noqa: F401
    except ImportError:
        assert grid.backend == "cpu" and len(notes) == 1
        assert notes[0].startswith("--backend auto: running on the CPU (")


@pytest.mark.skipif(host_compiler() is None, reason="no C++ compiler for the emulated GPU")
def test_a_gpu_grid_with_a_cluster_is_refused(monkeypatch):
    monkeypatch.setenv(DEVICE_ENV, "emulate")
    grid = backends.settle(_grid(), "gpu")
    assert grid.backend == "gpu" and isinstance(backends.choose(grid), backends.OnGpu)
    with pytest.raises(ConfigError, match="--backend gpu runs in this process"):
        backends.settle(_grid(), "gpu", client=object())


def test_in_process_hands_back_every_chunk_once_with_the_engines_runs():
    grid = _grid()
    todo = [(cell, chunk) for cell in grid.cells for chunk in grid.chunks(cell)]
    got = []
    backends.InProcess(workers=1).run(grid, todo, on_done=got.append, on_slots=None)
    assert sorted((r.chunk.cell, r.chunk.start) for r in got) == sorted(
        (c.cell, c.start) for _, c in todo
    )
    for cell in grid.cells:
        sim = Simulation(cell.instance, cell.policy, range(grid.seed, grid.seed + grid.runs), 300)
        sim.advance_to(300)
        finals = np.concatenate([r.regret[:, -1] for r in sorted(
            (r for r in got if r.chunk.cell == cell.key), key=lambda r: r.chunk.start)])
        assert np.array_equal(finals, sim.regret), cell.key
