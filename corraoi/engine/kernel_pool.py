"""Compiling several kernels at once, in worker processes that share the kernel cache.

A first ``corraoi sweep --policy all`` (or a first test run) needs several families' kernels,
each compiled in seconds by one core. :func:`prepare` compiles the ones the cache lacks in
worker processes, one kernel each and one per core at a time, with one notice and a progress
line (through :data:`corraoi.engine.kernel_cache.on_compile`). The caller then loads each
from the cache; a kernel a worker could not compile is compiled in-process when it is
needed, and reported there with its policy's name. Kernel locks
(:mod:`corraoi.engine.kernel_cache`) make a kernel that two processes need at once compile
once.

(Workers that each compile kernel after kernel, paying numba's import once per core rather
than once per kernel, were measured: all 24 built-ins' 14 kernels from an empty cache in
31.95 s against 32.68 s, within this machine's noise; not kept.)
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from corraoi.errors import KernelError
from corraoi.policies.api import CompiledPolicy
from corraoi.policies.loading import PLUGIN_MODULE_PREFIX

from . import kernel_cache, kernels

# A worker: compile one generated kernel module into the shared cache, warmed with the
# arguments of the single-source kernel ("one") or of the kernel of many sources ("many").
# A failure is left to the parent (module docstring).
_WORKER = (
    "import sys\n"
    "from pathlib import Path\n"
    "from corraoi.engine import kernel_cache, kernels\n"
    "if sys.argv[4] == 'many':\n"
    "    from corraoi.engine.sources import warm_args as warm\n"
    "else:\n"
    "    warm = kernels.warm_args\n"
    "kernel_cache.load(Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3]), sys.argv[2],\n"
    "                  warm=warm)\n"
)


def prepare(policies: Iterable[type[CompiledPolicy]], *, record: bool | tuple[bool, ...],
            many: Iterable[type[CompiledPolicy]] = ()) -> None:  # fmt: skip
    """Compile the kernels ``policies`` need that are not cached yet, concurrently (module
    docstring). Families whose hooks a fresh process cannot import (a plug-in loaded from a
    file) compile in-process later, as before. ``record``: the record kernels (True), the
    sweep kernels (False) or both (``(True, False)``: one pool, the sweep kernels first as
    they take longest, so that no core waits for the other at the end). ``many``: policies
    whose kernel of many sources (:mod:`corraoi.engine._sources_kernel`) is wanted, in the
    same pool (each kind's first: they compile two to four times longer)."""
    kinds = sorted({record} if isinstance(record, bool) else set(record))  # False first
    folder = kernel_cache.folder()
    todo: dict[str, tuple[Path, str, bool]] = {}
    wanted = [(p, True) for p in many] + [(p, False) for p in policies]
    for kind in kinds:
        for policy, sources in wanted:
            try:
                modname, source = kernels.kernel_source(policy, record=kind, sources=sources)
            except KernelError:
                continue  # reported by kernel_for with the policy's name
            if modname in todo or kernel_cache.ready(folder, modname):
                continue
            if not all(_importable(ref) for ref in kernels.hooks_of(policy)):
                continue
            path = kernel_cache.write_source(folder, modname, source)
            todo[modname] = (path, policy.name, sources)
    if len(todo) < 2:
        return  # one kernel compiles as fast in this process
    start = time.perf_counter()
    names = sorted({name for _, name, _ in todo.values()})
    cores = min(len(todo), os.cpu_count() or 1)
    say = kernel_cache.on_compile
    if say is not None:
        what = "" if len(todo) == len(names) else f", {len(todo)} kernels"
        say(f"compiling the engine for {len(names)} policy families ({', '.join(names)}{what}; "
            f"first use, {cores} at a time; cached in {folder})")  # fmt: skip
    pending = list(todo.items())
    running: list[subprocess.Popen[bytes]] = []
    done = 0
    try:
        while pending or running:
            while pending and len(running) < cores:
                modname, (path, _, sources) = pending.pop(0)
                running.append(
                    subprocess.Popen(
                        [sys.executable, "-c", _WORKER, str(folder), modname, str(path),
                         "many" if sources else "one"],
                        stdout=subprocess.DEVNULL,
                        stderr=subprocess.DEVNULL,
                    )
                )
            time.sleep(0.02)
            for proc in [p for p in running if p.poll() is not None]:
                running.remove(proc)
                done += 1
                if say is not None:
                    took = time.perf_counter() - start
                    say(f"  {done}/{len(todo)} compiled ({took:.1f} s)")
    finally:
        for proc in running:  # interrupted: stop the workers (their locks go with them)
            proc.kill()
            proc.wait()
    kernels.compile_seconds += time.perf_counter() - start


def prepare_for(wanted: Iterable[tuple[Any, bool]], *, record: bool) -> None:
    """:func:`prepare` for ``(resolved policy class, of many sources)`` pairs, as a sweep's
    cells or a record's plans give them: the compiled ones, each family once (a plain-Python
    policy has no kernel)."""
    one: dict[str, type[CompiledPolicy]] = {}
    many: dict[str, type[CompiledPolicy]] = {}
    for cls, sources in wanted:
        if isinstance(cls, type) and issubclass(cls, CompiledPolicy):
            (many if sources else one)[cls.name] = cls
    prepare(one.values(), record=record, many=many.values())


def _importable(ref: Any) -> bool:
    """Whether a fresh process can import the hook ``ref`` by its module's name."""
    if isinstance(ref, str):
        modname = ref.partition(":")[0]
    else:
        func = getattr(ref, "py_func", None)
        modname = getattr(func, "__module__", "") if func is not None else ""
    if not modname or modname.startswith(PLUGIN_MODULE_PREFIX):  # a file plug-in: this process
        return False
    module = sys.modules.get(modname)
    file = getattr(module, "__file__", None) if module is not None else None
    if module is not None and file is None:
        return False
    try:
        spec = importlib.util.find_spec(modname)
    except (ImportError, ValueError):
        return False
    if spec is None or spec.origin is None:
        return False
    return file is None or Path(spec.origin).resolve() == Path(file).resolve()
