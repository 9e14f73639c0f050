"""The command printed to open a recording: runnable as printed."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from corraoi.recorder.live import viewers as live


def test_on_path_it_is_the_plain_name(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    exe = tmp_path / "bin" / "rerun"
    exe.parent.mkdir()
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    monkeypatch.setattr(live, "rerun_executable", lambda: str(exe))
    monkeypatch.setenv("PATH", f"{exe.parent}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.chdir(tmp_path)
    assert live.view_command(["runs/a b.rrd"]) == "rerun 'runs/a b.rrd'"


def test_off_path_it_is_a_path_that_exists(monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    exe = tmp_path / "venv" / "bin" / "rerun"
    exe.parent.mkdir(parents=True)
    exe.write_text("#!/bin/sh\n")
    monkeypatch.setattr(live, "rerun_executable", lambda: str(exe))
    monkeypatch.setenv("PATH", "/nonexistent")
    monkeypatch.chdir(tmp_path)
    cmd = live.view_command(["x.rrd"])
    assert cmd == "venv/bin/rerun x.rrd" and (tmp_path / cmd.split()[0]).exists()
    monkeypatch.chdir(tmp_path / "venv")
    assert live.view_command(["x.rrd"]) == "bin/rerun x.rrd"
