"""Markov hidden states: the chain's draws, its instance files, and its theory."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.engine.simulation import simulate
from corraoi.model.channels import Channel
from corraoi.model.instance import Instance, load_instance
from corraoi.model.markov import mixing, period
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log

I1 = load_instance("I1")


def run(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, [str(a) for a in args])


def test_a_chain_whose_rows_all_equal_p_draws_the_iid_path_exactly():
    markov = Instance("I1", I1.p, I1.Y, transition=np.tile(I1.p, (4, 1)))
    assert not markov.is_iid
    for name in ("ucb", "cts"):
        a = next(simulate(I1, make_policy(name), [3, 4], 2000, block=2000))
        b = next(simulate(markov, make_policy(name), [3, 4], 2000, block=2000,
                          channel=Channel("markov")))  # fmt: skip
        assert np.array_equal(a.x, b.x) and np.array_equal(a.arm, b.arm)


def test_gilbert_elliott_transition_frequencies_are_within_their_ci():
    ge = load_instance("GE")
    blk = next(simulate(ge, make_policy("ucb"), list(range(20)), 20_000, block=20_000))
    x = blk.x
    prev, nxt = x[:, :-1].ravel(), x[:, 1:].ravel()
    for i, j, p in ((0, 1, 0.1), (1, 0, 0.3)):
        n = int((prev == i).sum())
        k = int(((prev == i) & (nxt == j)).sum())
        sd = math.sqrt(p * (1 - p) / n)
        assert abs(k / n - p) < 4 * sd, (i, j, k / n)
    # the stationary law: a fraction 0.75 of slots in the good state (runs are independent)
    share = (x == 0).mean(axis=1)
    assert abs(share.mean() - 0.75) < 4 * share.std(ddof=1) / math.sqrt(share.size)
    # bursty: the bad state lasts 1 / 0.3 slots on average, far longer than i.i.d. draws
    assert ge.transition is not None and ge.p.tolist() == pytest.approx([0.75, 0.25])


def test_markov_theory_and_show(tmp_path: Path):
    ge = load_instance("GE")
    assert ge.transition is not None
    m = mixing(ge.transition, ge.p)
    assert m.spectral_gap == pytest.approx(0.4)  # eigenvalues 1 and 0.6
    # t_mix(1/4): the TV distance from the worst start is 0.75 * 0.6^t (good) or 0.25 * 0.6^t
    assert m.t_mix == 3  # 0.75 * 0.6^2 = 0.27 > 1/4 >= 0.75 * 0.6^3 = 0.162
    res = run("instance", "show", "GE", "--json")
    out = json.loads(res.stdout)
    assert out["markov"]["t_mix"] == 3 and out["bounds"]["cucb"]["value"] is None
    assert "assume i.i.d." in out["bounds"]["cucb"]["note"]
    text = run("instance", "show", "GE").stdout
    assert "transition matrix P" in text and "t_mix(1/4) = 3 steps" in text
    assert period(np.array([[0.0, 1.0], [1.0, 0.0]])) == 2


def test_a_markov_log_describes_its_chain_and_round_trips(tmp_path: Path):
    out = tmp_path / "ge.mcap"
    assert (
        run("record", "-i", "GE", "-p", "cucb", "-T", "1500", "--no-rrd", "-o", out).exit_code == 0
    )
    log = open_log(out)
    assert log.format_version == 2
    assert log.config.instance == load_instance("GE")
    assert log.config.channel == Channel("markov")
    cfg = json.loads(log.metadata["config"])
    assert cfg["instance"]["transition"] == [[0.9, 0.1], [0.3, 0.7]]
    assert cfg["channel"] == {"kind": "markov"}
    # an i.i.d. instance's log has no transition and stays format version 1
    assert (
        run("record", "-p", "cucb", "-T", "10", "--no-rrd", "-o", tmp_path / "i.mcap").exit_code
        == 0
    )
    iid = open_log(tmp_path / "i.mcap")
    assert (
        iid.format_version == 1
        and "transition" not in json.loads(iid.metadata["config"])["instance"]
    )
    assert run("replay", out, "--rrd", tmp_path / "r.rrd").exit_code == 0


GOOD = {"transition": [[0.9, 0.1], [0.3, 0.7]], "Y": [[1, 0], [0, 1]]}


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"transition": [[0.9, 0.2], [0.3, 0.7]]}, "transition row 1 sums to 1.1"),
        ({"transition": [[0.9, 0.1], [-0.3, 1.3]]}, "transition row 2 has a negative entry -0.3"),
        (
            {"transition": [[0.9, 0.1]]},
            "transition must be a square n x n matrix, got shape (1, 2)",
        ),
        (
            {
                "p": [0.75, 0.25],
                "transition": [[0.5, 0.25, 0.25], [0.3, 0.3, 0.4], [0.2, 0.2, 0.6]],
            },
            "transition is 3 x 3, but there are 2 states",
        ),
        ({"p": [0.5, 0.5]}, "is not the stationary law of the transition matrix"),
        (
            {"transition": [[1.0, 0.0], [0.3, 0.7]]},
            "the chain is reducible: state x2 cannot be reached from state x1",
        ),
        ({"transition": [[0.0, 1.0], [1.0, 0.0]]}, "the chain is periodic with period 2"),
        (  # an absorbing last state: checked before its stationary law is solved for
            {"transition": [[0.9, 0.1], [0.0, 1.0]]},
            "the chain is reducible: state x1 cannot be reached from state x2",
        ),
        ({"transition": [[0.9, "x"], [0.3, 0.7]]}, "transition row 1: 'x' is not a finite number"),
        ({"transition": "no"}, "transition must be a list of rows"),
    ],
)
def test_a_malformed_transition_gets_one_line_naming_the_file_and_row(
    tmp_path: Path, change: dict, needle: str
):
    f = tmp_path / "chain.json"
    f.write_text(json.dumps({**GOOD, **change}))
    res = run("instance", "show", f)
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert res.output.count("\n") == 1 and str(f) in res.output and needle in res.output, res.output


def test_p_given_and_matching_is_accepted_and_toml_works(tmp_path: Path):
    f = tmp_path / "chain.toml"
    f.write_text("p = [0.75, 0.25]\ntransition = [[0.9, 0.1], [0.3, 0.7]]\nY = [[1, 0], [0, 1]]\n")
    inst = load_instance(f)
    assert inst.name == "chain" and inst.transition is not None
    assert Instance.from_dict(inst.to_dict()) == inst


def test_the_stationary_law_is_exact_for_a_small_chain():
    """Up to EXACT_STATES states, each probability is the exact law of the chain as given
    (its float entries as rationals) rounded once: checked against the Markov chain tree
    theorem (pi_i is proportional to the sum, over the spanning trees directed to i, of the
    product of their transition probabilities), an independent exact formula."""
    from fractions import Fraction

    from corraoi.model.markov import stationary

    assert load_instance("GE").p.tolist() == [0.75, 0.25]  # LAPACK gave 0.7500000000000007
    for P in ([[0.5, 0.3, 0.2], [0.1, 0.6, 0.3], [0.25, 0.25, 0.5]],
              [[0.9, 0.07, 0.03], [0.11, 0.8, 0.09], [0.3, 0.3, 0.4]]):  # fmt: skip
        q = [[Fraction(v) for v in row] for row in P]
        w = [q[1][0] * q[2][0] + q[1][2] * q[2][0] + q[2][1] * q[1][0],
             q[0][1] * q[2][1] + q[0][2] * q[2][1] + q[2][0] * q[0][1],
             q[0][2] * q[1][2] + q[0][1] * q[1][2] + q[1][0] * q[0][2]]  # fmt: skip
        want = [float(v / sum(w)) for v in w]
        assert stationary(np.array(P)).tolist() == want


def test_a_large_chain_s_stationary_law_is_its_fixed_point():
    from corraoi.model.markov import EXACT_STATES, stationary

    rng = np.random.default_rng(5)
    n = 3 * EXACT_STATES  # the fixed-order float path
    P = rng.random((n, n)) * (rng.random((n, n)) < 0.3) + np.eye(n) * 1e-3
    P /= P.sum(axis=1, keepdims=True)
    pi = stationary(P)
    assert math.isclose(math.fsum(pi), 1.0, rel_tol=1e-15) and (pi > 0).all()
    assert np.max(np.abs(pi @ P - pi) / pi) < 1e-13


STATIONARY_PROBE = """
import numpy as np
from corraoi.model.instance import Instance, load_instance
from corraoi.model.markov import stationary
from corraoi.model.theory import analyse
rng = np.random.default_rng(1)
out = [load_instance("GE").p, analyse(load_instance("GE")).mu]
for n in (7, 40, 300):
    P = rng.random((n, n)); P /= P.sum(axis=1, keepdims=True)
    out.append(stationary(P))
p = rng.dirichlet(np.ones(200)); Y = (rng.random((50, 200)) < 0.4).astype(int)
th = analyse(Instance("w", p, Y))
out += [th.mu, th.phi]
print(np.concatenate(out).tobytes().hex())
"""


def test_the_stationary_law_and_the_means_are_the_same_bits_whatever_the_cpu_kernels():
    """The same chains and instance under the CPU kernels OpenBLAS and NumPy can choose here
    (OPENBLAS_CORETYPE, NPY_DISABLE_CPU_FEATURES): the same bits, since no BLAS, LAPACK or
    SIMD reduction computes them. (A least-squares stationary law moved with the core type:
    0.7500000000000006 under Haswell's kernels, ...07 under SkylakeX's.)"""
    import platform
    import subprocess
    import sys

    root = str(Path(__file__).resolve().parent.parent)
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    variants: list[dict[str, str]] = [{}]
    if platform.machine() in ("x86_64", "AMD64"):
        cores = {"Prescott": "sse3", "Nehalem": "sse4_2", "Sandybridge": "avx",
                 "Haswell": "avx2", "SkylakeX": "avx512f"}  # fmt: skip
        variants += [{"OPENBLAS_CORETYPE": c} for c, f in cores.items() if f" {f}" in flags]
        variants += [{"NPY_DISABLE_CPU_FEATURES": "X86_V4"},
                     {"NPY_DISABLE_CPU_FEATURES": "AVX512F AVX512_SKX"}]  # fmt: skip
    seen = {}
    for extra in variants:
        env = {**os.environ, "PYTHONPATH": root, **extra}
        res = subprocess.run([sys.executable, "-c", STATIONARY_PROBE], env=env,
                             capture_output=True, text=True, timeout=120)  # fmt: skip
        if res.returncode != 0 and extra.get("NPY_DISABLE_CPU_FEATURES"):
            continue  # a NumPy that does not know these feature names
        assert res.returncode == 0, res.stderr
        seen[json.dumps(extra)] = res.stdout.strip()
    assert len(seen) >= 2 or len(variants) == 1
    assert len(set(seen.values())) == 1, {k: v[:32] for k, v in seen.items()}
