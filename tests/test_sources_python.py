"""Plain-Python policies of many sources (issue 43, item 2): a ``Policy`` that declares
``multi_source = "own"`` runs one instance per source, each seeing its own state; the engine
keeps the model's bookkeeping (collisions, ages, the orthogonal oracle, regret) exactly as
the kernel of many sources does, and a bad choice is one line naming the source and slot."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import corraoi
from corraoi.engine.simulation import Simulation
from corraoi.engine.sources import SourcesSimulation, simulate_sources
from corraoi.errors import PolicyError, PolicyRuntimeError
from corraoi.model.instance import load_instance
from corraoi.policies import Policy, make_policy
from corraoi.recorder.slotlog.reader import open_log

ROOT = Path(__file__).resolve().parent.parent
SELFISH = f"{ROOT / 'tests' / 'plugins' / 'selfish_ucb.py'}:SelfishUCB"
#: the columns the engine computes from the choices (the model), per slot and source
MODEL = ["t", "source", "x", "arm", "success", "collided", "aoi", "oracle_aoi", "regret",
         *(f"pulls_{k}" for k in range(1, 5)), *(f"mu_hat_{k}" for k in range(1, 5))]  # fmt: skip


def _plays(name: str, arms: np.ndarray) -> type[Policy]:
    """A plain-Python policy of many sources whose source m plays ``arms[t - 1, m - 1]``
    (0-based) in every run."""

    def select(self, t, state):
        return np.full(state.runs, arms[t - 1, state.source - 1])

    return type("Plays", (Policy,), {"name": name, "multi_source": "own", "select": select})


def test_the_plain_python_tier_keeps_the_models_books_as_the_kernel_does(tmp_path: Path):
    # the same choices in both tiers: every column the model computes is the kernel's
    kernel = corraoi.record("rhorand-ucb", "I1", seed=5, horizon=600, sources=3,
                            path=tmp_path / "k.mcap", rrd=False)  # fmt: skip
    ks = kernel.slots.sort_values(["t", "source"]).reset_index(drop=True)
    arms = ks["arm"].to_numpy().reshape(600, 3) - 1  # logs number arms from 1
    assert ks["collided"].any() and len(np.unique(arms)) == 4  # collisions to keep books of
    py = corraoi.record(_plays("plays-rhorand", arms), "I1", seed=5, horizon=600, sources=3,
                        path=tmp_path / "p.mcap", rrd=False)  # fmt: skip
    ps = py.slots.sort_values(["t", "source"]).reset_index(drop=True)
    for col in MODEL:
        np.testing.assert_array_equal(ps[col].to_numpy(), ks[col].to_numpy(), err_msg=col)
    assert py.summary.regret_by_source == kernel.summary.regret_by_source
    assert py.summary.collisions == kernel.summary.collisions > 0
    assert py.summary.regret == kernel.summary.regret


def test_collisions_ages_and_the_oracle_on_hand_checked_slots(tmp_path: Path):
    # two sources both on arm 2 at slots 1-3 collide there (no delivery: ages 2, 3, 4, though
    # each learns the channel's state); then each on its oracle channel (source 1 the best,
    # source 2 the second best): it delivers when that channel is ON, as the oracle does
    inst = load_instance("I1")
    T = 12
    best = np.argsort(-inst.mu, kind="stable")[:2]
    arms = np.array([[1, 1]] * 3 + [list(best)] * (T - 3))
    run = corraoi.record(_plays("plays-hand", arms), inst, seed=0, horizon=T, sources=2,
                         path=tmp_path / "h.mcap", rrd=False)  # fmt: skip
    s = run.slots.sort_values(["source", "t"])
    for m in (1, 2):
        src = s[s["source"] == m]
        x = src["x"].to_numpy() - 1  # logs number states from 1
        assert src["collided"].tolist() == [True] * 3 + [False] * (T - 3)
        on = inst.Y[best[m - 1], x] == 1  # its oracle channel
        delivered = np.r_[[False] * 3, on[3:]]
        assert src["success"].tolist() == delivered.tolist()
        age = oracle = 1
        ages, oracles = [], []
        for t in range(T):  # the paper's recursion, by hand
            age = 1 if delivered[t] else age + 1
            oracle = 1 if on[t] else oracle + 1
            ages.append(age)
            oracles.append(oracle)
        assert src["aoi"].tolist() == ages and src["aoi"].iloc[:3].tolist() == [2, 3, 4]
        assert src["oracle_aoi"].tolist() == oracles
        assert src["regret"].tolist() == np.cumsum(np.subtract(ages, oracles)).tolist()
        assert src["pulls_2"].iloc[:3].tolist() == [1, 2, 3]  # it played arm 2, and lost
        sensed = inst.Y[1, x[:3]]  # what it learned of arm 2 though it collided
        assert src["mu_hat_2"].iloc[2] == pytest.approx(sensed.mean())
    assert run.summary.collisions == 6
    assert run.summary.regret == sum(run.summary.regret_by_source)


def test_one_source_of_an_own_policy_is_its_single_source_run():
    inst, spec = load_instance("I2"), make_policy(SELFISH)
    seeds = [3, 4, 11]
    one = Simulation(inst, spec, seeds, 500).advance(500)
    assert one is not None
    many = SourcesSimulation(inst, spec, seeds, 500, 1).advance(500)
    assert many is not None
    for r in range(len(seeds)):
        (solo,) = many[r]
        run = one.run(r)
        for f in ("x", "arm", "success", "aoi", "oracle_aoi", "regret", "pulls", "score"):
            np.testing.assert_array_equal(getattr(solo, f), getattr(run, f), err_msg=f)
        assert solo.collided is None


def test_each_source_sees_its_own_state_and_its_collisions(tmp_path: Path):
    seen: list[tuple] = []
    made: list[int] = []

    class Probe(Policy):
        name = "probe-sources"
        multi_source = "own"

        def reset(self, state):
            made.append(id(self))

        def select(self, t, state):
            seen.append(("select", t, state.source, state.sources, id(self),
                         state.pulls.sum(axis=1).copy(), state.collided.copy(),
                         state.rng.random()))  # fmt: skip
            return state.rng.integers(state.arms)

        def update(self, t, arms, rewards, state):
            seen.append(("update", t, state.source, state.collided.copy(), arms.copy(),
                         rewards.copy()))  # fmt: skip

    run = corraoi.record(Probe, "I1", seed=2, horizon=40, sources=3, path=tmp_path / "p.mcap",
                         rrd=False)  # fmt: skip
    slots = run.slots.set_index(["t", "source"])
    assert len(set(made)) == 3  # an instance per source
    selects = [e for e in seen if e[0] == "select"]
    updates = [e for e in seen if e[0] == "update"]
    assert [(e[1], e[2]) for e in selects] == [(t, m) for t in range(1, 41) for m in (1, 2, 3)]
    assert {e[3] for e in selects} == {3}
    by_source = {m: {e[4] for e in selects if e[2] == m} for m in (1, 2, 3)}
    assert all(len(v) == 1 for v in by_source.values())  # one instance a source, throughout
    assert len(set.union(*by_source.values())) == 3
    for _, t, m, _, _, pulls, collided, _ in selects:
        assert (pulls == t - 1).all()  # its own plays only
        before = bool(slots.loc[(t - 1, m), "collided"]) if t > 1 else False
        assert collided.tolist() == [before]
    for _, t, m, collided, arms, rewards in updates:
        row = slots.loc[(t, m)]
        assert collided.tolist() == [bool(row["collided"])]
        assert arms.tolist() == [row["arm"] - 1]
        # the reward is the channel's state (sensed), delivered only without a collision
        on = load_instance("I1").Y[row["arm"] - 1, row["x"] - 1] == 1
        assert bool(rewards[0]) == on and bool(row["success"]) == (on and not row["collided"])
    # each source draws from its own stream
    draws = {m: [e[7] for e in selects if e[2] == m] for m in (1, 2, 3)}
    assert draws[1] != draws[2] != draws[3]


def test_a_sweep_of_a_plain_python_policy_of_many_sources_is_its_recorded_runs(tmp_path: Path):
    corraoi.sweep("I1", [SELFISH], runs=3, horizon=300, sources=[1, 2], out=tmp_path / "s",
                  seed=7, workers=1)  # fmt: skip
    rows = corraoi.load(tmp_path / "s").runs
    last = rows[rows["t"] == 300]
    for m in (1, 2):
        got = last[last["sources"] == m].sort_values("run")
        totals = simulate_sources(load_instance("I1"), make_policy(SELFISH), [7, 8, 9], 300, m)
        np.testing.assert_array_equal(got["regret"].to_numpy(), totals.total_regret)
        rec = corraoi.record(SELFISH, "I1", seed=8, horizon=300, sources=m,
                             path=tmp_path / f"r{m}.mcap", rrd=False)  # fmt: skip
        assert rec.summary.regret == totals.total_regret[1]
    assert last[last["sources"] == 2]["collisions"].sum() > 0


def _bad(name: str, select_body: str) -> type[Policy]:
    ns: dict = {"np": np}
    body = "".join(f"    {line}\n" for line in select_body.split("; "))
    exec(f"def select(self, t, state):\n{body}", ns)
    return type("Bad", (Policy,), {"name": name, "multi_source": "own", "select": ns["select"]})


@pytest.mark.parametrize("body, message", [
    ("return np.zeros(state.runs + 1, dtype=int) if state.source == 2 and t == 3 "
     "else np.zeros(state.runs, dtype=int)",
     r"^policy bad-sources, source 2, slot 3: select returned shape \(2,\); expected \(1,\) "
     r"\(one arm per run\)"),
    ("return np.full(state.runs, 9 if state.source == 3 and t == 3 else 0)",
     r"^policy bad-sources, source 3, slot 3: select returned arm 9 for run 0 \(seed 0\); "
     r"expected 0\.\.3"),
    ("assert not (state.source == 2 and t == 3), 'no channel'; "
     "return np.zeros(state.runs, dtype=int)",
     r"^policy bad-sources, source 2, slot 3: select raised AssertionError: no channel"),
])  # fmt: skip
def test_a_bad_choice_of_one_source_is_one_line_and_the_log_is_left_failed(
        tmp_path: Path, body: str, message: str):  # fmt: skip
    path = tmp_path / "b.mcap"
    with pytest.raises(PolicyRuntimeError, match=message) as info:
        corraoi.record(_bad("bad-sources", body), "I1", horizon=50, sources=3, path=path,
                       rrd=False)  # fmt: skip
    assert "\n" not in str(info.value)
    assert not path.exists()
    log = open_log(Path(f"{path}.partial"), verify=False)
    assert log.status == "failed"
    kept = log.read_all()
    assert kept.M == 3 and kept.t.tolist() == [1, 2]  # the slots before, of every source


def test_a_plain_python_policy_naming_a_compiled_rule_is_refused():
    cls = _bad("ranked-py", "return np.zeros(state.runs, dtype=int)")
    cls.multi_source = "rhorand"
    with pytest.raises(PolicyError, match=r"^policy ranked-py: multi_source 'rhorand'; a "
                       r'plain-Python policy\'s is "own"'):  # fmt: skip
        corraoi.record(cls, "I1", horizon=10, sources=2, path="never.mcap", rrd=False)
    assert not Path("never.mcap").exists()


def test_the_command_line_records_a_plain_python_policy_of_many_sources(tmp_path: Path):
    cli = [sys.executable, "-m", "corraoi", "record", "-p", SELFISH, "--sources", "3", "-T",
           "2000", "-o", str(tmp_path / "s.mcap"), "--no-rrd"]  # fmt: skip
    res = subprocess.run(cli, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert "3 sources: AoI regret at slot 2000" in res.stdout
    run = corraoi.load(tmp_path / "s.mcap")
    assert run.summary.collisions > 0 and len(run.summary.regret_by_source) == 3
    assert run.slots["score_1"].notna().any()  # its Choice's scores are logged
    single = [sys.executable, "-m", "corraoi", "record", "-p",
              f"{ROOT / 'tests' / 'plugins' / 'eps_greedy.py'}:EpsilonGreedy", "--sources", "2",
              "-T", "10", "-o", str(tmp_path / "e.mcap"), "--no-rrd"]  # fmt: skip
    res = subprocess.run(single, capture_output=True, text=True, timeout=300)
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert res.stderr.strip().count("\n") == 0
    assert 'declares multi_source = "own"' in res.stderr
    assert not (tmp_path / "e.mcap").exists() and not (tmp_path / "e.mcap.partial").exists()


def test_the_conformance_checks_run_every_source_and_catch_a_policy_of_many_sources(
        tmp_path: Path):  # fmt: skip
    from corraoi.testing import CHECKS, check_policy, policy_cases

    check_policy(SELFISH, sources=3, tmp_path=tmp_path)  # every check, every source
    check_policy("rhorand-ucb", sources=2, arms=(2, 5), horizon=120)
    cases = policy_cases(SELFISH, sources=3)
    assert [str(c) for c in cases] == ["selfish-ucb-K3-M3", "selfish-ucb-K8-M3",
                                       "selfish-ucb-K64-M3"]  # K = 2 < 3 sources: left out
    assert cases[0].batch.arm.shape == (4 * 3, 300)  # a row per run and source
    assert list((tmp_path).glob("check-selfish-ucb-K*-M3.mcap"))
    # a source that draws from numpy's global stream: not the same run twice
    global_rng = _bad("global-rng", "return np.random.randint(0, state.arms, state.runs)")
    with pytest.raises(AssertionError, match=r"global-rng \(K=3, 3 sources\): not "
                       "deterministic"):  # fmt: skip
        CHECKS[0](policy_cases(global_rng, sources=3, arms=(3,))[0])
    # a source that decides from every run of the batch: run i is not the seed's single run
    mixed = _bad("batch-mixer", "return np.full(state.runs, int(state.rng.random().sum() * "
                 "state.arms) % state.arms)")  # fmt: skip
    case = policy_cases(mixed, sources=2, arms=(4,))[0]
    with pytest.raises(AssertionError, match="decisions must use each run's own stream"):
        next(c for c in CHECKS if c.__name__ == "check_runs_use_their_own_streams")(case)
