"""``corraoi.policies.register`` (issue 23): the one way a policy becomes known by name, used by
the built-in families and by users alike."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import corraoi
from corraoi.errors import PolicyError
from corraoi.policies import (
    Policy,
    available,
    builtins,
    make_policies,
    make_policy,
    register,
    registered,
    registry,
    resolve,
)
from corraoi.policies.spec import PolicySpec
from corraoi.recorder.slotlog.reader import open_log
from corraoi.testing import check_policy

MODULE = textwrap.dedent(
    """
    import numpy as np
    from corraoi.policies import Param, Policy, register

    @register
    class Greedy(Policy):
        name = "greedy-reg"
        params = {"start": Param(1.0, "slots of round robin per arm", low=0, high=10)}

        def select(self, t, state):
            first = t <= state.arms * self.start
            return np.where(first, (t - 1) % state.arms, state.rng.argmax(state.mu_hat))
    """
)


@pytest.fixture
def table(monkeypatch):
    """A private copy of the registry table: what a test registers is gone after it."""
    monkeypatch.setattr(registry, "TABLE", dict(registry.TABLE))


@pytest.fixture
def regmod(table, tmp_path, monkeypatch):
    (tmp_path / "regmod.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "regmod", raising=False)
    import regmod  # noqa: PLC0415 - imported here: importing it registers its policy

    return regmod


def test_the_built_in_families_are_registered_in_the_papers_order():
    names = list(builtins())
    assert len(names) == 24 and names[:4] == ["ucb", "ts", "ts-gauss", "cucb"]
    assert names[:12] == [n for n, cls in builtins().items() if cls.paper]
    assert list(registered())[:24] == names
    assert all(a.source == "built-in" for a in available()[:24])


def test_a_registered_policy_is_found_by_name_everywhere(regmod):
    assert resolve("Greedy-Reg").cls is regmod.Greedy
    res = resolve("greedy-reg")
    assert res.qualname == "regmod:Greedy" and res.version.startswith("sha256:")
    spec = make_policy("greedy-reg", start=2)
    assert spec == PolicySpec("greedy-reg", {"start": 2.0}, qualname="regmod:Greedy",
                              version=res.version)  # fmt: skip
    both = make_policies(["ucb,greedy-reg"], {"start": 3})
    assert [(s.name, s.params) for s in both] == [
        ("ucb", {"c": 2.0}),
        ("greedy-reg", {"start": 3.0}),
    ]
    listed = {a.name: a.source for a in available()}
    assert listed["greedy-reg"] == "registered by regmod"
    # a spec read back from a log finds the registered class again
    back = PolicySpec.from_dict(spec.to_dict())
    assert back.resolve() is regmod.Greedy and back.params == {"start": 2.0}


def test_a_registered_policy_runs_and_logs_like_any_other(regmod, tmp_path):
    check_policy("greedy-reg", arms=(2, 4), horizon=80, tmp_path=tmp_path)
    log = open_log(corraoi.record("greedy-reg", horizon=60, seed=5, path=tmp_path / "g.mcap"))
    arms = log.read_all().arm
    K = log.config.instance.K
    assert list(arms[:K]) == list(range(K))  # round robin first, as the class says
    assert log.config.policy.name == "greedy-reg" and log.n_slots == 60


def test_registering_again_is_allowed_and_a_taken_name_is_refused(regmod):
    assert register(regmod.Greedy) is regmod.Greedy  # the same class: a no-op

    class Other(Policy):
        name = "greedy-reg"

        def select(self, t, state):
            return np.zeros(state.runs, dtype=np.int64)

    with pytest.raises(PolicyError, match=r"'greedy-reg' is taken by regmod:Greedy"):
        register(Other)
    assert resolve("greedy-reg").cls is regmod.Greedy

    class FakeUCB(Other):
        name = "ucb"

    with pytest.raises(PolicyError, match=r"'ucb' is taken by corraoi:ucb"):
        register(FakeUCB)
    assert builtins()["ucb"].__name__ == "UCB"


@pytest.mark.parametrize("name", ["all", "eps:greedy", "a,b", "Has Space", "-lead"])
def test_a_name_the_command_line_cannot_hold_is_refused(table, name):
    cls = type("P", (Policy,), {"name": name, "select": lambda self, t, state: None})
    with pytest.raises(PolicyError, match="not usable on the command line"):
        register(cls)
    assert name not in registered()


def test_what_is_not_a_policy_is_refused_in_one_line(table):
    with pytest.raises(PolicyError, match=r"register\('dict'\): .* is not a policy class"):
        register(dict)  # type: ignore[type-var]

    class NoSelect(Policy):
        name = "no-select"

    with pytest.raises(PolicyError, match="a Python policy must define select"):
        register(NoSelect)


def test_a_file_plug_in_that_registers_itself_is_logged_by_its_file(table, tmp_path):
    plugin = tmp_path / "selfreg.py"
    plugin.write_text(MODULE.replace("greedy-reg", "greedy-file"))
    res = resolve(f"{plugin}:Greedy")
    assert res.qualname == f"file:{plugin.resolve()}:Greedy"
    assert resolve("greedy-file").qualname == res.qualname
    assert resolve("greedy-file").version == res.version


def test_the_command_line_finds_a_policy_its_module_registered(tmp_path: Path):
    (tmp_path / "regmod.py").write_text(MODULE)
    code = (
        "import regmod; from corraoi.cli import main; "
        "main(['record', '--policy', 'greedy-reg', '-T', '40', '--no-rrd', '-o', 'g.mcap'])"
    )
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                          text=True, timeout=120, env=_env(tmp_path))  # fmt: skip
    assert done.returncode == 0, done.stderr
    log = open_log(tmp_path / "g.mcap")
    assert log.config.policy.name == "greedy-reg"
    assert log.config.policy.qualname == "regmod:Greedy"


def _env(path: Path) -> dict[str, str]:
    import os

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(path), env.get("PYTHONPATH", "")]))
    return env
