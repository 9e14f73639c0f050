"""CLI: instance list/show, policies, sweep (text and JSON), and bad input."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from corraoi.cli import main
from corraoi.policies import paper_names

POLICY_NAMES = paper_names()


def run(*args: str):
    return CliRunner().invoke(main, list(args))


def test_instance_list():
    res = run("instance", "list")
    assert res.exit_code == 0
    assert "I1" in res.output and "best arm 2" in res.output and "C=1" in res.output
    assert "I2" in res.output and "best arm 4" in res.output and "C=0" in res.output


def test_instance_show_json_i1():
    res = run("instance", "show", "I1", "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["mu"] == [0.2, 0.6, 0.5, 0.2]
    assert d["best_arm"] == 2
    assert d["gaps"] == [0.4, 0.0, 0.1, 0.4]
    assert [d["phi"][i] for i in (0, 2, 3)] == [0.4, 1.0, 0.4]
    assert d["competitive"] == [3] and d["strictly_competitive"] == [3] and d["C"] == 1
    assert d["pseudo_gap"][2] == -0.4


def test_instance_show_text_and_i2():
    res = run("instance", "show", "I2")
    assert res.exit_code == 0
    assert "best arm k* = 4" in res.output and "C = 0" in res.output
    d = json.loads(run("instance", "show", "I2", "--json").stdout)
    assert d["best_arm"] == 4 and d["C"] == 0 and d["competitive"] == []


def test_instance_show_file_and_errors(tmp_path: Path):
    good = tmp_path / "g.txt"
    good.write_text("0.5 0.5\n1 0\n1 1\n")
    res = run("instance", "show", str(good), "--json")
    assert json.loads(res.stdout)["best_arm"] == 2
    bad = tmp_path / "b.txt"
    bad.write_text("0.5 0.4\n1 0\n1 1\n")
    res = run("instance", "show", str(bad))
    assert res.exit_code == 2
    assert res.output.strip().count("\n") == 0
    assert f"{bad}:1: probabilities sum to" in res.output
    assert "Traceback" not in res.output
    res = run("instance", "show", str(tmp_path / "missing.txt"))
    assert res.exit_code == 2 and "no such instance file" in res.output


def test_policies_lists_twelve():
    res = run("policies")
    assert res.exit_code == 0
    for name in POLICY_NAMES:
        assert name in res.output


def test_sweep_json_fields_and_pairing():
    res = run("sweep", "--policy", "ucb,cucb", "-p", "ts", "--runs", "8", "--horizon", "500",
              "--seed", "3", "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert list(d["policies"]) == ["ucb", "cucb", "ts"]
    assert d["runs"] == 8 and d["horizon"] == 500 and d["seed"] == 3
    for s in d["policies"].values():
        assert set(s) >= {"regret_mean", "regret_ci95", "estimator_mean", "best_arm_share",
                          "wall_s"}  # fmt: skip
        assert 0 <= s["best_arm_share"] <= 1 and s["regret_ci95"] > 0
    # the same settings give the same numbers
    again = json.loads(
        run("sweep", "-p", "cucb", "-n", "8", "-T", "500", "-s", "3", "--json").stdout
    )
    assert again["policies"]["cucb"]["regret_mean"] == d["policies"]["cucb"]["regret_mean"]


def test_sweep_values_match_library():
    import numpy as np

    from corraoi.engine.simulation import Simulation
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy

    d = json.loads(run("sweep", "-p", "cts", "-n", "5", "-T", "300", "--json").stdout)
    sim = Simulation(load_instance("I1"), make_policy("cts"), list(range(5)), 300)
    sim.advance(300, record=False)
    assert d["policies"]["cts"]["regret_mean"] == float(np.mean(sim.regret))


def test_sweep_text_table():
    res = run("sweep", "-p", "ucb,cucb", "-n", "4", "-T", "200")
    assert res.exit_code == 0
    d = json.loads(run("sweep", "-p", "ucb,cucb", "-n", "4", "-T", "200", "--json").stdout)
    table = res.stdout.split("runs worth watching", 1)[0]  # the notable runs follow
    rows = {line.split()[0]: line.split() for line in table.splitlines()[2:]}
    for name in ("ucb", "cucb"):
        s = d["policies"][name]
        regret, ci, estimator, share = (float(v) for v in rows[name][1:5])
        assert regret == round(s["regret_mean"], 1) and ci == round(s["regret_ci95"], 1)
        assert estimator == round(s["estimator_mean"], 1)
        assert share == round(s["best_arm_share"], 3)


def test_sweep_bad_input():
    for args, needle in (
        (("-p", "cucv"), "did you mean cucb"),
        (("-p", "ucb", "--beta", "2"), "does not apply"),
        (("-p", "ucb", "--c", "-1"), "parameter c=-1 must be in (0, inf)"),
        (("-p", "ucb", "--c", "inf"), "parameter c=inf must be finite"),
        (("-p", "sw-ucb", "--param", "window=0.5"), "window=0.5 must be a whole number"),
        (("-p", "ucb", "--param", "window=10"), "parameter window does not apply to ucb"),
        (("-p", "ucb", "--param", "c"), "--param 'c': expected NAME=VALUE"),
        (("-p", "ucb", "--beta", "1e309"), "beta does not apply to ucb"),
        (("--instance", "nope"), "no such instance file"),
    ):
        res = run("sweep", "-n", "2", "-T", "10", *args)
        assert res.exit_code == 2, (args, res.output)
        assert needle in res.output and "Traceback" not in res.output
    for args, needle in ((("--runs", "0"), "0 is not in the range 1..100000000"),
                         (("--horizon", "0"), "0 is not in the range 1<=x<=4294967294"),
                         (("--horizon", "1e99"), "'1e99' is not a valid integer")):
        res = run("sweep", *args)
        assert res.exit_code == 2 and needle in res.output, res.output
    # an option given empty (a shell variable that was empty) never runs the default
    for args, needle in ((("-T", ""), "no horizon given"), (("-T", ","), "no horizon given"),
                         (("-i", ""), "no instance given"),
                         (("-p", "rhorand-ucb", "--sources", ""), "--sources '': no value given"),
                         (("-p", "rhorand-ucb", "--sources", " , "), "no value given")):
        res = run("sweep", "-n", "2", *args)
        assert res.exit_code == 2 and needle in res.output, (args, res.output)
        assert "Traceback" not in res.output and "total wall time" not in res.output


def test_sweep_json_has_theory_bounds_and_ranking():
    res = run("sweep", "-i", "I2", "-p", "cucb,ucb", "-n", "6", "-T", "400", "--json")
    d = json.loads(res.stdout)
    assert d["theory"]["C"] == 0 and d["theory"]["best_arm"] == 4
    assert d["policies"]["cucb"]["bound"]["theorem"] == "Theorem 2 (CUCB)"
    assert "bound" not in d["policies"]["ucb"]
    assert d["ranking"] == sorted(d["policies"], key=lambda n: d["policies"][n]["regret_mean"])
    assert [d["policies"][n]["rank"] for n in d["ranking"]] == [1, 2]


def test_sweep_states_a_tie_for_the_best_arm(tmp_path: Path):
    tie = tmp_path / "tie.txt"
    tie.write_text("0.5 0.5\n1 0\n0 1\n0 0\n")
    res = run("sweep", "-i", str(tie), "-p", "ucb", "-n", "4", "-T", "100", "--json")
    assert res.exit_code == 0
    assert "arms 1, 2 tie for the best mean" in res.stderr
    assert "tie for the best mean" in json.loads(res.stdout)["theory"]["notes"][0]


def test_sweep_out_dir_refusals(tmp_path: Path):
    afile = tmp_path / "f"
    afile.write_text("x")
    res = run("sweep", "-p", "ucb", "-n", "2", "-T", "10", "-o", str(afile))
    assert res.exit_code == 2 and "is not a directory" in res.output
    held = tmp_path / "held"
    held.mkdir()
    (held / "summary.json").write_text("{}")
    res = run("sweep", "-p", "ucb", "-n", "2", "-T", "10", "-o", str(held))
    assert res.exit_code == 2 and "already holds a sweep" in res.output
    assert (held / "summary.json").read_text() == "{}"


def test_usage_errors_are_one_line():
    for args, needle in (
        (("sweep", "--runs", "0"), "'--runs' / '-n': 0 is not in the range 1.."),
        (("sweep", "-T", "abc"), "'abc' is not a valid integer"),
        (("--bogus",), "No such option '--bogus'"),
        (("instance", "show"), "Missing argument 'NAME|PATH'"),
        (("record", "-p", "ucb", "--rrd"), "requires an argument. (see 'corraoi record --help')"),
        (("instance", "show", "I1", "-T"), "(see 'corraoi instance show --help')"),
    ):
        res = run(*args)
        assert res.exit_code == 2, args
        assert res.output.count("\n") == 1 and res.output.startswith("corraoi: error: ")
        assert needle in res.output and "--help" in res.output


def test_no_command_prints_the_help():
    res = run()
    assert res.exit_code == 0 and "Start with:" in res.output and "record" in res.output


def test_theorem_3_only_beside_gaussian_cts_with_beta_above_one():
    res = run("sweep", "-p", "cts,cts-gauss", "-n", "3", "-T", "100", "--beta", "2", "--json")
    d = json.loads(res.stdout)["policies"]
    assert d["cts"]["bound"]["value"] is None and "Gaussian priors" in d["cts"]["bound"]["note"]
    assert d["cts-gauss"]["bound"]["theorem"] == "Theorem 3 (CTS, beta=2)"
    assert d["cts-gauss"]["bound"]["value"] == (1 / 0.2 - 1 / 0.6) * 100  # linear regime
    low = json.loads(run("sweep", "-p", "cts-gauss", "-n", "2", "-T", "50", "--json").stdout)
    assert low["policies"]["cts-gauss"]["bound"]["value"] is None  # default beta = 1
