"""The golden files (tests/golden/, made by ``python tests/golden/regenerate.py``): every
built-in's decisions and the golden slot logs, pinned by value (integers exactly, floats that
are not inputs within 1e-12 relative), in this process and from an empty kernel cache in a
fresh one; and CI's own empty kernel cache (issue 45, item 6)."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from .scripts import load_script

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "golden"


def regenerate() -> Any:
    return load_script("tests/golden/regenerate.py")


def test_differences_pins_integers_exactly_and_floats_within_1e_12():
    g = regenerate()
    assert g.differences({"a": [1, 2.0]}, {"a": [1, 2.0 * (1 + 0.9e-12)]}) == []
    assert g.differences({"a": [1, 2.0]}, {"a": [1, 2.0 * (1 + 1.1e-12)]}) != []
    assert g.differences([3], [4]) == ["[0]: 4, expected 3"]
    assert g.differences([3], [3.0]) == []  # a float on either side compares by value
    assert g.differences({"x": "abc"}, {"x": "abd"}) == ["/x: 'abd', expected 'abc'"]
    assert g.differences({"x": [1, 2]}, {"x": [1]}) == ["/x: 1 items, expected 2"]
    assert g.differences({"x": 1}, {"x": 1, "score": 2}) == ["/score: new (not in the golden file)"]
    assert g.differences([float("nan")], [float("nan")]) == []
    assert g.differences([True], [1]) != []


def test_golden_runs_of_every_builtin():
    g = regenerate()
    stored = json.loads((GOLDEN / "builtins.json").read_text())
    now = g.golden()
    assert set(stored["runs"]) == set(now["runs"])  # every built-in on every instance
    assert {k.split("/")[0] for k in now["runs"]} == {"I1", "I2", "golden-wide", "GE"}
    found = g.differences(stored, now)
    assert found == [], "changed (rerun tests/golden/regenerate.py only if intended):\n" + \
        "\n".join(found)  # fmt: skip


def test_golden_logs_value_for_value():
    g = regenerate()
    stored = json.loads((GOLDEN / "logs.json").read_text())
    assert set(stored) == {g.case_name(k) for k in g.LOG_CASES}
    found = g.differences(stored, g.logs())
    assert found == [], "\n".join(found)
    ge = stored["GE/cts/s3/T600"]["metadata"]
    # the Gilbert-Elliott chain's stationary law, exact, and mu* = 0.75 from it
    assert ge["p"] == [0.75, 0.25] and ge["mu_star"] == 0.75
    est = stored["GE/cts/s3/T600"]["columns"]["estimator"]
    assert est[0] == 2 - 1 / 0.75  # slot 1: age 2 (a failure), minus t / mu*


@pytest.mark.slow
def test_the_golden_cases_from_an_empty_kernel_cache_in_a_fresh_process(tmp_path: Path):
    """No kernel compiled before (an empty CORRAOI_CACHE_DIR), a new interpreter: the same
    values. A cache filled by older code can then never be what makes the golden tests
    pass. As near another machine as this one gets: numba compiles for a generic CPU of
    this architecture (no AVX) and OpenBLAS takes its oldest x86-64 kernels."""
    import platform

    cache = tmp_path / "cache"
    env = {**os.environ, "CORRAOI_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT),
           "NUMBA_CPU_NAME": "generic"}  # fmt: skip
    if platform.machine() in ("x86_64", "AMD64"):
        env["OPENBLAS_CORETYPE"] = "Prescott"
    res = subprocess.run(
        [sys.executable, str(GOLDEN / "regenerate.py"), "--check"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1200,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    assert "golden: every value as pinned" in res.stdout
    compiled = list(cache.rglob("*.nbi"))  # compiled there and then, not loaded
    assert compiled, f"no kernel compiled in {cache}"


def test_regenerate_check_names_a_change_and_fails(tmp_path: Path):
    g = regenerate()
    stored = json.loads((GOLDEN / "builtins.json").read_text())
    stored["theory"]["GE"]["mu_star"] = 0.75000000075
    found = g.differences(stored, g.golden(), "builtins.json")
    assert found == ["builtins.json/theory/GE/mu_star: 0.75, expected 0.75000000075 "
                     "(within 1e-12 relative)"]  # fmt: skip


def test_ci_run_empties_a_kernel_cache_of_its_own_that_git_ignores(tmp_path: Path):
    """.ci/run exports CORRAOI_CACHE_DIR, inside the checkout and ignored by git, emptied
    before the README's block runs: what a stale cache held is gone."""
    work = tmp_path / "checkout"
    (work / ".ci").mkdir(parents=True)
    shutil.copy(ROOT / ".ci" / "run", work / ".ci" / "run")
    block = 'echo "cache=$CORRAOI_CACHE_DIR"; ls -A "$CORRAOI_CACHE_DIR" | wc -l'
    (work / "README.md").write_text(f"```bash\nfirst\n```\n\n```bash\n{block}\n```\n")
    stale = work / ".ci" / "kernel-cache" / "kernels-0" / "stale.nbi"
    stale.parent.mkdir(parents=True)
    stale.write_text("old")
    fake = tmp_path / "bin"  # so that .ci/run does not install a browser here
    fake.mkdir()
    (fake / "chromium").write_text("#!/bin/sh\n")
    (fake / "chromium").chmod(stat.S_IRWXU)
    env = {**os.environ, "PATH": f"{fake}{os.pathsep}{os.environ['PATH']}"}
    env.pop("CORRAOI_CACHE_DIR", None)
    res = subprocess.run(["bash", str(work / ".ci" / "run")], env=env, capture_output=True,
                         text=True, timeout=60)  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    lines = res.stdout.strip().splitlines()
    assert lines[-2] == f"cache={work / '.ci' / 'kernel-cache'}" and lines[-1].strip() == "0"
    assert not stale.exists()
    ignored = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "-q",
                              ".ci/kernel-cache/kernels-0/x.nbi"])  # fmt: skip
    assert ignored.returncode == 0, ".ci/kernel-cache/ is not ignored by .gitignore"
