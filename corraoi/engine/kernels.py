"""Compose a compiled kernel per policy family and keep it in numba's disk cache.

numba caches a compiled function beside its source file, keyed by that file. A kernel built
as a closure over a policy's hooks has no file of its own and misses the cache, so every new
process would recompile (seconds). Instead, the source of :mod:`corraoi.engine._kernel` is copied
into the kernel cache with its ``HOOKS`` import lines pointing at the family's hooks, under a
name derived from a hash of everything that goes into it (the template, the hooks' modules,
:mod:`corraoi.rng`, the corraoi version). The copy is imported as a module and its ``advance``
is compiled once, then loaded from numba's cache by every later process.

Kernels are per family (the hooks), not per variant: ``correlated`` and ``aoi_aware`` are
runtime flags, so the paper's twelve policies need three families. Each family has two
kernels shaped by their job (the template's docstring): the serial record kernel, which a
one-run ``corraoi record`` compiles in about 3 s, and the sweep kernel, without the per-slot
recording path. A command compiles only the one it uses; when several families must compile
(a first ``--policy all``), :func:`corraoi.engine.kernel_pool.prepare` compiles them in worker
processes at once. Where the copies are kept, locked, checked and compiled:
:mod:`corraoi.engine.kernel_cache`.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from corraoi._version import __version__
from corraoi.errors import KernelError
from corraoi.policies.api import CompiledPolicy

from . import kernel_cache
from .block import Outputs

_TEMPLATE = Path(__file__).with_name("_kernel.py")
#: The kernel of many sources (issue 43): a sibling template that calls _kernel's shared
#: functions, composed with the same hooks (its docstring says why it is not _kernel's).
_SOURCES_TEMPLATE = Path(__file__).with_name("_sources_kernel.py")
_RNG = Path(__file__).parent.parent / "rng.py"
_HOOK_LINES = (
    "from corraoi.policies.hooks import forced_none as _forced  # HOOKS",
    "from corraoi.policies.hooks import score_none as _score  # HOOKS",
    "from corraoi.policies.hooks import update_none as _update  # HOOKS",
)
#: Seconds this process spent compiling kernels (speed figures such as record's slots/s
#: leave them out).
compile_seconds = 0.0


def load_hook(ref: Any, role: str, policy: type[CompiledPolicy]) -> Any:
    """The numba function a hook names: itself, or ``"module:function"`` imported."""
    if not isinstance(ref, str):
        return ref
    modname, _, attr = ref.partition(":")
    try:
        module = importlib.import_module(modname)
        return getattr(module, attr)
    except (ImportError, AttributeError) as exc:
        raise KernelError(
            f"policy {policy.name}: its {role} hook {ref!r} cannot be imported: {exc}"
        ) from None


def _hook_ref(ref: Any, role: str, policy: type[CompiledPolicy]) -> tuple[str, str, Path | None]:
    """(module, attribute, source file) of a compiled hook, which must be importable."""
    hook = load_hook(ref, role, policy)
    func = getattr(hook, "py_func", None)
    if func is None or not hasattr(hook, "compile"):
        raise KernelError(
            f"policy {policy.name}: its {role} hook {hook!r} is not a numba @njit function"
        )
    modname, attr = func.__module__, func.__name__
    module = sys.modules.get(modname)
    if module is None or getattr(module, attr, None) is not hook:
        raise KernelError(
            f"policy {policy.name}: its {role} hook {attr} must be defined at the top level of "
            f"module {modname} (hooks are imported by the generated kernel)"
        )
    file = getattr(module, "__file__", None)
    return modname, attr, Path(file) if file else None


def hooks_of(policy: type[CompiledPolicy]) -> tuple[Any, Any, Any]:
    return (
        policy.forced if policy.forced is not None else "corraoi.policies.hooks:forced_none",
        policy.score if policy.score is not None else "corraoi.policies.hooks:score_none",
        policy.update if policy.update is not None else "corraoi.policies.hooks:update_none",
    )


def kernel_source(policy: type[CompiledPolicy], *, record: bool,
                  sources: bool = False) -> tuple[str, str]:  # fmt: skip
    """(module name, source) of the record or sweep kernel of ``policy``'s family: the
    single-source kernel, or with ``sources`` the kernel of many sources."""
    refs = [
        _hook_ref(h, role, policy)
        for h, role in zip(hooks_of(policy), ("forced", "score", "update"), strict=True)
    ]
    template = _SOURCES_TEMPLATE if sources else _TEMPLATE
    text = template.read_text(encoding="utf-8")
    digest = hashlib.sha256(text.encode())
    if sources:  # it calls _kernel's functions: a change there is a change here
        digest.update(_TEMPLATE.read_bytes())
    digest.update(_RNG.read_bytes())
    digest.update(__version__.encode())
    digest.update(b"record" if record else b"sweep")
    for (modname, attr, file), line, alias in zip(
        refs, _HOOK_LINES, ("_forced", "_score", "_update"), strict=True
    ):
        if line not in text:
            raise KernelError(f"kernel template {template}: hook line missing: {line}")
        text = text.replace(line, f"from {modname} import {attr} as {alias}  # HOOKS")
        digest.update(f"{modname}:{attr}".encode())
        # the bytes the hook's module was loaded from (a plug-in's exact source: the file
        # may have changed since, or a sweep's kept copy runs): never the file read again
        loaded = getattr(sys.modules.get(modname), "__corraoi_source__", None)
        if isinstance(loaded, bytes):
            digest.update(loaded)
        elif file is not None and file.is_file():
            digest.update(file.read_bytes())
    if not record:
        text = _sweep_variant(text)
    header = (
        f"# Generated by corraoi.engine.kernels from corraoi/engine/{template.name}: the "
        + ("record" if record else "sweep")
        + " kernel of one policy\n# family. Do not edit; delete the folder to clear the cache.\n"
    )
    what = ("sources_" if sources else "") + ("record" if record else "sweep")
    name = f"corraoi_{what}_{digest.hexdigest()[:20]}"
    return name, header + text


@functools.lru_cache(maxsize=64)
def _sweep_variant(text: str) -> str:
    """The template with the sweep kernel's decorator and without the recording path (kept
    per text: a sweep asks for each policy's kernel twice a chunk)."""
    lines = text.split("\n")
    out: list[str] = []
    skipping = False
    swapped = 0
    for line in lines:
        stripped = line.strip()
        if stripped == "# RECORD-BEGIN":
            skipping = True
        elif stripped == "# RECORD-END":
            skipping = False
        elif skipping:
            continue
        elif stripped.endswith("# KERNEL") and stripped.startswith("@njit("):
            out.append(f"{line[: len(line) - len(line.lstrip())]}{_sweep_decorator(text)}")
            swapped += 1
        else:
            out.append(line)
    if swapped != 1 or skipping:
        raise KernelError(f"kernel template {_TEMPLATE}: KERNEL or RECORD markers are broken")
    return "\n".join(out)


def _sweep_decorator(text: str) -> str:
    from . import _kernel

    return _kernel.SWEEP_DECORATOR


def warm_args(K: int = 2) -> tuple[Any, ...]:
    """Arguments of a zero-slot ``advance`` call with the types the engine passes (so the
    compiled signature is the one the engine will look up in the cache)."""
    R = 1
    f8, i8 = np.float64, np.int64
    return (
        np.ones((1, 2), f8), 0, np.zeros(1, i8), np.zeros((K, 2), np.int8),
        np.zeros((K, 8, 1), np.uint64), 0, False, False,
        np.zeros(0, f8), 0, 0,
        np.zeros((R, 4), np.uint64), np.zeros((R, 4), np.uint64), np.zeros((R, 2), f8),
        np.zeros((R, 1), f8), np.full(R, -1, i8), np.zeros((R, K), i8), np.zeros((R, K), i8),
        np.ones(R, i8), np.ones(R, i8), np.zeros(R, i8), np.zeros(R, i8), np.zeros((R, 3), i8),
        False, *Outputs(R, 0, K).buffers(),
        np.empty(0, i8), np.empty((R, 0), i8), np.empty((R, 0), i8), np.empty((R, 0, K), i8),
    )  # fmt: skip


def kernel_for(policy: type[CompiledPolicy], *, record: bool,
               sources: Callable[[], tuple[Any, ...]] | None = None) -> Any:  # fmt: skip
    """The compiled ``advance`` of ``policy``'s family: the record kernel (per-slot columns)
    or the sweep kernel (finals and snapshots only), built, cached and loaded on demand.
    ``sources``: the kernel of many sources (:mod:`corraoi.engine._sources_kernel`) instead,
    warmed with the arguments this gives (``corraoi.engine.sources.warm_args``)."""
    global compile_seconds
    modname, source = kernel_source(policy, record=record, sources=sources is not None)
    kernel, took = kernel_cache.kernel(modname, source, policy.name,
                                       warm=warm_args if sources is None else sources,
                                       say=kernel_cache.on_compile)  # fmt: skip
    compile_seconds += took
    return kernel
