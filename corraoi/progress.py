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
