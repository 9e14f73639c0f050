"""The record and sweep kernels (issue 22): the same decisions as the golden runs, compiled
once per cache even by two processes at once, rebuilt when a cache entry is damaged, and
built concurrently for several families."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit

from corraoi.engine import kernels
from corraoi.engine.simulation import Simulation
from corraoi.engine.threads import set_workers
from corraoi.model.instance import load_instance
from corraoi.policies import builtins, make_policy

GOLDEN = Path(__file__).parent / "golden"
PLUGINS = Path(__file__).parent / "plugins"
sys.path.insert(0, str(GOLDEN))
from regenerate import HORIZON, SEEDS, instances  # noqa: E402

WANT = json.loads((GOLDEN / "builtins.json").read_text())["runs"]


def _arms_by_sweep_kernel(inst, name: str) -> tuple[list[str], list[int]]:
    """Every slot's arm, read back from the sweep kernel's pulls at every slot."""
    sim = Simulation(inst, make_policy(name), SEEDS, HORIZON)
    snaps = sim.advance_to(HORIZON, snapshots=range(1, HORIZON + 1))
    pulls = np.stack([s.pulls for s in snaps], axis=1)  # (R, T, K)
    before = np.concatenate([np.zeros_like(pulls[:, :1]), pulls[:, :-1]], axis=1)
    arms = np.argmax(pulls - before, axis=2)
    letters = ["".join(chr(ord("a") + int(a)) for a in row) for row in arms]
    return letters, [int(r) for r in snaps[-1].regret]


@pytest.mark.parametrize("name", builtins())
def test_sweep_kernel_takes_the_golden_decisions(name: str):
    for inst in instances():
        arms, regret = _arms_by_sweep_kernel(inst, name)
        want = WANT[f"{inst.name}/{name}"]
        assert arms == want["arms"], f"{inst.name}/{name}: the sweep kernel's arms changed"
        assert regret == want["regret"]


def test_record_and_sweep_kernels_agree_on_a_compiled_plugin():
    spec = make_policy(f"{PLUGINS / 'compiled_greedy.py'}:BonusUCB", a=0.7)
    inst = load_instance("I2")
    rec = Simulation(inst, spec, [5, 6, 7], 600).advance(600)
    assert rec is not None
    sim = Simulation(inst, spec, [5, 6, 7], 600)
    snaps = sim.advance_to(600, snapshots=range(1, 601))
    pulls = np.stack([s.pulls for s in snaps], axis=1)
    assert np.array_equal(pulls, rec.pulls)
    assert np.array_equal(np.stack([s.regret for s in snaps], axis=1), rec.regret)
    assert len(set(map(tuple, rec.arm))) == 3  # three different runs, not one copied


def test_threads_do_not_change_any_run():
    inst = load_instance("I1")
    finals = []
    for workers in (1, 2):
        set_workers(workers)
        try:
            sim = Simulation(inst, make_policy("cts"), range(64), 5000)  # above the threshold
            sim.advance_to(5000)
            finals.append((sim.regret.copy(), sim.pulls.copy()))
        finally:
            set_workers(None)
    assert np.array_equal(finals[0][0], finals[1][0])
    assert np.array_equal(finals[0][1], finals[1][1])


def test_set_workers_rejects_zero():
    from corraoi.errors import ConfigError

    with pytest.raises(ConfigError, match="workers must be >= 1"):
        set_workers(0)


# ---------------------------------------------------------------- the cache, across processes

_RUN = """
import sys, json
from corraoi.engine import kernel_cache
from corraoi.engine.simulation import Simulation
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
notes = []
kernel_cache.on_compile = notes.append
sim = Simulation(load_instance('I1'), make_policy(sys.argv[1]), [0, 1], 300)
sim.advance_to(300)
stats = sim.kernel(False).stats
print(json.dumps({"notes": notes, "regret": sim.regret.tolist(),
                  "misses": sum(stats.cache_misses.values())}))
"""


def _python(code: str, cache: Path, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "CORRAOI_CACHE_DIR": str(cache)}
    return subprocess.Popen([sys.executable, "-c", code, *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip


def _result(proc: subprocess.Popen[str]) -> dict:
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def _expected(policy: str) -> list[int]:
    sim = Simulation(load_instance("I1"), make_policy(policy), [0, 1], 300)
    sim.advance_to(300)
    return sim.regret.tolist()


def test_two_processes_sharing_a_fresh_cache_compile_once(tmp_path: Path):
    cache = tmp_path / "cache"
    first = _python(_RUN, cache, "ucb")
    second = _python(_RUN, cache, "ucb")
    a, b = _result(first), _result(second)
    compiled = [r for r in (a, b) if any("compiling" in n for n in r["notes"])]
    assert len(compiled) == 1, (a["notes"], b["notes"])  # one compiled, one waited and loaded
    assert a["regret"] == b["regret"] == _expected("ucb")
    assert len(list(cache.glob("kernels-*/corraoi_sweep_*.py"))) == 1


@pytest.fixture(scope="module")
def ucb_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A fresh cache holding ucb's sweep kernel, compiled once for the damage tests (each
    damages a copy of it)."""
    cache = tmp_path_factory.mktemp("ucb-cache") / "cache"
    ran = _result(_python(_RUN, cache, "ucb"))
    assert ran["regret"] == _expected("ucb") and any("compiling" in n for n in ran["notes"])
    return cache


@pytest.mark.slow
@pytest.mark.parametrize("which", ["index", "data", "source", "flipped", "sums"])
def test_a_damaged_cache_entry_is_rebuilt_with_one_notice(tmp_path: Path, which: str,
                                                          ucb_cache: Path):  # fmt: skip
    """A truncated index or data file, a flipped byte in the compiled code (same size: numba
    would load it and run it) or lost checksums: checked before loading, rebuilt."""
    cache = tmp_path / "cache"
    shutil.copytree(ucb_cache, cache)  # times kept: numba's index checks the source's
    whole = _result(_python(_RUN, cache, "ucb"))
    assert whole["notes"] == [] and whole["misses"] == 0  # the copy loads as it is
    folder = next(cache.glob("kernels-*"))
    if which == "source":
        victim = next(folder.glob("corraoi_sweep_*.py"))
    elif which == "sums":
        victim = next(folder.glob(".corraoi_sweep_*.sha256"))
    else:
        suffix = ".nbi" if which == "index" else ".nbc"
        victim = next(p for p in (folder / "__pycache__").iterdir() if p.suffix == suffix)
    data = victim.read_bytes()
    if which == "flipped":
        mid = len(data) // 2
        victim.write_bytes(data[:mid] + bytes([data[mid] ^ 0xFF]) + data[mid + 1 :])
    elif which == "sums":
        victim.unlink()
    else:
        victim.write_bytes(data[: len(data) // 3])  # truncated, as by a full disk or a kill
    again = _result(_python(_RUN, cache, "ucb"))
    assert again["regret"] == _expected("ucb")
    if which == "sums":
        assert len([n for n in again["notes"] if "has no checksums" in n]) == 1, again["notes"]
    elif which != "source":  # a damaged source is simply rewritten (its text is compared)
        assert len([n for n in again["notes"] if "damaged" in n]) == 1, again["notes"]
    fine = _result(_python(_RUN, cache, "ucb"))  # and the rebuilt entry loads cleanly
    assert fine["notes"] == [] and fine["misses"] == 0


_PREPARE = """
import sys, json
from corraoi.engine import kernel_cache, kernel_pool
from corraoi.policies import make_policy
notes = []
kernel_cache.on_compile = notes.append
classes = [make_policy(n).resolve() for n in sys.argv[1:]]
kernel_pool.prepare(classes, record=False)
print(json.dumps({"notes": notes}))
"""


@pytest.mark.slow
def test_prepare_compiles_families_concurrently_into_the_cache(tmp_path: Path):
    cache = tmp_path / "cache"
    out = _result(_python(_PREPARE, cache, "ucb", "cucb", "ts", "cts-gauss"))
    # ucb/cucb share a family, ts, and ts-gauss: three kernels, one notice, a line each
    assert out["notes"][0].startswith("compiling the engine for 3 policy families")
    assert [n.split()[0] for n in out["notes"][1:]] == ["1/3", "2/3", "3/3"]
    for name in ("cucb", "ts", "cts-gauss"):  # then a run loads each without compiling
        got = _result(_python(_RUN, cache, name))
        assert got["notes"] == [] and got["misses"] == 0, got
        assert got["regret"] == _expected(name)


def test_kernel_source_variants_differ_only_where_they_should():
    cls = make_policy("cucb").resolve()
    rec_name, rec = kernels.kernel_source(cls, record=True)
    sw_name, sw = kernels.kernel_source(cls, record=False)
    assert rec_name != sw_name
    assert "o_x[r, j] = x" in rec and "o_x[r, j] = x" not in sw  # no recording path
    assert "parallel=True" in sw and "parallel=True" not in rec.split("def advance(")[0][-300:]
    # no parfor, so no numba thread team under the engine's threads
    assert "prange(" not in sw and "import prange" not in sw


def test_prepare_puts_both_kinds_in_one_pool_sweep_kernels_first(tmp_path: Path, monkeypatch):
    """A first test run's record and sweep kernels go to one pool (no core idles between two
    batches), the longer sweep kernels first; the notice counts families and kernels."""
    from corraoi.engine import kernel_cache, kernel_pool

    monkeypatch.setenv("CORRAOI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(kernel_cache, "LOADED", {})  # as in a fresh process (whatever ran)
    started: list[str] = []

    class Done:  # a worker that has finished at once
        def __init__(self, argv: list[str], **_: object) -> None:
            started.append(argv[4])  # the kernel module's name

        def poll(self) -> int:
            return 0

    monkeypatch.setattr(kernel_pool.subprocess, "Popen", Done)
    notes: list[str] = []
    monkeypatch.setattr(kernel_cache, "on_compile", notes.append)
    classes = [make_policy(n).resolve() for n in ("ucb", "cucb", "ts")]  # two families
    kernel_pool.prepare(classes, record=(True, False))
    assert [n.split("_")[1] for n in started] == ["sweep", "sweep", "record", "record"]
    assert notes[0].startswith("compiling the engine for 2 policy families (ts, ucb, 4 kernels;")
    assert [n.split()[0] for n in notes[1:]] == ["1/4", "2/4", "3/4", "4/4"]


def test_prepare_queues_the_kernels_of_many_sources_first_in_the_same_pool(
        tmp_path: Path, monkeypatch):  # fmt: skip
    """A sweep or a record of several sources compiles the kernel of many sources of each
    family in the pool as well (two families at once), each kind's first (they compile two
    to four times longer), each worker told which kernel's arguments warm it."""
    from corraoi.engine import kernel_cache, kernel_pool

    monkeypatch.setenv("CORRAOI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(kernel_cache, "LOADED", {})
    started: list[tuple[str, str]] = []

    class Done:
        def __init__(self, argv: list[str], **_: object) -> None:
            kind = argv[4].removeprefix("corraoi_").rsplit("_", 1)[0]  # sources_sweep, ...
            started.append((kind, argv[6]))  # and the worker's "one" or "many"

        def poll(self) -> int:
            return 0

    monkeypatch.setattr(kernel_pool.subprocess, "Popen", Done)
    one = [make_policy("ucb").resolve()]
    many = [make_policy(n).resolve() for n in ("rhorand-ucb", "mctopm-cucb", "rhorand-ts")]
    kernel_pool.prepare(one, record=(True, False), many=many)  # mctopm-cucb: ucb's family
    assert started == [("sources_sweep", "many"), ("sources_sweep", "many"), ("sweep", "one"),
                       ("sources_record", "many"), ("sources_record", "many"),
                       ("record", "one")]  # fmt: skip


@njit
def _plain_hook(t, K, npull, nsucc, params, ps, pst):
    return -1


@njit(fastmath=True)
def _fastmath_hook(t, K, npull, nsucc, params, ps, pst):
    return -1


@njit(inline="never")
def _never_hook(t, K, npull, nsucc, params, ps, pst):
    return -1


def test_hooks_are_inlined_unless_their_options_change_their_code():
    """An out-of-line hook doubled a UCB plug-in's time per slot (docs/performance.md): the
    kernel re-declares a plain hook inline="always", the same function; a hook whose options
    change its code is called as declared."""
    from corraoi.engine import _kernel

    got = _kernel.inlined(_plain_hook)
    assert got is not _plain_hook and got.py_func is _plain_hook.py_func
    assert got.targetoptions["inline"] == "always"
    for hook in (_fastmath_hook, _never_hook, got):
        assert _kernel.inlined(hook) is hook
    # the compiled plug-in's kernel (its score hook is a plain @njit) calls it inlined
    cls = make_policy(f"{PLUGINS / 'compiled_greedy.py'}:BonusUCB").resolve()
    kernel = kernels.kernel_for(cls, record=False)
    score = kernel.py_func.__globals__["_score"]
    assert score.py_func.__name__ == "bonus_score"
    assert score.targetoptions["inline"] == "always"


def test_every_sampler_a_kernel_can_call_is_inlined():
    """Kernels and hooks call these in the per-slot loop; out of line, a family ran at full
    or half rate by where its code landed in memory (docs/performance.md)."""
    import inspect

    from corraoi import rng
    from corraoi.policies import builtin_hooks, hooks

    standalone = {"sfc64_doubles"}  # called from Python only (tests against NumPy)
    seen = []
    for module in (rng, hooks, builtin_hooks):
        for name, obj in inspect.getmembers(module, lambda o: hasattr(o, "targetoptions")):
            if obj.py_func.__module__ != module.__name__ or name in standalone:
                continue
            seen.append(name)
            assert obj.targetoptions.get("inline") == "always", f"{module.__name__}.{name}"
    assert {"argmax_random", "beta", "gamma", "integer", "uniform", "ucb_score"} <= set(seen)


def test_the_cache_folder_falls_back_to_the_temp_folder_when_it_cannot_be_written(
    tmp_path: Path, monkeypatch
):
    """kernel_cache.folder: under $CORRAOI_CACHE_DIR (a subfolder for the emulated GPU's
    libraries), else, where that cannot be made or written, one folder in the system's temp
    folder -- never an error."""
    import tempfile

    from corraoi._version import __version__
    from corraoi.engine import kernel_cache

    monkeypatch.setenv("CORRAOI_CACHE_DIR", str(tmp_path / "cache"))
    assert kernel_cache.folder() == tmp_path / "cache" / f"kernels-{__version__}"
    gpu = kernel_cache.folder("gpu-emulation")
    assert gpu == tmp_path / "cache" / f"kernels-{__version__}" / "gpu-emulation" and gpu.is_dir()
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("CORRAOI_CACHE_DIR", str(blocked))
    fallback = Path(tempfile.gettempdir()) / f"corraoi-kernels-{__version__}-{os.getuid()}"
    assert kernel_cache.folder() == fallback == kernel_cache.folder("gpu-emulation")
    assert fallback.is_dir()


#: One run of a tiny kernel through the kernel cache, an interrupt injected at a moment of
#: its compile (argv[1]): inside numba's temporary index or data file, between numba's index
#: and its data, while corraoi writes the checksums, or none. Several moments in one process
#: are a notebook whose cell is stopped again and again.
_INTERRUPTED = """
import json, sys
import numba.core.caching as caching
import corraoi.files.partial as partial
from corraoi.engine import kernel_cache

SOURCE = "from numba import njit\\n@njit(cache=True)\\ndef advance(x):\\n    return x * 2 + 1\\n"
real = (caching.IndexDataCacheFile._save_index, caching.IndexDataCacheFile._save_data,
        partial.PartialFile.write_bytes)

def in_tmp(path_of):
    def save(self, *args):
        with self._open_for_write(path_of(self, *args)) as f:
            f.write(b"half")
            raise KeyboardInterrupt
    return save

def interrupt(*args, **kwargs):
    raise KeyboardInterrupt

INJECT = {
    "index-tmp": ("_save_index", in_tmp(lambda self, overloads: self._index_path)),
    "data-tmp": ("_save_data", in_tmp(lambda self, name, data: self._data_path(name))),
    "no-data": ("_save_data", interrupt),
}
notes, took = [], []
for moment in sys.argv[1].split(","):
    cls = caching.IndexDataCacheFile
    cls._save_index, cls._save_data, partial.PartialFile.write_bytes = real
    if moment in INJECT:
        setattr(cls, *INJECT[moment])
    elif moment == "sums":
        partial.PartialFile.write_bytes = staticmethod(interrupt)
    try:
        fn, seconds = kernel_cache.load(kernel_cache.folder(), "tiny_kernel",
                                        kernel_cache.write_source(kernel_cache.folder(),
                                                                  "tiny_kernel", SOURCE),
                                        "the tiny kernel", warm=lambda: (20,), say=notes.append)
        took.append(seconds)
        assert fn(20) == 41
    except KeyboardInterrupt:
        took.append(None)
print(json.dumps({"notes": notes, "took": took}))
"""


def test_a_compile_interrupted_again_and_again_ends_complete_on_the_next_run(tmp_path: Path):
    """Interrupts at every moment of a compile, in fresh processes and in one process (a
    notebook), leave nothing that is trusted; the next uninterrupted run compiles the entry
    whole, saying why, and the run after it loads it without a word."""
    cache = tmp_path / "cache"
    runs = [_result(_python(_INTERRUPTED, cache, moments))
            for moments in ("index-tmp,data-tmp", "no-data", "sums", "none", "none")]  # fmt: skip
    assert [r["took"] for r in runs[:3]] == [[None, None], [None], [None]]
    for r in runs[1:3]:  # each interrupted compile is told apart from an older corraoi's
        assert r["notes"][0].endswith("was interrupted while it compiled; rebuilding it")
    assert runs[3]["took"][0] > 0 and runs[3]["notes"] == [
        "the cached engine for the tiny kernel was interrupted while it compiled; rebuilding it"
    ]
    assert runs[4] == {"notes": [], "took": [0.0]}  # complete: loaded, not compiled
    left = sorted(p.name for p in cache.rglob("*tiny_kernel*"))
    assert not [n for n in left if ".tmp" in n or n.endswith(".compiling")], left
    assert any(n.endswith(".nbc") for n in left) and ".tiny_kernel.sha256" in left
