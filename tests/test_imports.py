"""Each command imports only what it uses (issue 22): a light command never pays for numba,
Rerun, pandas or pyarrow. Each case runs the real command in a fresh interpreter and lists
the heavy modules left in ``sys.modules``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

HEAVY = ("numba", "rerun", "pandas", "pyarrow", "matplotlib", "dask", "foxglove")

_PROBE = f"""
import json, sys
from corraoi.cli import main
try:
    main(sys.argv[2:])
except SystemExit as exc:
    code = exc.code
else:
    code = 0
also = tuple(filter(None, sys.argv[1].split(",")))
heavy = sorted(m for m in {HEAVY!r} + also if m in sys.modules)
print("\\nIMPORTS " + json.dumps({{"code": code, "heavy": heavy}}))
"""
#: not heavy, but a command that runs no kernel has no use for them (15-25 ms each)
ENGINE = ("corraoi.engine.kernels", "importlib.metadata")


def _heavy(args: list[str], cwd: Path, also: tuple[str, ...] = ()) -> list[str]:
    """The modules of HEAVY (and ``also``) that ``corraoi ARGS`` left imported."""
    proc = subprocess.run([sys.executable, "-c", _PROBE, ",".join(also), *args], cwd=cwd,
                          capture_output=True, text=True, env=dict(os.environ),
                          timeout=300)  # fmt: skip
    line = [x for x in proc.stdout.splitlines() if x.startswith("IMPORTS ")]
    assert line, proc.stdout + proc.stderr
    out = json.loads(line[-1][len("IMPORTS ") :])
    assert out["code"] in (0, 1, None), proc.stderr  # diff exits 1 when the runs differ
    return list(out["heavy"])


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("imports")
    for pol in ("ucb", "cucb"):
        subprocess.run([sys.executable, "-m", "corraoi.cli", "record", "--policy", pol, "-T",
                        "300", "--no-rrd", "-o", f"{pol}.mcap"], cwd=where, check=True,
                       capture_output=True)  # fmt: skip
    return where


@pytest.mark.parametrize(
    "args",
    [
        ["--help"],
        ["info", "cucb.mcap"],
        ["diff", "ucb.mcap", "cucb.mcap"],
        ["instance", "list"],
        ["instance", "show", "I1"],
        ["policies"],
    ],
    ids=lambda a: " ".join(a),
)
def test_light_commands_import_nothing_heavy(logs: Path, args: list[str]):
    assert _heavy(args, logs) == []


@pytest.mark.parametrize("args", [["info", "cucb.mcap"], ["diff", "ucb.mcap", "cucb.mcap"]],
                         ids=lambda a: a[0])  # fmt: skip
def test_reading_a_log_imports_neither_the_kernels_nor_package_metadata(logs: Path, args):
    assert _heavy(args, logs, ENGINE) == []


def test_a_record_already_up_to_date_asks_no_package_its_version(logs: Path):
    # it compares the log's engine-sources hash with this corraoi's: versions() gave it, and
    # imported importlib.metadata (20 ms) and asked every package for its version
    assert _heavy(["record", "--policy", "cucb", "-T", "300", "--no-rrd", "-o", "cucb.mcap"],
                  logs, ("importlib.metadata",)) == []  # fmt: skip


def test_info_of_a_sweep_folder_imports_nothing_heavy(logs: Path):
    folder = logs / "sweep"
    subprocess.run([sys.executable, "-m", "corraoi.cli", "sweep", "-p", "ucb,cucb", "-T", "200",
                    "--runs", "5", "-o", str(folder), "--force"], cwd=logs, check=True,
                   capture_output=True)  # fmt: skip
    assert _heavy(["info", str(folder)], logs) == []


def test_export_to_csv_leaves_numba_rerun_and_pandas_out(logs: Path):
    assert _heavy(["export", "cucb.mcap", "-o", "cucb.csv", "--force"], logs) == ["pyarrow"]


def test_record_without_rrd_never_imports_rerun(logs: Path):
    args = ["record", "--policy", "ucb", "-T", "20", "--no-rrd", "-o", "n.mcap", "--force"]
    assert _heavy(args, logs) == ["numba"]


def test_record_with_rrd_leaves_rerun_to_its_worker_and_never_imports_pandas(logs: Path):
    """The .rrd is written by a forked worker (its own imports: test_rerun_worker.py)."""
    args = ["record", "--policy", "ucb", "-T", "20", "-o", "r.mcap", "--force"]
    assert _heavy(args, logs) == ["numba"]


@pytest.mark.parametrize(
    "args",
    [["replay", "cucb.mcap", "-o", "r.rrd", "--force"],
     ["compare", "ucb.mcap", "cucb.mcap", "-o", "c.rrd", "--force"]],
    ids=["replay", "compare"],
)  # fmt: skip
def test_replay_and_compare_need_rerun_only(logs: Path, args: list[str]):
    assert _heavy(args, logs) == ["pyarrow", "rerun"]
