"""The conformance check in named pieces (issue 23): one test per check with readable ids,
and a policy that breaks one rule fails that check and only that one."""

from __future__ import annotations

from pathlib import Path

import pytest

from corraoi.testing import CHECKS, parametrize_with_checks, policy_cases

EPS = str(Path(__file__).parent / "plugins" / "eps_greedy.py") + ":EpsilonGreedy"


@parametrize_with_checks(["aoi-aware-cucb", EPS], arms=(2, 5), horizon=120)
def test_policies_pass_every_check(case, check, tmp_path):  # type: ignore[no-untyped-def]
    check(case, tmp_path)


def test_the_ids_name_the_policy_the_arms_and_the_check():
    mark = parametrize_with_checks(["cucb"], arms=(3,), horizon=20)
    ids = mark.kwargs["ids"]
    assert ids == [f"cucb-K3-{c.__name__.removeprefix('check_')}" for c in CHECKS]
    assert "cucb-K3-runs_use_their_own_streams" in ids and len(ids) == 6


def test_a_batch_mixing_policy_fails_only_the_own_stream_check(tmp_path: Path):
    plugin = tmp_path / "mixer.py"
    plugin.write_text(
        "import numpy as np\n"
        "from corraoi.policies import Policy\n"
        "class Mixer(Policy):\n"
        "    name = 'mixer'\n"
        "    def select(self, t, state):\n"
        "        return np.full(state.runs, int(np.random.default_rng(t + state.runs)"
        ".integers(state.arms)))\n"
    )
    (case,) = policy_cases(f"{plugin}:Mixer", arms=(3,), horizon=60)
    failed = []
    for check in CHECKS:
        try:
            check(case, tmp_path)
        except AssertionError as exc:
            failed.append((check.__name__, str(exc)))
    assert [name for name, _ in failed] == ["check_runs_use_their_own_streams"]
    assert "mixer.py:Mixer (K=3): run 3 of a batch differs" in failed[0][1]


def test_an_arm_out_of_range_is_refused_by_the_engine_with_its_slot(tmp_path: Path):
    """The engine stops a plain-Python policy's bad arm before any check sees it."""
    from corraoi.errors import PolicyRuntimeError

    plugin = tmp_path / "wild.py"
    plugin.write_text(
        "import numpy as np\n"
        "from corraoi.policies import Policy\n"
        "class Wild(Policy):\n"
        "    name = 'wild'\n"
        "    def select(self, t, state):\n"
        "        return np.full(state.runs, state.arms)\n"
    )
    (case,) = policy_cases(f"{plugin}:Wild", arms=(2,), horizon=10)
    with pytest.raises(PolicyRuntimeError, match=r"policy wild, slot 1: select returned arm 2 "
                       r"for run 0 \(seed \d+\); expected 0\.\.1"):  # fmt: skip
        CHECKS[0](case, tmp_path)
