"""Instance files are data with limits: special files, sizes, nesting, names, dimensions."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.errors import InstanceError
from corraoi.model.instance import MAX_ARMS, MAX_FILE_BYTES, Instance, load_instance


def one_line(*args: object) -> str:
    res = CliRunner().invoke(main, ["instance", "show", *[str(a) for a in args]])
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert res.output.count("\n") == 1
    return res.output


def test_a_fifo_is_refused_at_once(tmp_path: Path):
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)  # nobody writes: reading it would block forever
    assert "not a regular file" in one_line(fifo)


def test_an_endless_device_is_refused_at_once():
    assert "not a regular file" in one_line("/dev/zero")


def test_a_file_over_the_size_limit_is_refused_before_reading(tmp_path: Path):
    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(MAX_FILE_BYTES + 1)  # sparse: no memory, no disk
    assert f"larger than the limit of {MAX_FILE_BYTES} bytes" in one_line(big)


@pytest.mark.parametrize("suffix", [".json", ".toml"])
def test_deep_nesting_is_one_line(tmp_path: Path, suffix: str):
    f = tmp_path / f"deep{suffix}"
    if suffix == ".json":
        f.write_text("[" * 50_000 + "]" * 50_000)
    else:
        f.write_text("p = " + "[" * 50_000 + "]" * 50_000 + "\n")
    assert "nested" in one_line(f)
    f.write_text(json.dumps({"p": [0.5, 0.5], "Y": [[1, 0], [0, 1]], "arms": [[[[[[[[["x"]]]]]]]]]})
                 if suffix == ".json" else 'p = [0.5, 0.5]\nY = [[1, 0], [0, 1]]\n'
                 'arms = [[[[[[[[["x"]]]]]]]]]\n')  # fmt: skip
    assert "nested deeper than 8 levels" in one_line(f)


def test_names_are_data():
    # any text is a name: output paths sanitise it and terminals get it escaped
    # (tests/test_adversarial_cli.py); the instance keeps it as it is
    p, Y = np.array([0.5, 0.5]), np.array([[1, 0], [0, 1]])
    for name in ("../../x", "a\x1b[31mred", "x" * 500):
        assert Instance(name, p, Y).name == name


def test_dimension_limits(tmp_path: Path):
    f = tmp_path / "wide.json"
    K = MAX_ARMS + 1
    f.write_text(json.dumps({"p": [1.0], "Y": [[1]] * K}))
    with pytest.raises(InstanceError, match=f"{K} arms and 1 states; at most {MAX_ARMS} arms"):
        load_instance(f)


def test_a_1024_state_transition_matrix_fits(tmp_path: Path):
    n = 1024
    P = np.full((n, n), 1.0 / n)
    f = tmp_path / "big-chain.json"
    f.write_text(json.dumps({"transition": P.tolist(), "Y": [[1] * n, [0] * (n - 1) + [1]]}))
    inst = load_instance(f)
    assert inst.n_states == n and inst.transition is not None
