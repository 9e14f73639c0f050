"""The policy registry, name parsing and parameters."""

from __future__ import annotations

import pytest

from corraoi.errors import PolicyError
from corraoi.policies import POLICY_NAMES, make_policies, make_policy, parse_policy_names


def test_twelve_policies():
    assert len(POLICY_NAMES) == 12
    bases = ["ucb", "ts", "ts-gauss", "cucb", "cts", "cts-gauss"]
    assert set(POLICY_NAMES) == set(bases) | {f"aoi-aware-{b}" for b in bases}


def test_parse_forms():
    assert parse_policy_names(["cucb"]) == ["cucb"]
    assert parse_policy_names(["ucb,cts", "ucb", " TS "]) == ["ucb", "cts", "ts"]
    assert parse_policy_names(["all"]) == list(POLICY_NAMES)


def test_typo_suggests():
    with pytest.raises(PolicyError, match="did you mean cucb"):
        parse_policy_names(["cucv"])
    with pytest.raises(PolicyError, match="unknown policy 'zzz'"):
        make_policy("zzz")


def test_params_defaults_and_validation():
    assert make_policy("ucb").params == {"c": 2.0}
    assert make_policy("aoi-aware-cts-gauss").params == {"beta": 1.0}
    assert make_policy("ts").params == {}
    assert make_policy("cucb", c=1.5).c == 1.5
    with pytest.raises(PolicyError, match="c must be finite and > 0"):
        make_policy("ucb", c=-1)
    with pytest.raises(PolicyError, match="unknown policy parameter 'gamma'"):
        make_policy("ucb", gamma=1.0)
    with pytest.raises(PolicyError, match="does not apply to ucb"):
        make_policies(["ucb"], beta=2.0)
    specs = make_policies(["ucb", "ts-gauss"], c=3.0, beta=0.5)
    assert specs[0].params == {"c": 3.0} and specs[1].params == {"beta": 0.5}


def test_flags():
    p = make_policy("aoi-aware-cts")
    assert p.correlated and p.aoi_aware and p.base_name == "cts"
    assert not make_policy("ts").correlated
