"""docs/examples/analysis.ipynb runs from top to bottom (when the notebook extras are here)."""

from __future__ import annotations

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parent.parent / "docs" / "examples" / "analysis.ipynb"


@pytest.mark.slow
def test_the_analysis_notebook_runs(tmp_path: Path):
    for name in ("nbclient", "nbformat", "ipykernel", "pandas", "pyarrow", "matplotlib"):
        why = f'{name} is not installed (pip install -e ".[analysis,notebook]")'
        pytest.importorskip(name, reason=why)
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(NOTEBOOK, as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), "commit it clean"
    client = NotebookClient(nb, timeout=240, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})  # fmt: skip
    client.execute()
    text = "\n".join(
        o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs
    )
    assert "paired against cucb" in text  # the sweep's paired table was printed
    assert "cucb 3 201 slots" in text  # the window holds slots 400..600
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if "image/png" in o.get("data", {})]  # fmt: skip
    assert images, "the paired comparison plot was drawn"
    last = nb.cells[-1].outputs
    try:
        import rerun_notebook  # noqa: F401
    except ImportError:  # corraoi.show said what to install, in one line
        said = "".join(o.get("text", "") for o in last)
        assert 'pip install "corraoi[notebook]"' in said and said.count("\n") == 1, said
    else:  # the Rerun viewer widget was displayed inline (corraoi.show)
        assert any("application/vnd.jupyter.widget-view+json" in o.get("data", {}) for o in last)


QUICKSTART = NOTEBOOK.with_name("quickstart.ipynb")


def execute_quickstart(tmp_path: Path):
    """docs/examples/quickstart.ipynb executed in a fresh kernel (nbclient); returns it."""
    for name in ("nbclient", "nbformat", "ipykernel", "pandas", "pyarrow", "rerun_notebook"):
        why = f'{name} is not installed (pip install -e ".[notebook]")'
        pytest.importorskip(name, reason=why)
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(QUICKSTART, as_version=4)
    assert all(not c.get("outputs") and c.get("execution_count") is None
               for c in nb.cells if c.cell_type == "code"), "commit it clean"  # fmt: skip
    client = NotebookClient(nb, timeout=240, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})  # fmt: skip
    client.execute()
    return nb


@pytest.mark.slow
def test_the_quickstart_notebook_records_sweeps_drills_and_shows(tmp_path: Path):
    import re

    nb = execute_quickstart(tmp_path)
    code = [c for c in nb.cells if c.cell_type == "code"]
    html = ["".join(o.get("data", {}).get("text/html", "") for o in c.outputs) for c in code]
    assert "cucb-I1-s0" in html[1] and "AoI regret (pathwise)" in html[1]  # the Run's table
    assert "I1, 20 runs, T = 2000" in html[2]  # the Sweep's table
    assert "<td>ucb</td>" in html[2] and "<td>cucb</td>" in html[2]
    # the drilled run's regret is the sweep's row (the notebook asserts it too)
    text = "".join(o.get("text", "") for o in code[3].outputs)
    found = re.search(r"regret (\d+) in the sweep, (\d+) recorded again", text)
    assert found and found[1] == found[2], text
    import json

    summary = json.loads(next(Path(p) for p in _work_folders(html[2])).joinpath(
        "summary.json").read_text())  # fmt: skip
    assert int(found[1]) == summary["notable"]["cells"]["ucb"]["worst"]["regret"]
    assert "worst.mcap" in html[3]  # the drilled Run's table names its files
    # the show cell: the Rerun viewer widget, and nothing printed beside it
    (shown,) = code[4].outputs
    view = shown["data"]["application/vnd.jupyter.widget-view+json"]
    state = nb.metadata["widgets"]["application/vnd.jupyter.widget-state+json"]["state"]
    model = state[view["model_id"]]["state"]
    # its JavaScript comes from this kernel's server on 127.0.0.1, not from the network
    assert re.fullmatch(r"http://127\.0\.0\.1:\d+/widget\.js", model["_esm"]), model["_esm"]
    assert model["_height"] == 640 and model["_width"] == "auto"


def _work_folders(html: str) -> list[str]:
    """The sweep folder named in the Sweep's table (``...: /tmp/corraoi-quickstart-.../sweep``)."""
    import re

    return re.findall(r": (/\S+/sweep)</p>", html)
