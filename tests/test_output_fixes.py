"""What tripped a first hour (issue 32): the sweep table's best-arm column, ``wall s`` and the
kernel compile, the ``wrote`` line, ``T <= t0`` explained, ``instance show`` with long arm
names, and a warning for a --param that changes more than the policy it was meant for."""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from pathlib import Path

from click.testing import CliRunner

from corraoi.cli import main


def _cli(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


def test_the_best_arm_column_says_it_is_a_share():
    res = CliRunner().invoke(main, ["sweep", "-p", "ucb", "-n", "3", "-T", "200"])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("policy"))
    assert "best-arm" in lines[head] and "best arm" not in lines[head]
    under = lines[head + 1]
    col = lines[head].index("best-arm") + len("best-arm")
    assert under[col - len("share") : col] == "share"  # right under its header
    share = float(lines[head + 2].split()[4])
    data = json.loads(CliRunner().invoke(main, ["sweep", "-p", "ucb", "-n", "3", "-T", "200",
                                                "--json"]).stdout)  # fmt: skip
    assert share == round(data["policies"]["ucb"]["best_arm_share"], 3)


def test_wall_s_leaves_the_kernel_compile_out(tmp_path: Path):
    tag = uuid.uuid4().hex[:8]  # new code: its kernel is compiled now, first use
    (tmp_path / "fresh.py").write_text(f'''
from numba import njit
from corraoi.policies import CompiledPolicy

@njit(cache=True)
def fresh_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    for k in range(K):
        vals[k] = muhat[k] + 1.0 / (1.0 + npull[k])  # {tag}

class Fresh(CompiledPolicy):
    name = "fresh"
    score = fresh_score
''')
    res = _cli("sweep", "-p", "fresh.py:Fresh", "-n", 2, "-T", 100, "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "compiling the engine for fresh" in res.stderr  # it did compile (seconds)
    summary = json.loads(res.stdout)
    assert summary["policies"]["fresh"]["wall_s"] < 0.5 < summary["wall_s"]


def test_the_wrote_line_names_what_was_written(tmp_path: Path):
    res = CliRunner().invoke(main, ["sweep", "-p", "ucb", "-n", "4", "-T", "100", "--chunk",
                                    "2", "-o", str(tmp_path / "sw")])  # fmt: skip
    assert res.exit_code == 0, res.output
    wrote = [ln for ln in res.output.splitlines() if ln.startswith("wrote ")]
    files = "manifest.json, results.parquet, sweep.mcap, sweep.rrd, summary.json, summary.md"
    assert wrote[0].startswith(f"wrote {tmp_path / 'sw'}/: {files}")
    assert wrote[0].endswith("(2 chunks run)")
    res = CliRunner().invoke(main, ["sweep", "-i", "I1,I2", "-p", "ucb", "-n", "4", "-T", "100",
                                    "-o", str(tmp_path / "two")])  # fmt: skip
    wrote = [ln for ln in res.output.splitlines() if ln.startswith("wrote ")]
    assert wrote[0].startswith(f"wrote {tmp_path / 'two'}/: manifest.json, results.parquet, "
                               "I1/, I2/, each group folder with sweep.mcap, sweep.rrd, "
                               "summary.json, summary.md")  # fmt: skip
    assert wrote[0].endswith("(2 chunks run)") and ": ." not in wrote[0]


def test_a_bound_below_its_threshold_says_what_it_is():
    res = CliRunner().invoke(main, ["instance", "show", "I1", "-T", "10000"])
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.splitlines() if "Theorem 2 (CUCB)" in ln)
    assert "T <= t0 = 152792: the theorem holds from its threshold t0 on" in line
    assert "below it, the linear bound (1/mu_min - 1/mu*) T" in line


def test_instance_show_keeps_its_columns_with_long_arm_names(tmp_path: Path):
    inst = {"name": "long", "p": [0.5, 0.5], "Y": [[1, 0], [0, 1]],
            "arms": ["a-channel-name-of-thirty-chars", "b"]}  # fmt: skip
    (tmp_path / "long.json").write_text(json.dumps(inst))
    res = CliRunner().invoke(main, ["instance", "show", str(tmp_path / "long.json")])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.lstrip().startswith("arm "))
    header, rows = lines[head], lines[head + 1 : head + 3]
    for col in ("name", "Y(x)", "mu", "gap", "phi", "p-gap"):  # right-aligned columns
        end = header.index(f" {col} ") + 1 + len(col)
        for row in rows:
            assert row[end - 1] != " " and row[end] == " ", (col, header, row)
    assert rows[0].split()[1] == "a-channel-name-of-thirty-chars"


def test_an_unscoped_param_that_changes_two_policies_is_warned_and_a_scoped_one_is_not():
    res = CliRunner().invoke(main, ["sweep", "-p", "ts,cucb,aoi-aware-cucb", "--param", "c=3",
                                    "-n", "2", "-T", "30"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert ("corraoi: warning: --param c applies to cucb, aoi-aware-cucb; to set it for one of "
            "them, write --param POLICY.c=... (e.g. --param aoi-aware-cucb.c=...)") in res.output
    res = CliRunner().invoke(main, ["sweep", "-p", "cucb,aoi-aware-cucb", "--param",
                                    "aoi-aware-cucb.c=3,4", "-n", "2", "-T", "30", "--json"])
    assert res.exit_code == 0 and "warning" not in res.output, res.output
    data = json.loads(res.stdout)
    assert sorted(data["policies"]) == ["aoi-aware-cucb(c=3)", "aoi-aware-cucb(c=4)", "cucb"]
