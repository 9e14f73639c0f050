"""docs/python-api.md runs as shown: its Python blocks, in order, in one fresh folder and one
namespace (as a reader pastes them into one session), and each prints what it says."""

from __future__ import annotations

import contextlib
import io
import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "python-api.md"


def _blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", DOC.read_text(), flags=re.S)


def test_the_page_has_examples():
    assert len(_blocks()) >= 5


def test_every_example_runs_in_order(tmp_path: Path) -> None:
    namespace: dict[str, object] = {"__name__": "__main__"}
    out = io.StringIO()
    old = os.getcwd()
    os.chdir(tmp_path)
    try:
        with contextlib.redirect_stdout(out):
            for block in _blocks():
                exec(compile(block, str(DOC), "exec"), namespace)  # noqa: S102
    finally:
        os.chdir(old)
    text = out.getvalue().splitlines()
    # what the comments promise
    assert text[0] == "Run('runs/cucb-I1-s0.mcap', cucb-I1-s0, complete)"
    assert text[3] == "runs/cucb-I1-s0.rrd"
    assert "{'epsilon': 0.05}" in text
    assert "True" in text  # the worst run's regret equals the sweep's, the paired path
    assert (tmp_path / "sweeps" / "py" / "summary.json").is_file()
    assert (tmp_path / "runs" / "ucb-vs-cucb.rrd").is_file()
    # show: served on the loopback, the recording Sweep.record wrote, stopped by close()
    url = next(line for line in text if line.startswith("http://"))
    assert url.startswith("http://127.0.0.1:") and "rerun%2Bhttp%3A%2F%2F127.0.0.1" in url
    assert repr([namespace["worst"].rrd]) in text  # type: ignore[attr-defined]
    assert namespace["shown"].closed  # type: ignore[attr-defined]
