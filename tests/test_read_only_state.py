"""A plain-Python policy sees read-only state (issue 45, item 3): a write into any field of
``RunState`` raises at once and ends the run with one PolicyRuntimeError naming the policy,
the field and the slot; the log is left at its ``.partial`` name, marked failed, never
complete."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import corraoi
from corraoi.errors import PolicyRuntimeError
from corraoi.policies import Policy
from corraoi.policies.api import RunState
from corraoi.recorder.slotlog.reader import open_log

#: A write into each field, as a policy would make it by mistake.
WRITES = {
    "t": "state.t = 0",
    "runs": "state.runs = 5",
    "arms": "state.arms = 2",
    "seeds": "state.seeds[0] = 99",
    "pulls": "state.pulls[:] = 0",
    "successes": "state.successes[0, 1] += 1",
    "mu_hat": "state.mu_hat[...] = 1",
    "aoi": "state.aoi += 1",
    "rng": "state.rng = None",
    "source": "state.source = 2",
    "sources": "state.sources = 3",
    "collided": "state.collided[0] = True",
}


def _writer(field: str, where: str, statement: str) -> type[Policy]:
    source = (
        "import numpy as np\n"
        "def act(state):\n"
        f"    {statement}\n"
        "def select(self, t, state):\n"
        f"    if {where == 'select'} and t == 3:\n"
        "        act(state)\n"
        "    return np.full(state.runs, (t - 1) % state.arms)\n"
        "def update(self, t, arms, rewards, state):\n"
        f"    if {where == 'update'} and t == 4:\n"
        "        act(state)\n"
    )
    ns: dict = {}
    exec(compile(source, f"<writer {field}>", "exec"), ns)  # no source: the field by memory
    return type(f"Writes_{field}", (Policy,), {"name": f"writes-{field}", "select": ns["select"],
                                               "update": ns["update"]})  # fmt: skip


def test_every_field_of_run_state_is_covered():
    assert set(WRITES) == set(RunState.FIELDS)


@pytest.mark.parametrize("field", list(WRITES))
def test_a_write_into_the_state_ends_the_run_failed(tmp_path: Path, field: str):
    path = tmp_path / "w.mcap"
    with pytest.raises(PolicyRuntimeError) as info:
        corraoi.record(_writer(field, "select", WRITES[field]), "I1", horizon=50, path=path,
                       rrd=False)  # fmt: skip
    text = str(info.value)
    verb = "set" if field in ("t", "runs", "arms", "rng", "source", "sources") else "wrote into"
    assert text.startswith(f"policy writes-{field}, slot 3: select {verb} state.{field}, "
                           "which is read-only"), text  # fmt: skip
    assert "\n" not in text and text.endswith("marked failed")
    assert not path.exists()  # no complete log
    partial = Path(f"{path}.partial")
    log = open_log(partial, verify=False)
    assert log.status == "failed" and log.read_all().t.tolist() == [1, 2]


@pytest.mark.parametrize("field", ["pulls", "mu_hat", "t"])
def test_a_write_in_update_names_update_and_its_slot(tmp_path: Path, field: str):
    with pytest.raises(PolicyRuntimeError, match=rf"slot 4: update (set|wrote into) "
                       rf"state\.{field}, which is read-only"):  # fmt: skip
        corraoi.record(_writer(field, "update", WRITES[field]), "I1", horizon=50,
                       path=tmp_path / "u.mcap", rrd=False)  # fmt: skip
    assert open_log(tmp_path / "u.mcap.partial", verify=False).status == "failed"


@pytest.mark.parametrize(
    ("statement", "field"),
    [
        ("m = state.mu_hat\n    m[0, 0] = 0.5", "mu_hat"),
        ("np.copyto(state.pulls, 0)", "pulls"),
        ("np.add(state.aoi, 1, out=state.aoi)", "aoi"),
        ("state.successes.fill(0)", "successes"),
        ("np.put(state.mu_hat, [0], 1.0)", "mu_hat"),
    ],
    ids=["alias", "copyto", "ufunc-out", "fill", "np.put"],
)
def test_every_way_of_writing_names_the_field(tmp_path: Path, statement: str, field: str):
    path = tmp_path / "policy_file.py"
    path.write_text(
        "import numpy as np\nfrom corraoi.policies import Policy\n"
        "class W(Policy):\n    name = 'w'\n"
        "    def select(self, t, state):\n        if t == 3:\n"
        f"            {statement.replace(chr(10), chr(10) + '        ')}\n"
        "        return np.zeros(state.runs, dtype=np.int64)\n"
    )
    with pytest.raises(PolicyRuntimeError, match=rf"policy w, slot 3: select wrote into "
                       rf"state\.{field}, which is read-only"):  # fmt: skip
        corraoi.record(f"{path}:W", "I1", horizon=20, path=tmp_path / "w.mcap", rrd=False)


def test_views_cannot_be_made_writeable_and_follow_the_run(tmp_path: Path):
    seen: dict = {}

    class Keeper(Policy):
        name = "keeper"

        def select(self, t, state):
            if t == 1:
                seen["pulls"] = state.pulls  # kept: the engine's counts, read-only
                with pytest.raises(ValueError):
                    state.pulls.flags.writeable = True
            return np.full(state.runs, (t - 1) % state.arms)

        def update(self, t, arms, rewards, state):
            assert not arms.flags.writeable and not rewards.flags.writeable
            seen.setdefault("rewards", []).append(rewards)

    run = corraoi.record(Keeper, "I1", horizon=40, path=tmp_path / "k.mcap", rrd=False)
    assert seen["pulls"].tolist() == [[10, 10, 10, 10]]
    # each slot's rewards are its own array: a kept one is not overwritten by the next slot
    assert [int(r[0]) for r in seen["rewards"]] == run.slots.success.astype(int).tolist()
