"""``theory.analyse`` runs once per instance object (issue 23): a recorded run asks for it
from the engine, the MCAP sink, the Rerun sink and the summary, and gets one value."""

from __future__ import annotations

import numpy as np
import pytest

import corraoi.model.theory as theory
from corraoi.engine.block import RunConfig
from corraoi.face.recording import record_run
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import make_policies


@pytest.fixture
def calls(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    seen: list[str] = []
    real = theory.compute_theory

    def counted(inst: Instance) -> theory.InstanceTheory:
        seen.append(inst.name)
        return real(inst)

    monkeypatch.setattr(theory, "compute_theory", counted)
    return seen


def test_a_recorded_run_analyses_its_instance_once(tmp_path, calls):
    config = RunConfig(load_instance("I2"), make_policies(("aoi-aware-cucb",), {})[0], 3, 2000)
    out = record_run(config, tmp_path / "a.mcap", rrd=tmp_path / "a.rrd")
    assert out.slots == 2000 and (tmp_path / "a.rrd").is_file()
    assert calls == ["I2"]


def test_the_kept_theory_is_the_computed_one_and_cannot_be_changed(calls):
    inst = load_instance("I1")
    kept = theory.analyse(inst)
    assert theory.analyse(inst) is kept and calls == ["I1"]
    fresh = theory.compute_theory(load_instance("I1"))
    for name in ("mu", "gaps", "phi", "pseudo_gap", "pseudo_rewards"):
        assert np.array_equal(getattr(kept, name), getattr(fresh, name))
    assert (kept.best_arm, kept.competitive) == (fresh.best_arm, fresh.competitive)
    with pytest.raises(ValueError, match="read-only"):
        kept.mu[0] = 1.0
    other = Instance("other", np.array([0.5, 0.5]), np.array([[1, 0], [0, 1]]))
    assert theory.analyse(other).best_arm == 0 and calls[-1] == "other"
