"""Many sources sharing the channels (issue 43): the run's configuration and block."""

from __future__ import annotations

import numpy as np
import pytest

from corraoi.engine.block import RunConfig, SlotBlock, SourcesBlock
from corraoi.engine.simulation import simulate_run
from corraoi.engine.slot_record import SHARED, record_for
from corraoi.errors import ConfigError
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy


@pytest.mark.parametrize("bad", [0, 5, -1, 2.0, "2", True, None])
def test_sources_outside_1_to_K_is_one_error_naming_it(bad):
    expected = r"sources .*expected an integer from 1 to the number of arms, 4"
    with pytest.raises(ConfigError, match=expected):
        RunConfig(load_instance("I1"), make_policy("ucb"), 0, 100, sources=bad)


def test_a_single_source_config_is_written_as_before_and_several_round_trip():
    one = RunConfig(load_instance("I1"), make_policy("ucb"), 3, 100)
    assert "sources" not in one.to_dict() and one.label == "ucb-I1-s3"
    three = RunConfig(load_instance("I1"), make_policy("ucb"), 3, 100, sources=3)
    assert three.to_dict()["sources"] == 3 and three.label == "ucb-I1-m3-s3"
    assert RunConfig.from_dict(three.to_dict()) == three
    assert RunConfig.from_dict(one.to_dict()).sources == 1


def test_a_single_sources_record_has_no_field_of_several_sources():
    assert [f.name for f in record_for(2) if f not in record_for(1)] == ["collided"]
    assert SHARED == ("t", "x")


def test_a_sources_block_joins_and_slices_source_by_source():
    inst = load_instance("I1")
    a, b = (SlotBlock.concat(list(simulate_run(inst, make_policy(p), 1, 300)))
            for p in ("ucb", "ts"))  # fmt: skip
    whole = SourcesBlock((a, b))
    assert whole.M == 2 and len(whole) == 300 and np.array_equal(whole.x, a.x)
    parts = [whole.slice(0, 100), whole.slice(100, None)]
    assert SourcesBlock.concat(parts).equals(whole)
    assert not SourcesBlock.concat(parts).equals(SourcesBlock((b, a)))
    with pytest.raises(ValueError, match="two sources or more"):
        SourcesBlock((a,))
