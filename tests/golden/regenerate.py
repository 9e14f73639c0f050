"""The golden files: what corraoi computes on fixed inputs, pinned by value on every machine.

    python tests/golden/regenerate.py           # write builtins.json and logs.json
    python tests/golden/regenerate.py --check   # compare with them; exit 1 naming each change

* ``builtins.json``: a short run of every built-in policy on fixed seeds, on I1, I2, a wide
  instance and GE (a Markov chain): every slot's arm, the final regret, overrides and
  candidate counts, the final estimator and means; and each instance's derived values (p
  where it is a chain's stationary law, mu, mu*, phi).
* ``logs.json``: the slot logs of :data:`LOG_CASES` written by the recorder's ``McapSink``
  and read back: every column of every slot and the run's metadata, as numbers.

Decisions and integers must be equal; a float that is not an input only within
:data:`REL_TOL` relative (:func:`differences`): the pins hold on any machine whose floats
agree to that, never by the bytes of a file (which depend on how a float is printed).
docs/model.md says what is guaranteed across machines.

Run it only when a change to the engine, a policy or the log changes what they compute on
purpose, and say so in the changelog: tests/test_golden.py, test_builtins.py,
test_kernels.py and test_views.py compare against these files.

The field table of docs/log-format.md is written from the slot record's declaration
(corraoi/engine/slot_record.py) by the same command: run it after a change there.

tests/golden/before-score.mcap is never regenerated: a slot log written by corraoi before
the score existed (commit 2347ea6; aoi-aware-cucb on I1, seed 5, 1200 slots), which today's
reader must keep reading (tests/test_slot_record.py).
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from corraoi.engine.simulation import simulate, simulate_run
from corraoi.model.instance import Instance, load_instance
from corraoi.model.theory import analyse
from corraoi.policies import builtins, make_policy

HERE = Path(__file__).parent
HORIZON = 400
SEEDS = [3, 4]
#: Floats agree when they differ by at most this, relative to the larger magnitude.
REL_TOL = 1e-12
#: The slot logs pinned value for value: (instance, policy, seed, horizon).
LOG_CASES = [("I1", "aoi-aware-cucb", 5, 600), ("GE", "cts", 3, 600)]
#: Metadata that names the writer, not the run.
_WRITER_KEYS = ("corraoi_version",)


def wide() -> Instance:
    rng = np.random.default_rng(7)
    p = rng.dirichlet(np.ones(12))
    Y = (rng.random((6, 12)) < 0.35).astype(np.int64)
    Y[2, int(np.argmax(p))] = 1
    return Instance("golden-wide", p, Y)


def instances() -> list[Instance]:
    return [load_instance("I1"), load_instance("I2"), wide(), load_instance("GE")]


def _floats(a: np.ndarray) -> list[Any]:
    return [float(v) for v in np.asarray(a, dtype=np.float64).ravel()]


def theory_of(inst: Instance) -> dict[str, Any]:
    """An instance's derived floats (p only where the instance does not give it)."""
    th = analyse(inst)
    out: dict[str, Any] = {
        "mu": _floats(th.mu),
        "mu_star": th.mu_star,
        "phi": _floats(th.phi),
        "best_arm": th.best_arm,
        "competitive": list(th.competitive),
    }
    if inst.transition is not None:
        out["p"] = _floats(inst.p)
    return out


def golden() -> dict[str, object]:
    runs: dict[str, object] = {}
    theory: dict[str, object] = {}
    for inst in instances():
        theory[inst.name] = theory_of(inst)
        for name in builtins():
            blk = next(simulate(inst, make_policy(name), SEEDS, HORIZON, block=HORIZON))
            runs[f"{inst.name}/{name}"] = {
                "arms": ["".join(chr(ord("a") + int(a)) for a in row) for row in blk.arm],
                "regret": [int(r) for r in blk.regret[:, -1]],
                "overrides": [int(v) for v in blk.override.sum(axis=1)],
                "candidates": [int(v) for v in blk.candidates.sum(axis=(1, 2))],
                "estimator": _floats(blk.estimator[:, -1]),
                "mu_hat": [_floats(m) for m in blk.mu_hat[:, -1]],
            }
    return {"horizon": HORIZON, "seeds": SEEDS, "theory": theory, "runs": runs}


def log_values(path: Path) -> dict[str, Any]:
    """A slot log read back by the recorder: its run and end metadata (JSON values decoded)
    and every column of every slot, as plain numbers (integers stay integers)."""
    from corraoi.recorder.slotlog.reader import open_log

    log = open_log(path)
    meta: dict[str, Any] = {}
    for key, text in log.metadata.items():
        if key in _WRITER_KEYS:
            continue
        try:
            meta[key] = json.loads(text)
        except ValueError:
            meta[key] = text
    if isinstance(meta.get("config"), dict):
        meta["config"].pop("version", None)
    end = {k: json.loads(v) if k != "status" else v for k, v in log.end.items()}
    block = log.read_all()
    columns = {}
    for name in block.fields():
        col = np.asarray(block.column(name))
        columns[name] = col.tolist() if col.dtype.kind == "f" else col.astype(int).tolist()
    return {"metadata": meta, "end": end, "columns": columns}


def write_log(key: tuple[str, str, int, int], path: Path) -> Any:
    """Record the log of one of :data:`LOG_CASES` at ``path``; returns its RunConfig."""
    from corraoi.engine.block import RunConfig
    from corraoi.recorder.slotlog.sink import McapSink

    inst_name, policy, seed, horizon = key
    config = RunConfig(load_instance(inst_name), make_policy(policy), seed, horizon)
    with McapSink(path, config, fsync=False) as sink:
        for b in simulate_run(config.instance, config.policy, seed, horizon):
            sink.write(b)
    return config


def case_name(key: tuple[str, str, int, int]) -> str:
    inst_name, policy, seed, horizon = key
    return f"{inst_name}/{policy}/s{seed}/T{horizon}"


def logs() -> dict[str, object]:
    out: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for key in LOG_CASES:
            path = Path(tmp) / "golden.mcap"
            write_log(key, path)
            out[case_name(key)] = log_values(path)
            path.unlink()
    return out


def write_docs_table() -> Path:
    """The slot record's table between its markers in docs/log-format.md."""
    from corraoi.engine.slot_record import markdown_table

    doc = HERE.parent.parent / "docs" / "log-format.md"
    begin, end = "<!-- slot-record: begin -->\n", "<!-- slot-record: end -->"
    text = doc.read_text(encoding="utf-8")
    head, rest = text.split(begin, 1)
    doc.write_text(head + begin + markdown_table() + end + rest.split(end, 1)[1], encoding="utf-8")
    return doc


def differences(want: Any, got: Any, where: str = "", limit: int = 20) -> list[str]:
    """Where ``got`` differs from ``want``: numbers that are integers in both must be equal,
    others (a float on either side) within REL_TOL relative; strings, booleans and None
    equal; lists and tables in shape and key for key. At most ``limit`` lines."""
    out: list[str] = []

    def walk(a: Any, b: Any, at: str) -> None:
        if len(out) >= limit:
            return
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if k not in b:
                    out.append(f"{at}/{k}: missing")
                elif k not in a:
                    out.append(f"{at}/{k}: new (not in the golden file)")
                else:
                    walk(a[k], b[k], f"{at}/{k}")
            return
        if isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                out.append(f"{at}: {len(b)} items, expected {len(a)}")
                return
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                walk(x, y, f"{at}[{i}]")
            return
        numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (a, b))
        if numbers and (isinstance(a, float) or isinstance(b, float)):
            if not close(float(a), float(b)):
                out.append(f"{at}: {b!r}, expected {a!r} (within {REL_TOL:g} relative)")
        elif type(a) is not type(b) or a != b:
            out.append(f"{at}: {b!r}, expected {a!r}")

    walk(want, got, where)
    return out


def close(a: float, b: float) -> bool:
    """Equal within REL_TOL relative (NaNs equal NaNs, infinities equal themselves)."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= REL_TOL * max(abs(a), abs(b))


def dump(value: Any, indent: str = "") -> str:
    """JSON with one key a line and each list of numbers (or of lists of them) on one line:
    a change shows in a diff as the lines of the columns it touched."""
    if isinstance(value, dict) and value:
        inner = indent + " "
        items = [f"{inner}{json.dumps(k)}: {dump(value[k], inner)}" for k in sorted(value)]
        return "{\n" + ",\n".join(items) + "\n" + indent + "}"
    if isinstance(value, list) and any(isinstance(v, (dict, str)) for v in value):
        inner = indent + " "
        return "[\n" + ",\n".join(inner + dump(v, inner) for v in value) + "\n" + indent + "]"
    return json.dumps(value, separators=(",", ":"))


FILES = {"builtins.json": golden, "logs.json": logs}


def main(argv: list[str]) -> int:
    check = argv == ["--check"]
    if argv and not check:
        print("usage: python tests/golden/regenerate.py [--check]", file=sys.stderr)
        return 2
    bad = 0
    for name, make in FILES.items():
        path = HERE / name
        now = make()
        if check:
            found = differences(json.loads(path.read_text()), now, name)
            for line in found:
                print(line)
            bad += len(found)
        else:
            path.write_text(dump(now) + "\n")
            print(f"wrote {path}")
    if not check:
        print(f"wrote {write_docs_table()}")
    if check:
        print("golden: differences found" if bad else "golden: every value as pinned")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
