"""The policy registry, name parsing and parameters."""

from __future__ import annotations

import pytest

from corraoi.errors import PolicyError
from corraoi.policies import (
    PolicySpec,
    builtins,
    make_policies,
    make_policy,
    paper_names,
    parse_param_assignments,
    parse_policy_names,
)

BASES = ["ucb", "ts", "ts-gauss", "cucb", "cts", "cts-gauss"]
PAPER = BASES + [f"aoi-aware-{b}" for b in BASES]


def test_the_paper_twelve_in_table_order():
    assert paper_names() == PAPER


def test_new_builtins_are_registered_but_not_in_all():
    names = set(builtins())
    for extra in ("q-ucb", "q-ts", "sw-ucb", "d-ts", "cq-ucb", "cq-ts", "aoi-aware-q-ucb",
                  "aoi-aware-sw-ucb", "aoi-aware-d-ts", "aoi-aware-cq-ts"):  # fmt: skip
        assert extra in names
        assert extra not in parse_policy_names(["all"])
    # drifting-channel policies have no correlated form (documented in their module)
    assert "csw-ucb" not in names and "cd-ts" not in names


def test_parse_forms():
    assert parse_policy_names(["cucb"]) == ["cucb"]
    assert parse_policy_names(["ucb,cts", "ucb", " TS "]) == ["ucb", "cts", "ts"]
    assert parse_policy_names(["all"]) == PAPER


def test_typo_suggests():
    with pytest.raises(PolicyError, match="did you mean cucb"):
        parse_policy_names(["cucv"])
    with pytest.raises(PolicyError, match="unknown policy 'zzz'"):
        make_policy("zzz")


def test_params_defaults_and_validation():
    assert make_policy("ucb").params == {"c": 2.0}
    assert make_policy("aoi-aware-cts-gauss").params == {"beta": 1.0}
    assert make_policy("ts").params == {}
    assert make_policy("sw-ucb").params == {"window": 500.0, "c": 2.0}
    assert make_policy("cucb", c=1.5).params["c"] == 1.5
    with pytest.raises(PolicyError, match=r"c=-1 must be in \(0, inf\)"):
        make_policy("ucb", c=-1)
    with pytest.raises(PolicyError, match=r"gamma=1.5 must be in \(0, 1\]"):
        make_policy("d-ts", gamma=1.5)
    with pytest.raises(PolicyError, match="window=2.5 must be a whole number"):
        make_policy("sw-ucb", window=2.5)
    with pytest.raises(PolicyError, match="unknown parameter 'gamma'"):
        make_policy("ucb", gamma=1.0)
    with pytest.raises(PolicyError, match="does not apply to ucb"):
        make_policies(["ucb"], beta=2.0)
    specs = make_policies(["ucb", "ts-gauss"], c=3.0, beta=0.5)
    assert specs[0].params == {"c": 3.0} and specs[1].params == {"beta": 0.5}


def test_a_param_declared_with_the_wrong_types_is_one_line():
    from corraoi.policies import Param

    with pytest.raises(PolicyError, match=r"Param high 'exploration': expected a number or "
                                          r"None \(Param\(default, help, low, high"):  # fmt: skip
        Param(0.1, 0, 1, "exploration")  # type: ignore[arg-type]
    with pytest.raises(PolicyError, match="Param help 0: expected a line of text"):
        Param(0.1, 0)  # type: ignore[arg-type]
    with pytest.raises(PolicyError, match="Param default '0.1': expected a number"):
        Param("0.1")  # type: ignore[arg-type]
    with pytest.raises(PolicyError, match="Param integer 'yes': expected True or False"):
        Param(1.0, "n", 0, 10, integer="yes")  # type: ignore[arg-type]
    assert Param(3, "k", 1, 10, integer=True).range_text() == "an integer in [1, 10]"


def test_param_assignments_go_to_every_policy_that_declares_them():
    specs = make_policies(["ucb", "sw-ucb", "ts"], parse_param_assignments(["c=1.5", "window=50"]))
    assert [s.params for s in specs] == [{"c": 1.5}, {"window": 50.0, "c": 1.5}, {}]
    with pytest.raises(PolicyError, match="parameter window does not apply to ucb, ts"):
        make_policies(["ucb", "ts"], {"window": 10.0})
    for bad, expected in (("c", "expected NAME=VALUE"), ("c=abc", "'abc' is not a number"),
                          ("=3", "expected NAME=VALUE")):  # fmt: skip
        with pytest.raises(PolicyError, match=expected):
            parse_param_assignments([bad])


def test_flags_and_theorems():
    cls = make_policy("aoi-aware-cts").resolve()
    assert cls.correlated and cls.aoi_aware and cls.theorem is None  # type: ignore[attr-defined]
    assert make_policy("cts").resolve().theorem == "cts"
    assert make_policy("cucb").resolve().theorem == "cucb"
    assert not make_policy("ts").resolve().correlated  # type: ignore[attr-defined]


def test_builtin_spec_logs_as_before_and_round_trips():
    spec = make_policy("cucb", c=1.5)
    assert spec.to_dict() == {"name": "cucb", "params": {"c": 1.5}}
    assert PolicySpec.from_dict(spec.to_dict()) == spec
    assert spec.builtin and spec.color == (44, 160, 44)
