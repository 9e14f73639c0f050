"""The progress bar (click's): drawn on a terminal, silent otherwise."""

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
    assert "sweep  [" in text and "   25%" in text and "  100%" in text and "cts" in text
    assert text.index("25%") < text.index("100%")
    assert text.endswith("\n")
    assert bar.done == 200


def test_silent_when_not_a_terminal():
    out = io.StringIO()
    with Progress(10, "sweep", stream=out) as bar:
        bar.update(10)
    assert out.getvalue() == ""
    assert bar.done == 10


def test_updates_are_throttled_but_the_last_one_is_drawn():
    out = FakeTTY()
    with Progress(1000, "record", stream=out, min_interval=3600.0) as bar:
        for _ in range(10):
            bar.update(100)
    text = out.getvalue()
    # drawn at the start (0%), at the first update, and at 100%; the eight between wait
    assert text.count("%") == 3 and "   10%" in text and "  100%" in text
    assert "20%" not in text


def test_updates_past_the_total_stop_at_the_total():
    out = io.StringIO()
    with Progress(10, "x", stream=out) as bar:
        bar.update(7)
        bar.update(7)
    assert bar.done == 10
