"""docs/scaling.md runs as shown: its commands (a scheduler and workers on 127.0.0.1
included, stopped by the test) and its Python examples."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("dask.distributed")
pytest.importorskip("pyarrow")

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "scaling.md"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(), flags=re.S)


def test_the_experiment_file_in_the_doc_is_the_shipped_one():
    shipped = (ROOT / "docs" / "examples" / "experiment.toml").read_text()
    def keys(text: str) -> list[str]:
        lines = [ln.split("#")[0].rstrip() for ln in text.splitlines()]
        return [ln for ln in lines if ln]

    assert keys(shipped) == keys(blocks("toml")[0])


@pytest.mark.slow
def test_every_command_and_example_runs_as_shown(tmp_path: Path):
    shutil.copytree(ROOT / "docs" / "examples", tmp_path / "docs" / "examples")
    bindir = Path(sys.executable).parent
    env = {**os.environ, "PATH": f"{bindir}{os.pathsep}{os.environ['PATH']}"}
    script = "set -euo pipefail\ntrap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n"
    script += "\n".join(blocks("bash")) + "\n"
    res = subprocess.run(["bash", "-c", script], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=400)  # fmt: skip
    # (Dask's scheduler and workers print their own shutdown noise when the trap stops them;
    # a corraoi command that failed would stop the script: set -e.)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "corraoi: error" not in res.stderr
    for folder in ("grid-cli", "grid", "grid-cluster"):
        assert (tmp_path / folder / "manifest.json").exists(), folder
    # the cluster's runs are the laptop's (which were then extended to 60 runs and ts)
    from corraoi.recorder.sweeplog.results import read_results

    keys = ["instance", "policy", "params", "horizon", "run", "t"]
    cluster = read_results(tmp_path / "grid-cluster" / "results.parquet")
    laptop = read_results(tmp_path / "grid" / "results.parquet")
    both = cluster.merge(laptop, on=keys, suffixes=("_c", "_l"))
    assert len(both) == len(cluster) and len(laptop) > len(cluster)
    assert (both["regret_c"] == both["regret_l"]).all()
    code = "\n".join(blocks("python"))
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
