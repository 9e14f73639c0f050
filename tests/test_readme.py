"""The README stays true: its pytest example runs and passes as written."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_readme_diff_example_passes(tmp_path: Path):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"^```python\n(.*?)^```$", text, flags=re.S | re.M)
    assert blocks, "README.md has no python example"
    example = tmp_path / "test_readme_example.py"
    example.write_text(blocks[0])
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    res = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(example)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    assert "2 passed" in res.stdout


def test_readme_first_block_runs_the_main_job_and_second_the_suite():
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"^```[a-z]*\n(.*?)^```$", text, flags=re.S | re.M)
    assert "pip install -e ." in blocks[0] and "corraoi record --policy cucb" in blocks[0]
    assert 'pip install -e ".[test]"' in blocks[1] and "pytest" in blocks[1]
    # .ci/run extracts exactly that second block
    res = subprocess.run(
        ["bash", "-c", "cd " + str(ROOT) + " && " + _ci_block_extractor()],
        capture_output=True, text=True,
    )  # fmt: skip
    assert res.stdout.strip() == blocks[1].strip()


def _ci_block_extractor() -> str:
    text = (ROOT / ".ci" / "run").read_text()
    start = text.index("block=$(")
    end = text.index("README.md)", start) + len("README.md)")
    return text[start:end] + '; printf "%s\\n" "$block"'
