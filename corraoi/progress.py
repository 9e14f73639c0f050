"""A dependency-free progress bar on stderr, shown only when stderr is a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """``with Progress(total, "sweep") as bar: bar.update(n)``; silent when not a TTY."""

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
        self._start = time.perf_counter()
        self._last = 0.0
        self._min_interval = min_interval

    def __enter__(self) -> Progress:
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def update(self, n: int = 1, *, note: str = "") -> None:
        self.done = min(self.done + int(n), self.total)
        now = time.perf_counter()
        if self.enabled and (now - self._last >= self._min_interval or self.done == self.total):
            self._last = now
            self._draw(note)

    def _draw(self, note: str) -> None:
        frac = self.done / self.total
        width = 30
        filled = int(frac * width)
        elapsed = time.perf_counter() - self._start
        eta = elapsed / frac - elapsed if frac > 0 else 0.0
        bar = "#" * filled + "-" * (width - filled)
        extra = f" {note}" if note else ""
        self.stream.write(
            f"\r{self.label} [{bar}] {frac:6.1%} {elapsed:5.1f}s eta {eta:5.1f}s{extra}\x1b[K"
        )
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
            self.enabled = False
