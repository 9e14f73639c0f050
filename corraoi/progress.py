"""Progress on stderr (click's progress bar), drawn only when stderr is a terminal; and the
one-line notice shown while the engine's kernels compile on first use."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

import click


class Progress:
    """``with Progress(total, "sweep") as bar: bar.update(n)``; silent when not a TTY.

    A thin wrapper over :func:`click.progressbar` that keeps a count (``done``), takes a
    note per update (shown after the bar) and redraws at most every ``min_interval``
    seconds (and at 100%).
    """

    def __init__(
        self,
        total: int,
        label: str,
        *,
        stream: TextIO | None = None,
        enabled: bool | None = None,
        min_interval: float = 0.1,
    ) -> None:
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            isatty = getattr(self.stream, "isatty", None)
            enabled = bool(isatty and isatty())
        self.enabled = enabled
        self.done = 0
        self._pending = 0
        self._last = float("-inf")
        self._min_interval = min_interval
        self._bar: Any = None

    def __enter__(self) -> Progress:
        if self.enabled:
            self._bar = click.progressbar(
                length=self.total,
                label=self.label,
                file=self.stream,
                show_eta=True,
                show_percent=True,
                width=30,
                item_show_func=lambda note: note,
            )
            self._bar.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def update(self, n: int = 1, *, note: str = "") -> None:
        step = min(int(n), self.total - self.done)
        self.done += step
        if self._bar is None:
            return
        self._pending += step
        now = time.perf_counter()
        if now - self._last >= self._min_interval or self.done == self.total:
            self._last = now
            self._bar.update(self._pending, current_item=note or None)
            self._pending = 0

    def close(self) -> None:
        bar, self._bar = self._bar, None
        if bar is not None:
            if self._pending:
                bar.update(self._pending)
                self._pending = 0
            bar.__exit__(None, None, None)
            self.enabled = False


#: The engine calls ``compile_notice(True)`` before it compiles its kernels (the first use
#: in a fresh install; later runs load them from numba's cache) and ``compile_notice(False)``
#: when done; the CLI subtracts :func:`compile_seconds` from its speed figures.
_compile: dict[str, float] = {"started": 0.0, "total": 0.0}


def compile_notice(starting: bool, *, stream: TextIO | None = None) -> None:
    """Say once on stderr that the kernels are being compiled, and time it."""
    if starting:
        _compile["started"] = time.perf_counter()
        out = stream if stream is not None else sys.stderr
        try:
            out.write("corraoi: compiling the simulation kernels (first use only)...\n")
            out.flush()
        except (OSError, ValueError):
            pass
    elif _compile["started"]:
        _compile["total"] += time.perf_counter() - _compile["started"]
        _compile["started"] = 0.0


def compile_seconds() -> float:
    """Seconds spent compiling kernels in this process so far (0.0 if none were)."""
    return _compile["total"]


def kernels_need_compiling() -> bool:
    """Whether the engine's kernels will be compiled on their next call: not compiled in
    this process yet, and no numba cache index for them on disk (a fresh install)."""
    import os

    try:
        from . import _kernel
    except ImportError:  # pragma: no cover - the engine is part of corraoi
        return False
    for name in ("advance",):
        dispatcher = getattr(_kernel, name, None)
        if dispatcher is None or getattr(dispatcher, "signatures", None):
            return False
        cache = getattr(dispatcher, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
        if index is None or os.path.exists(index):
            return False
    return True


class CompileWatch:
    """Around the engine's first block: the notice on stderr if the kernels will compile,
    and the seconds that took (subtracted from speed figures).

    ``watch = CompileWatch(); ...; watch.first_block()`` after the first block arrives.
    """

    def __init__(self, *, stream: TextIO | None = None) -> None:
        self.active = kernels_need_compiling()
        self.seconds = 0.0
        self._start = time.perf_counter()
        if self.active:
            compile_notice(True, stream=stream)

    def first_block(self) -> None:
        if self.active:
            self.active = False
            self.seconds = time.perf_counter() - self._start
            compile_notice(False)
