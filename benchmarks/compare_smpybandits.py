"""corraoi's multi-source rhoRand-UCB and MCTopM-UCB against SMPyBandits 0.9.7 (issue 43, item 5).

The instance: K = 9 independent Bernoulli channels with means 0.1, 0.2, ..., 0.9 and M = 3
sources (players). SMPyBandits draws each arm once per slot; corraoi draws the hidden state
X_t, one of the 2^9 outcome vectors (p[s] = prod_k mu_k^bit_k(s) (1 - mu_k)^(1 - bit_k(s)),
Y[k, s] = bit k of s): the same law. The collision model is "no one delivers on a shared
channel" (SMPyBandits' ``onlyUniqUserGetsReward``).

Per policy and side, over --runs runs of --horizon slots:

* collisions: the number of (source, slot) pairs whose channel was shared, as SMPyBandits'
  ``EvaluatorMultiPlayers`` counts them (``collisions[arm] += 1`` for each colliding player);
* reward regret at T, SMPyBandits' default (``MORE_ACCURATE = True``) definition:
  T * (sum of the M best means) - sum_k mu_k * (selections of k that did not collide);
* realized reward regret: T * (sum of the M best means) - deliveries (its ``moreAccurate=False``).

The two sides agree on a quantity when the difference of the means is within 1.96 standard
errors of that difference (SE = sqrt(SE_1^2 + SE_2^2), each SE = sample std / sqrt(runs)).

SMPyBandits needs Python 3.8 and old numpy/scipy: the script builds its own virtual
environment in ``smpybandits-0.9.7/`` of corraoi's cache folder (``$CORRAOI_CACHE_DIR``,
else ``~/.cache/corraoi``) or ``--venv``, with the pinned versions below, the first time
(pip, network), and runs SMPyBandits there in child processes. The corraoi side runs in
this interpreter.

    python benchmarks/compare_smpybandits.py [--runs 200] [--horizon 10000] [--seed 1]
        [--jobs N] [--python PATH] [--venv DIR] [--smpybandits-only] [--json FILE]

Exit status: 0 done; 4 no Python 3.8; 5 the SMPyBandits environment could not be built.
"""

from __future__ import annotations

import argparse
import glob
import importlib
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

MEANS = tuple(round(0.1 * k, 1) for k in range(1, 10))
SOURCES = 3
#: (SMPyBandits class, corraoi policy name)
POLICIES = (("rhoRand", "rhorand-ucb"), ("MCTopM", "mctopm-ucb"))
PINS = (
    "numpy==1.21.6",
    "scipy==1.7.3",
    "scikit-learn==1.0.2",
    "joblib==1.2.0",
    "smpybandits==0.9.7",
)
QUANTITIES = ("collisions", "regret", "regret_realized")
NO_PYTHON = 4
NO_VENV = 5

#: Runs inside the SMPyBandits venv (Python 3.8): one JSON line per (policy, run) on stdout.
WORKER = r"""
import contextlib, json, sys
import numpy as np
args = json.loads(sys.argv[1])
with contextlib.redirect_stdout(sys.stderr):  # SMPyBandits prints a lot
    from SMPyBandits.Arms import Bernoulli
    from SMPyBandits.Environment.MAB import MAB
    from SMPyBandits.Environment.CollisionModels import onlyUniqUserGetsReward
    from SMPyBandits.Environment.EvaluatorMultiPlayers import delayed_play
    from SMPyBandits.Policies import UCB
    import SMPyBandits.PoliciesMultiPlayers as MP
    env = MAB({"arm_type": Bernoulli, "params": args["means"]})
means = np.asarray(env.means, dtype=float)
M, T = args["sources"], args["horizon"]
best = T * np.sort(means)[-M:].sum()
for name in args["policies"]:
    for run in args["runs"]:
        policy = getattr(MP, name)(M, env.nbArms, UCB)
        with contextlib.redirect_stdout(sys.stderr):
            r = delayed_play(env, policy.children, T, onlyUniqUserGetsReward,
                             seed=args["seed"] + run, repeatId=run + 1)
        per_arm = r.collisions.sum(axis=1)           # colliding players, summed over slots
        clean = r.pulls.sum(axis=0) - per_arm         # selections that did not collide
        print(json.dumps({"policy": name, "run": run,
                          "collisions": int(per_arm.sum()),
                          "regret": float(best - np.dot(means, clean)),
                          "regret_realized": float(best - r.rewards.sum())}), flush=True)
"""


# --- SMPyBandits' environment -------------------------------------------------------------


def find_python38(explicit: str | None) -> str | None:
    """A Python 3.8 interpreter: --python, else python3.8 on PATH, else pyenv's."""
    candidates = (
        [explicit]
        if explicit
        else [
            shutil.which("python3.8"),
            *sorted(
                glob.glob(os.path.expanduser("~/.pyenv/versions/3.8*/bin/python3.8")), reverse=True
            ),
        ]
    )
    for exe in candidates:
        if not exe:
            continue
        try:
            out = subprocess.run(
                [exe, "-c", "import sys; print(sys.version_info[:2] == (3, 8))"],
                capture_output=True,
                text=True,
                timeout=60,
            )
        except (OSError, subprocess.TimeoutExpired):
            continue
        if out.returncode == 0 and out.stdout.strip() == "True":
            return exe
    return None


def default_venv() -> Path:
    from corraoi.engine.kernel_cache import cache_dir

    return cache_dir().parent / "smpybandits-0.9.7"


def ensure_venv(python: str, venv: Path) -> Path:
    """The venv's interpreter, building the venv (pinned versions) unless it is already there.

    Raises RuntimeError with one line when it cannot be built."""
    exe = venv / "bin" / "python"
    stamp = venv / "corraoi-pins.txt"
    want = "\n".join(PINS) + "\n"
    if exe.exists() and stamp.exists() and stamp.read_text() == want:
        return exe
    if venv.exists() and any(venv.iterdir()) and not (venv / "pyvenv.cfg").exists():
        raise RuntimeError(
            f"{venv} is not empty and not a virtual environment: give another --venv"
        )
    shutil.rmtree(venv, ignore_errors=True)
    venv.parent.mkdir(parents=True, exist_ok=True)
    for cmd in (
        [python, "-m", "venv", str(venv)],
        [str(exe), "-m", "pip", "install", "-q", "--disable-pip-version-check", *PINS],
    ):
        print(f"building SMPyBandits' environment: {' '.join(cmd[-6:])}", file=sys.stderr)
        out = subprocess.run(cmd, capture_output=True, text=True)
        if out.returncode != 0:
            shutil.rmtree(venv, ignore_errors=True)
            said = out.stderr.strip().splitlines() or ["no message"]
            last = ([ln for ln in said if ln.startswith("ERROR")] or said)[-1]
            raise RuntimeError(
                f"cannot build SMPyBandits' environment in {venv}: "
                f"{' '.join(cmd[:3])} ... failed: {last}"
            )
    stamp.write_text(want)
    return exe


def smpybandits_side(
    exe: Path, runs: int, horizon: int, seed: int, jobs: int = 1
) -> dict[str, dict[str, np.ndarray]]:
    """Per SMPyBandits policy, each quantity's per-run values (run i with seed ``seed + i``),
    the runs shared among ``jobs`` child processes."""
    procs = []
    for part in np.array_split(np.arange(runs), max(1, min(jobs, runs))):
        args = {
            "means": list(MEANS),
            "sources": SOURCES,
            "horizon": horizon,
            "runs": part.tolist(),
            "seed": seed,
            "policies": [name for name, _ in POLICIES],
        }
        cmd = [str(exe), "-c", WORKER, json.dumps(args)]
        procs.append(
            subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        )
    rows = []
    for proc in procs:
        out, err = proc.communicate()
        if proc.returncode != 0:
            last = (err.strip().splitlines() or ["no message"])[-1]
            raise RuntimeError(f"SMPyBandits failed (exit {proc.returncode}): {last}")
        rows += [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    rows.sort(key=lambda r: r["run"])
    return {
        name: {
            q: np.array([r[q] for r in rows if r["policy"] == name], dtype=float)
            for q in QUANTITIES
        }
        for name, _ in POLICIES
    }


# --- corraoi's side -----------------------------------------------------------------------


def bernoulli_instance(means: tuple[float, ...] = MEANS) -> Any:
    """Independent Bernoulli channels as a correlated instance: state s is the outcome vector
    whose bit k says whether channel k delivers; p[s] is its probability."""
    from corraoi.model.instance import Instance

    mu = np.asarray(means, dtype=float)
    K = mu.size
    bits = (np.arange(1 << K)[None, :] >> np.arange(K)[:, None]) & 1  # Y[k, s] = bit k of s
    p = np.prod(np.where(bits == 1, mu[:, None], 1.0 - mu[:, None]), axis=0)
    return Instance(name=f"bernoulli-{K}", p=p / math.fsum(p), Y=bits)


def totals(
    arm: np.ndarray, collided: np.ndarray, success: np.ndarray, mu: np.ndarray, M: int
) -> dict[str, float]:
    """The three quantities of one run from its slot columns, each of shape (T, M): the
    channel each source picked (0-based), whether it collided, whether it delivered."""
    T = arm.shape[0]
    best = T * np.sort(mu)[-M:].sum()
    clean = np.bincount(arm[~collided.astype(bool)].ravel(), minlength=mu.size)
    return {
        "collisions": float(np.count_nonzero(collided)),
        "regret": float(best - np.dot(mu, clean)),
        "regret_realized": float(best - np.count_nonzero(success)),
    }


def corraoi_side(runs: int, horizon: int, seed: int = 1) -> dict[str, dict[str, np.ndarray]]:
    """Per corraoi policy, each quantity's per-run values.

    What it needs of the engine is one call: ``sources.simulate_runs(instance, policy, seeds,
    horizon, sources=M)`` yielding one run per seed, in order, with the slot columns ``arm``
    (0-based channel), ``collided`` and ``success``, each of shape (horizon, M)."""
    sources = importlib.import_module("corraoi.engine.sources")
    inst = bernoulli_instance()
    mu = np.asarray(MEANS, dtype=float)
    seeds = list(range(seed, seed + runs))
    out: dict[str, dict[str, np.ndarray]] = {}
    for _, name in POLICIES:
        per_run = [
            totals(run.arm, run.collided, run.success, mu, SOURCES)
            for run in sources.simulate_runs(inst, name, seeds, horizon, sources=SOURCES)
        ]
        out[name] = {q: np.array([r[q] for r in per_run]) for q in QUANTITIES}
    return out


# --- the table ----------------------------------------------------------------------------


def mean_se(x: np.ndarray) -> tuple[float, float]:
    n = x.size
    return float(x.mean()), float(x.std(ddof=1) / math.sqrt(n)) if n > 1 else float("nan")


def compare(a: np.ndarray, b: np.ndarray) -> tuple[float, bool]:
    """(difference / SE of the difference, whether |difference| <= 1.96 SE)."""
    (ma, sa), (mb, sb) = mean_se(a), mean_se(b)
    se = math.hypot(sa, sb)
    d = mb - ma
    z = d / se if se > 0 else (0.0 if d == 0 else math.inf)
    return z, abs(z) <= 1.96


def table(
    smpy: dict[str, dict[str, np.ndarray]],
    ours: dict[str, dict[str, np.ndarray]] | None,
    runs: int,
    horizon: int,
) -> str:
    head = (
        f"K = {len(MEANS)} Bernoulli arms, means {MEANS[0]}..{MEANS[-1]}, M = {SOURCES}, "
        f"T = {horizon}, {runs} runs; onlyUniqUserGetsReward / no one delivers"
    )
    cols = (
        f"{'policy':12} {'side':12} {'collisions':>20} {'reward regret':>20} "
        f"{'realized regret':>20}  {'diff/SE (coll, regret)':>22}  agree"
    )
    lines = [head, cols, "-" * len(cols)]

    def cell(x: np.ndarray) -> str:
        m, s = mean_se(x)
        return f"{m:10.1f} ± {s:7.1f}"

    for smpy_name, our_name in POLICIES:
        for side, name, res in (
            ("smpybandits", smpy_name, smpy[smpy_name]),
            ("corraoi", our_name, ours[our_name] if ours else None),
        ):
            if res is None:
                continue
            cmp, agree = "-", "-"
            if side == "corraoi":
                zc, okc = compare(smpy[smpy_name]["collisions"], res["collisions"])
                zr, okr = compare(smpy[smpy_name]["regret"], res["regret"])
                cmp, agree = f"{zc:+.2f}, {zr:+.2f}", "yes" if okc and okr else "NO"
            lines.append(
                f"{name:12} {side:12} {cell(res['collisions']):>20} {cell(res['regret']):>20} "
                f"{cell(res['regret_realized']):>20}  {cmp:>22}  {agree}"
            )
    return "\n".join(lines)


def saved_side(
    path: Path, runs: int, horizon: int, seed: int
) -> dict[str, dict[str, np.ndarray]] | None:
    """SMPyBandits' side as an earlier ``--json`` wrote it, or None (and one line) when the
    file is not one of the same runs."""
    try:
        data = json.loads(path.read_text())
        same = (data["runs"], data["horizon"], data["seed"], tuple(data["means"]), data["sources"])
        side = data["smpybandits"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        print(f"--smpybandits-json {path}: not a --json of this script ({exc})")
        return None
    if same != (runs, horizon, seed, MEANS, SOURCES):
        print(f"--smpybandits-json {path}: runs, horizon, seed, means, sources {same}; expected "
              f"{(runs, horizon, seed, MEANS, SOURCES)}")  # fmt: skip
        return None
    return {k: {q: np.asarray(v, dtype=float) for q, v in d.items()} for k, d in side.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--horizon", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=1, help="run i uses seed SEED + i (both sides)")
    ap.add_argument("--python", help="the Python 3.8 interpreter (default: found on PATH or pyenv)")
    ap.add_argument(
        "--venv", type=Path, help="SMPyBandits' environment (default: in corraoi's cache)"
    )
    ap.add_argument("--jobs", type=int, default=1, help="SMPyBandits' runs in JOBS processes")
    ap.add_argument("--smpybandits-only", action="store_true", help="skip the corraoi side")
    ap.add_argument("--json", type=Path, help="also write the per-run values here")
    ap.add_argument(
        "--smpybandits-json",
        type=Path,
        help="take SMPyBandits' side from an earlier --json of the same --runs, --horizon "
        "and --seed (its 400 runs are 20 CPU minutes) instead of running it",
    )
    args = ap.parse_args(argv)
    if args.runs < 2 or args.horizon < 1:
        ap.error(f"--runs must be >= 2 and --horizon >= 1, got {args.runs} and {args.horizon}")
    if args.smpybandits_json is not None:
        smpy = saved_side(args.smpybandits_json, args.runs, args.horizon, args.seed)
        if smpy is None:
            return NO_VENV
    else:
        python = find_python38(args.python)
        if python is None:
            print(
                "no Python 3.8 found (python3.8 on PATH, ~/.pyenv/versions/3.8*, or --python): "
                "SMPyBandits 0.9.7 needs it"
            )
            return NO_PYTHON
        try:
            exe = ensure_venv(python, args.venv or default_venv())
            smpy = smpybandits_side(exe, args.runs, args.horizon, args.seed, args.jobs)
        except RuntimeError as exc:
            print(exc)
            return NO_VENV
    ours = None if args.smpybandits_only else corraoi_side(args.runs, args.horizon, args.seed)
    print(table(smpy, ours, args.runs, args.horizon))
    if args.json:
        data = {
            "runs": args.runs,
            "horizon": args.horizon,
            "seed": args.seed,
            "means": MEANS,
            "sources": SOURCES,
            "smpybandits": {k: {q: v.tolist() for q, v in d.items()} for k, d in smpy.items()},
            "corraoi": {k: {q: v.tolist() for q, v in d.items()} for k, d in ours.items()}
            if ours
            else None,
        }
        args.json.write_text(json.dumps(data))
    return 0


if __name__ == "__main__":
    sys.exit(main())
