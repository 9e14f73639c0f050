"""corraoi.testing and the corraoi_run pytest fixture (registered through pytest11), and the
example test of docs/analysis.md, run as a user would run it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from corraoi.recorder.slotlog.reader import open_log
from corraoi.testing import assert_runs_equal

ROOT = Path(__file__).resolve().parent.parent


def test_the_fixture_records_a_run_and_twice_is_equal(corraoi_run: Callable[..., Path]):
    a = corraoi_run(policy="cts", seed=7, horizon=1500)
    b = corraoi_run(policy="cts", seed=7, horizon=1500)
    assert a.path != b.path and a.path.is_file() and b.path.is_file() and a.complete
    log = open_log(a)
    assert (log.config.policy.name, log.config.seed, log.n_slots) == ("cts", 7, 1500)
    assert_runs_equal(a, b)
    assert_runs_equal(open_log(a), b)  # an opened log works too


def test_a_difference_names_the_first_slot_field_values_and_extent(
    corraoi_run: Callable[..., Path],
):
    a = corraoi_run(policy="ucb", seed=1, horizon=2000)
    b = corraoi_run(policy="cucb", seed=1, horizon=2000)
    # where the runs first differ, found independently of corraoi.viewer.diff
    la, lb = open_log(a).read_all(), open_log(b).read_all()
    firsts = {}
    for name in ("arm", "aoi", "pulls", "candidates"):
        ca, cb = la.column(name), lb.column(name)
        ne = ca != cb
        bad = ne.any(axis=1) if ne.ndim > 1 else ne
        firsts[name] = int(la.t[bad.argmax()]) if bad.any() else None
    first = min(v for v in firsts.values() if v is not None)
    with pytest.raises(AssertionError) as info:
        assert_runs_equal(a, b)
    msg = str(info.value)
    head = msg.splitlines()[0]
    assert head.startswith(f"runs differ from slot {first}: field ")
    field = head.split("field ")[1].split(" ")[0]
    assert firsts.get(field, first) == first
    assert "divergence: " in msg and " slots differ (first at slot " in msg
    assert "policy.name ('ucb' != 'cucb')" in msg
    if field == "arm":  # arms are numbered from 1 in the message
        i = first - 1
        assert f"is {int(la.arm[i]) + 1} in a and {int(lb.arm[i]) + 1} in b" in head


def test_fields_restrict_the_comparison(corraoi_run: Callable[..., Path]):
    a = corraoi_run(policy="ts", seed=2, horizon=1000)
    b = corraoi_run(policy="ts", seed=3, horizon=1000)
    with pytest.raises(AssertionError, match="field x"):
        assert_runs_equal(a, b, fields=["x"])  # a different seed: a different hidden path


def test_loaded_runs_compare_too(corraoi_run: Callable[..., Path]):
    pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    import corraoi

    a = corraoi_run(policy="cucb", seed=0, horizon=1000)
    assert_runs_equal(corraoi.load(a), corraoi.load(corraoi_run(policy="cucb", horizon=1000)))


def test_the_plugin_imports_nothing_heavy():
    code = (
        "import sys, corraoi.pytest_plugin; "
        "print([m for m in ('numba', 'numpy', 'corraoi.recorder', 'corraoi.viewer', "
        "'corraoi.engine.simulation') "
        "if m in sys.modules])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_docs_example_test_passes(tmp_path: Path):
    """docs/analysis.md's example test, run by pytest in a fresh directory: the fixture
    comes from the installed entry point, not from this suite's conftest."""
    text = (ROOT / "docs" / "analysis.md").read_text()
    blocks = re.findall(r"^```python\n(# test_[a-z_]+\.py\n.*?)^```$", text, flags=re.S | re.M)
    assert blocks, "docs/analysis.md has no example test"
    example = tmp_path / blocks[0].splitlines()[0][2:]
    example.write_text(blocks[0])
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(example)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    assert re.search(r"\b2 passed\b", res.stdout), res.stdout
