"""docs/extending.md runs as shown: its plug-in files, its commands and its test example."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "extending.md"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(), flags=re.S)


def test_first_python_block_is_the_eps_greedy_plugin_file():
    first = blocks("python")[0]
    assert first.splitlines()[0] == "# eps_greedy.py"
    assert "class EpsilonGreedy(Policy)" in first and "Param(0.1" in first


def test_the_many_sources_example_is_the_tested_plugin_byte_for_byte():
    shown = next(b for b in blocks("python") if b.startswith("# selfish_ucb.py\n"))
    assert shown == (ROOT / "tests" / "plugins" / "selfish_ucb.py").read_text()


@pytest.mark.slow
def test_every_command_runs_as_shown(tmp_path: Path):
    for code in blocks("python"):
        head = code.splitlines()[0]
        if re.fullmatch(r"# \w+\.py", head):
            (tmp_path / head[2:]).write_text(code)
    site = tmp_path / "site"
    bindir = Path(sys.executable).parent
    env = {
        **os.environ,
        "PATH": f"{bindir}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": f"{site}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
    }
    for block in blocks("bash"):
        for line in block.splitlines():
            command = line.split("  #")[0].strip()
            if not command:
                continue
            if command.startswith("pip install"):
                # the same install, into a folder of the test's (not the test environment),
                # from a copy (a build leaves build/ and *.egg-info beside the sources)
                package = tmp_path / "pkg"
                shutil.copytree(ROOT / command.split()[-1], package)
                command = f"{sys.executable} -m pip install -q --no-deps --target {site} {package}"
            res = subprocess.run(command, shell=True, cwd=tmp_path, env=env,
                                 capture_output=True, text=True, timeout=300)  # fmt: skip
            assert res.returncode == 0, (command, res.stdout[-2000:], res.stderr[-2000:])
            assert "Traceback" not in res.stderr, (command, res.stderr)
            if command.startswith("corraoi policies"):
                assert re.search(r"^eps-greedy\s", res.stdout, flags=re.M), res.stdout
    assert (tmp_path / "ep.mcap").exists() and (tmp_path / "cucb-on-trace.mcap").exists()
    assert (tmp_path / "selfish.mcap").exists()


def test_the_doc_test_example_passes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    example = next(b for b in blocks("python") if "check_policy" in b)
    (tmp_path / "eps_greedy.py").write_text(blocks("python")[0])
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {}
    exec(compile(example, "extending.md", "exec"), namespace)
    test = namespace["test_my_policy_conforms"]
    assert callable(test)
    test(tmp_path)


def test_the_doc_parametrized_example_runs_one_test_per_check(tmp_path: Path):
    example = next(b for b in blocks("python") if "parametrize_with_checks" in b)
    (tmp_path / "eps_greedy.py").write_text(blocks("python")[0])
    (tmp_path / "test_mine.py").write_text(example)
    res = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider",
                          "-p", "no:xdist", "test_mine.py", "-v"], cwd=tmp_path,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-2000:]
    assert "12 passed" in res.stdout  # 2 instances x 6 checks
    assert "test_my_policy[eps-greedy-K8-runs_use_their_own_streams] PASSED" in res.stdout


def test_the_register_example_runs_as_a_script(tmp_path: Path):
    example = next(b for b in blocks("python") if "@register" in b)
    (tmp_path / "rr.py").write_text(
        example + "\nfrom corraoi.testing import check_policy\n"
        "check_policy('round-robin', arms=(3,), horizon=30)\n"
    )
    res = subprocess.run([sys.executable, "rr.py"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=300)  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.splitlines() == ["__main__:RoundRobin"]
