"""Instances: built-ins, the community text format, JSON/TOML, and every malformed case."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from corraoi.errors import InstanceError
from corraoi.model.instance import (
    Instance,
    format_text_instance,
    load_instance,
    parse_text_instance,
)


def test_builtins_exact():
    i1 = load_instance("I1")
    assert i1.p.tolist() == [0.2, 0.3, 0.3, 0.2]
    assert i1.Y.tolist() == [[1, 0, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [0, 0, 0, 1]]
    i2 = load_instance("i2")  # case-insensitive
    assert i2.p.tolist() == [0.1, 0.1, 0.5, 0.3]
    assert i2.Y.tolist() == [[1, 0, 0, 0], [1, 1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]]
    assert i1.arm_names == ("1", "2", "3", "4")


def test_text_format_round_trip(tmp_path: Path):
    path = tmp_path / "mine.txt"
    path.write_text("# a comment\n0.25 0.75\n1 0\n\n0 1   # arm 2\n1 1\n")
    inst = load_instance(path)
    assert inst.name == "mine"
    assert inst.K == 3 and inst.n_states == 2
    np.testing.assert_allclose(inst.mu, [0.25, 0.75, 1.0])
    again = parse_text_instance(format_text_instance(inst))
    assert np.array_equal(again.p, inst.p) and np.array_equal(again.Y, inst.Y)


def test_json_and_toml_with_names(tmp_path: Path):
    data = {
        "name": "two",
        "p": [0.5, 0.5],
        "Y": [[1, 0], [0, 1]],
        "arms": ["los", "relay"],
        "states": ["clear", "rain"],
    }
    jp = tmp_path / "two.json"
    jp.write_text(json.dumps(data))
    tp = tmp_path / "two.toml"
    tp.write_text(
        'name = "two"\np = [0.5, 0.5]\nY = [[1, 0], [0, 1]]\n'
        'arms = ["los", "relay"]\nstates = ["clear", "rain"]\n'
    )
    a, b = load_instance(jp), load_instance(tp)
    assert a == b
    assert a.arm_names == ("los", "relay") and a.state_names == ("clear", "rain")
    assert Instance.from_dict(a.to_dict()) == a


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("", "empty instance file"),
        ("# only a comment\n", "empty instance file"),
        ("-0.1 1.1\n1 0\n0 1\n", ":1: probability '-0.1' must be >= 0"),
        ("0.3 0.3\n1 0\n0 1\n", ":1: probabilities sum to 0.6"),
        ("0.5 abc\n1 0\n0 1\n", ":1: probability 'abc' is not a number"),
        ("0.5 0.5\n1 2\n0 1\n", ":2: reward '2' is not 0 or 1"),
        ("0.5 0.5\n1 0\n0 1 1\n", ":3: 3 rewards, expected 2"),
        ("0.5 0.5\n1 0\n", "at least 2 arms"),
    ],
)
def test_malformed_text_names_file_and_line(tmp_path: Path, text: str, needle: str):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(InstanceError) as info:
        load_instance(path)
    msg = str(info.value)
    assert str(path) in msg
    assert needle in msg
    assert "\n" not in msg


def test_missing_file_and_directory(tmp_path: Path):
    with pytest.raises(InstanceError, match="no such instance file"):
        load_instance(tmp_path / "nope.txt")
    with pytest.raises(InstanceError, match="is a directory"):
        load_instance(tmp_path)


def test_bad_json(tmp_path: Path):
    path = tmp_path / "x.json"
    path.write_text('{"p": [0.5, 0.5], "Y": [[1, 0], [0, 3]]}')
    with pytest.raises(InstanceError, match="Y row 2: reward 3 is not 0 or 1"):
        load_instance(path)
    path.write_text("{not json")
    with pytest.raises(InstanceError, match=r"x.json:1: invalid JSON"):
        load_instance(path)


def test_array_validation():
    with pytest.raises(InstanceError, match="sum to 1"):
        Instance("x", np.array([0.5, 0.6]), np.array([[1, 0], [0, 1]]))
    with pytest.raises(InstanceError, match="at least 2 arms"):
        Instance("x", np.array([0.5, 0.5]), np.array([[1, 0]]))
    # within the 1e-9 tolerance is accepted
    Instance("x", np.array([0.5, 0.5 + 5e-10]), np.array([[1, 0], [0, 1]]))


def test_an_instance_name_is_one_name_however_its_letters_are_composed():
    import unicodedata

    nfd = unicodedata.normalize("NFD", "Café-Zürich")
    assert nfd != "Café-Zürich"
    a = Instance(nfd, [0.5, 0.5], [[1, 0], [0, 1]])
    b = Instance("Café-Zürich", [0.5, 0.5], [[1, 0], [0, 1]])
    assert a.name == "Café-Zürich"
    assert a == b and hash(a) == hash(b)
