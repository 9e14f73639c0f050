"""Every command the README shows runs as shown (issue 23), in one fresh directory, in the
order a reader meets them, and does what the README says it does.

The commands are read from the README itself: each ``corraoi ...`` in a code span or a code
block. A few cannot run here as written; :data:`NOT_RUN` says why, and the test fails when
the README shows a command that is neither run nor listed there (so a new one is not
forgotten)."""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow  # the README's commands, one after the other: about 40 s

#: Shown but not run here, and why.
NOT_RUN = {
    "corraoi record -p cucb -T 100000 --foxglove --pace 500":
        "a live Foxglove server paced at 500 slots/s for 200 s (tests/test_foxglove*.py)",
    "corraoi sweep ... --backend gpu": "needs a CUDA GPU (tests/test_gpu.py, emulated)",
    "corraoi sweep experiment.toml": "the README names no such file (docs/scaling.md has one)",
}
#: Forms that name a command only (its options come from the lines that run it).
NAMES_ONLY = {"corraoi export", "corraoi info", "corraoi record", "corraoi recover",
              "corraoi COMMAND --help", "corraoi info DIR",
              "corraoi record --from DIR --run worst|median|best|widest-gap|N",
              "corraoi figure DIR/sweep.mcap -o fig.png [--log-x] [--log-y] [--split]",
              "corraoi sweep --instance I1 --policy all --runs 200 --horizon 10000 [--seed S] "
              "[--json]"}  # fmt: skip


def readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    spans = re.findall(r"`(corraoi [^`]*)`", text)
    lines = [m.split("  ")[0].strip() for m in re.findall(r"^(corraoi .*)$", text, flags=re.M)]
    return list(dict.fromkeys(spans + lines))


def _run(args: str, cwd: Path, expect: int = 0) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    res = subprocess.run(["corraoi", *shlex.split(args)[1:]], cwd=cwd, env=env,
                         capture_output=True, text=True, timeout=600)  # fmt: skip
    assert res.returncode == expect, (args, res.returncode, res.stdout[-2000:], res.stderr[-2000:])
    assert "Traceback" not in res.stderr, (args, res.stderr)
    return res


@pytest.fixture(scope="module")
def ran(tmp_path_factory: pytest.TempPathFactory) -> dict[str, subprocess.CompletedProcess[str]]:
    """Run the README's commands in order in one directory; their outputs by command."""
    pytest.importorskip("pyarrow")
    pytest.importorskip("matplotlib")
    where = tmp_path_factory.mktemp("readme")
    shutil.copy(ROOT / "tests" / "plugins" / "eps_greedy.py", where / "eps_greedy.py")
    out: dict[str, subprocess.CompletedProcess[str]] = {}
    order = [
        ("corraoi record --policy cucb", 0),
        ("corraoi instance show I1", 0),
        ("corraoi record -p ucb,cucb -s 7", 0),
        ("corraoi compare runs/ucb-I1-s7.mcap runs/cucb-I1-s7.mcap", 0),
        ("corraoi diff runs/ucb-I1-s7.mcap runs/cucb-I1-s7.mcap", 1),
        ("corraoi replay runs/cucb-I1-s7.mcap -o replay.rrd", 0),
        ("corraoi sweep --policy all -o sweeps/I1", 0),
        ("corraoi record --from sweeps/I1 --run worst", 0),
        ("corraoi info sweeps/I1", 0),
        ("corraoi figure sweeps/I1/sweep.mcap -o fig.png --log-x", 0),
        ("corraoi sweep --instance I1 --policy all --runs 200 --horizon 10000 --json", 0),
        ("corraoi reproduce -o paper", 0),
        ("corraoi policies", 0),
        ("corraoi record --policy eps_greedy.py:EpsilonGreedy --param epsilon=0.05", 0),
        ("corraoi sweep -i I1,I2 -p ucb,sw-ucb --param window=100,1000 -o grid", 0),
        ("corraoi record -p rhorand-cucb --sources 3", 0),
        ("corraoi sweep -p rhorand-ucb,mctopm-ucb --sources 1,2,3,4 -o sources", 0),
        ("corraoi reproduce decentralized -o dec", 0),
        ("corraoi --help", 0),
        ("corraoi record --help", 0),
    ]
    for command, code in order:
        out[command] = _run(command, where, code)
    # `corraoi info` / `recover` of a log whose writer was killed: make one first
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    proc = subprocess.Popen(["corraoi", "record", "-T", "100000000", "-o", "runs/long.mcap",
                             "--no-rrd"], cwd=where, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)  # fmt: skip
    partial = where / "runs" / "long.mcap.partial"
    deadline = time.monotonic() + 120
    while not (partial.exists() and partial.stat().st_size > 200_000):
        assert time.monotonic() < deadline and proc.poll() is None, "record never got going"
        time.sleep(0.1)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    for command in ("corraoi info runs/long.mcap.partial",
                    "corraoi recover runs/long.mcap.partial"):
        out[command] = _run(command, where, 0)
    out["where"] = where  # type: ignore[assignment]
    return out


def test_every_command_the_readme_shows_is_run_or_said_why_not(ran):
    run_here = {c.split(" --log-x")[0] for c in ran if c != "where"}
    missing = [c for c in readme_commands()
               if c not in ran and c not in NOT_RUN and c not in NAMES_ONLY
               and c not in run_here]  # fmt: skip
    assert missing == []


def test_the_commands_do_what_the_readme_says(ran):
    where: Path = ran["where"]
    first = ran["corraoi record --policy cucb"].stdout
    assert "cucb (c=2) on I1, seed 0: 10000 of 10000 slots" in first
    assert (where / "runs/cucb-I1-s0.mcap").is_file() and (where / "runs/cucb-I1-s0.rrd").is_file()
    assert "open in the Rerun viewer:  rerun runs/cucb-I1-s0.rrd" in first
    assert "competitive sub-optimal arms: 3   C = 1" in ran["corraoi instance show I1"].stdout
    table = ran["corraoi compare runs/ucb-I1-s7.mcap runs/cucb-I1-s7.mcap"].stdout
    assert re.search(r"policy\s+ucb\s+cucb", table) and "pathwise regret" in table
    diff = ran["corraoi diff runs/ucb-I1-s7.mcap runs/cucb-I1-s7.mcap"].stdout
    assert re.search(r"^  x\s+-\s+0 of 10000", diff, flags=re.M)  # one hidden path
    assert re.search(r"^  arm\s+\d+\s+[1-9]\d* of 10000", diff, flags=re.M)  # where they diverge
    assert (where / "replay.rrd").is_file() and (where / "fig.png").stat().st_size > 10_000
    summary = json.loads((where / "sweeps" / "I1" / "summary.json").read_text())
    worst = summary["notable"]["cells"]["cucb"]["worst"]
    assert (where / "runs" / f"I1-I1-cucb-run{worst['run']}-worst.mcap").is_file()
    assert f"run {worst['run']}" in ran["corraoi info sweeps/I1"].stdout
    js = json.loads(ran["corraoi sweep --instance I1 --policy all --runs 200 --horizon 10000 "
                        "--json"].stdout)  # fmt: skip
    assert len(js["policies"]) == 12 and js["runs"] == 200
    assert (where / "paper" / "I2" / "summary.json").is_file()
    listing = ran["corraoi policies"].stdout
    assert all(re.search(rf"^{n}\s", listing, flags=re.M) for n in ("cucb", "q-ucb", "d-ts"))
    assert "eps-greedy (epsilon=0.05) on I1" in ran[
        "corraoi record --policy eps_greedy.py:EpsilonGreedy --param epsilon=0.05"].stdout
    assert (where / "grid" / "I2" / "summary.json").is_file()
    three = ran["corraoi record -p rhorand-cucb --sources 3"].stdout
    assert (where / "runs/rhorand-cucb-I1-m3-s0.mcap").is_file(), three
    assert re.search(r"3 sources: AoI regret at slot 10000: -?\d+ \(pathwise, summed; by "
                     r"source -?\d+, -?\d+, -?\d+\), \d+ collisions", three), three
    cells = json.loads((where / "sources" / "summary.json").read_text())["policies"]
    assert len(cells) == 8 and "mctopm-ucb(M=4)" in cells, list(cells)  # 2 policies x M 1..4
    assert (where / "dec" / "regret-vs-sources.png").is_file()
    assert "Start with:" in ran["corraoi --help"].stdout
    assert "--from SWEEP" in ran["corraoi record --help"].stdout
    assert "cut short" in ran["corraoi info runs/long.mcap.partial"].stdout
    assert (where / "runs" / "long.recovered.mcap").is_file()
