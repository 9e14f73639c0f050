"""Shared fixtures of the recorder tests: run configurations, engine output, recorded logs."""

from __future__ import annotations

import signal
from collections.abc import Callable
from pathlib import Path

import pytest

from corraoi.engine.block import RunConfig, SlotBlock
from corraoi.engine.simulation import simulate_run
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy

Recorded = tuple[Path, RunConfig, SlotBlock]

# A suite started in the background by a non-interactive shell (`.ci/run &`, a CI runner)
# inherits SIGINT ignored, and so would every command the tests start: Python keeps an
# ignored SIGINT ignored, so the Ctrl-C tests would wait in vain. Take it back here; the
# commands then start with SIGINT at its default, as from a terminal.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_configure(config: pytest.Config) -> None:
    """Before any test, compile every built-in family's record and sweep kernels that the
    kernel cache lacks, a worker process per core (kernel_pool.prepare): on a fresh machine the
    tests then load them instead of compiling one by one inside the first tests that need
    them. Done once, by the main process (not by each pytest-xdist worker)."""
    if hasattr(config, "workerinput"):
        return
    _compile_bytecode()
    from corraoi.engine import kernel_cache, kernel_pool
    from corraoi.policies import builtins

    classes = [make_policy(name).resolve() for name in builtins()]
    # the kernels of many sources of the built-in families (rhorand-ucb's serves every rule
    # of ucb, cucb and their AoI-aware forms; rhorand-ts's those of ts and cts)
    many = [make_policy(name).resolve() for name in ("rhorand-ucb", "rhorand-ts")]
    notes: list[str] = []
    previous, kernel_cache.on_compile = kernel_cache.on_compile, notes.append
    try:
        kernel_pool.prepare(classes, record=(True, False), many=many)
    finally:
        kernel_cache.on_compile = previous
    if notes:
        print(f"corraoi: {notes[0]}")


def _compile_bytecode() -> None:
    """Write the bytecode of corraoi, recorder and viewer once, before the tests. Where
    ``PYTHONDONTWRITEBYTECODE`` is set (as on CI machines), no command the tests start
    would write it, so each would compile the modules it imports again: about 0.1 s of
    every one of the suite's hundreds of ``corraoi`` processes on the 2-core machine."""
    import compileall

    root = Path(__file__).resolve().parent.parent
    for package in ("corraoi", "recorder", "viewer"):
        compileall.compile_dir(root / package, quiet=2)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: one pytest-xdist worker more than there are cores. A good part of the
    suite waits rather than computes (commands started as processes, sockets, a browser,
    signals sent at chosen moments): on the 2-core machine the whole suite took 6:05-6:32
    with 2 workers and 4:45 with 3 (CPU busy 1.8 of 2 cores); 4 gave nothing more and
    delayed the timed interrupts past their second."""
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return (cores or 1) + 1


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked ``slow`` (10 s or more each: documents run as shown, kernels compiled
    into a fresh cache, a browser) run first. pytest-xdist hands tests out in this order,
    so the long ones start together and the short ones fill in around them, instead of one
    worker finishing a 40 s test alone at the end. Otherwise the order is kept."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(autouse=True)
def _own_working_directory(tmp_path_factory: pytest.TempPathFactory, monkeypatch) -> None:
    """Every test runs in a fresh empty directory, never the checkout: a `runs/` left there
    by the README's quick start (or anything else) cannot change a test's outcome, and no
    test can write into the checkout by a relative path."""
    monkeypatch.chdir(tmp_path_factory.mktemp("cwd"))


def _config(
    policy: str = "cucb", instance: str = "I1", seed: int = 0, horizon: int = 2500
) -> RunConfig:
    return RunConfig(load_instance(instance), make_policy(policy), seed, horizon)


def _engine(config: RunConfig, block: int = 1000) -> list[SlotBlock]:
    return list(
        simulate_run(config.instance, config.policy, config.seed, config.horizon, block=block)
    )


@pytest.fixture
def make_config() -> Callable[..., RunConfig]:
    """make_config(policy="cucb", instance="I1", seed=0, horizon=2500) -> RunConfig."""
    return _config


@pytest.fixture
def engine() -> Callable[..., list[SlotBlock]]:
    """engine(config, block=1000) -> the engine's blocks for the run."""
    return _engine


@pytest.fixture
def record_mcap(tmp_path: Path) -> Callable[..., Recorded]:
    """record_mcap(policy, horizon=, seed=, name=, block=) -> (path, config, engine output)."""
    from corraoi.recorder.slotlog.sink import McapSink

    def record(
        policy: str = "cucb",
        *,
        instance: str = "I1",
        seed: int = 0,
        horizon: int = 2500,
        name: str | None = None,
        block: int = 1000,
    ) -> Recorded:
        config = _config(policy, instance, seed, horizon)
        path = tmp_path / (name or f"{config.label}.mcap")
        blocks = _engine(config, block)
        with McapSink(path, config, fsync=False) as sink:
            for b in blocks:
                sink.write(b)
        return path, config, SlotBlock.concat(blocks)

    return record
