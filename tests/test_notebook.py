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
    except ImportError:
        assert "rerun-notebook is not installed" in "".join(o.get("text", "") for o in last)
    else:  # the Rerun viewer widget was displayed inline
        assert any("application/vnd.jupyter.widget-view+json" in o.get("data", {}) for o in last)
