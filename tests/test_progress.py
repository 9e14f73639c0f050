"""The progress bar: drawn on a terminal, silent otherwise."""

from __future__ import annotations

import io

from corraoi.progress import Progress


class FakeTTY(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_draws_on_a_terminal_and_reaches_100_percent():
    out = FakeTTY()
    with Progress(200, "sweep", stream=out, min_interval=0.0) as bar:
        bar.update(50)
        bar.update(150, note="cts")
    text = out.getvalue()
    assert "sweep [" in text and " 25.0%" in text and "100.0%" in text and "cts" in text
    assert text.endswith("\n")


def test_silent_when_not_a_terminal():
    out = io.StringIO()
    with Progress(10, "sweep", stream=out) as bar:
        bar.update(10)
    assert out.getvalue() == ""
    assert bar.done == 10
