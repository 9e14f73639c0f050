"""Every number tied to the code that made it (issue 32): a log carries each plug-in's source
and hash and the versions that matter; a sweep folder keeps a copy of each plug-in's source;
``record --from``, ``compare --from`` and ``--resume`` refuse code other than the sweep's in
one line (with ``--kept-code`` and ``--allow-changed-code`` as the ways out); ``record --from``
checks that the re-recorded run gives the sweep's regret again."""

from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from corraoi.errors import CodeChanged
from corraoi.policies import PolicySpec, make_policy
from corraoi.provenance import KERNEL_SOURCES, Provenance, kernel_sources_hash
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.sweeplog.read import read_sweep

PLUGIN = '''"""A plain-Python plug-in: greedy after a forced first pull of every arm."""
import numpy as np

from corraoi.policies import Param, Policy


class Greedyish(Policy):
    name = "greedyish"
    params = {"bonus": Param(0.5, "optimism per unpulled arm", low=0.0)}

    def select(self, t, state):
        score = state.mu_hat + self.bonus / (1.0 + state.pulls)
        return state.rng.argmax(score)
'''
EDITED = PLUGIN.replace("1.0 + state.pulls", "1.0 + 3 * state.pulls")


def _cli(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "corraoi", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


def _one_line(res: subprocess.CompletedProcess[str], code: int) -> str:
    assert res.returncode == code, (res.returncode, res.stderr)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("corraoi: error: ")
    return lines[0]


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


@pytest.fixture
def swept(tmp_path: Path) -> Path:
    """A sweep of cucb and the plug-in in ``tmp_path/sw`` (the plug-in at tmp_path/greedyish.py)."""
    (tmp_path / "greedyish.py").write_text(PLUGIN)
    res = _cli("sweep", "-i", "I1", "-p", "cucb,greedyish.py:Greedyish", "-n", 6, "-T", 400,
               "--chunk", 3, "-o", "sw", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    return tmp_path / "sw"


# ---------------------------------------------------------------------------- in the files


def test_a_slot_log_carries_the_plugins_exact_bytes_its_hash_and_the_versions(tmp_path: Path):
    source = PLUGIN.encode() + b"\n# \xc3\xa9 and trailing bytes kept as they are \n\n"
    (tmp_path / "greedyish.py").write_bytes(source)
    res = _cli("record", "-p", "greedyish.py:Greedyish", "-T", 50, "--no-rrd", "-o", "g.mcap",
               cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    log = open_log(tmp_path / "g.mcap")
    assert [(n, m, d) for n, m, d in log.attachments] == [("greedyish.py", "text/x-python",
                                                          source)]  # fmt: skip
    prov = Provenance.read(log.provenance)
    assert prov["plugins"][0]["sha256"] == _sha(source) == log.config.policy.sha256
    assert log.config.policy.version == f"sha256:{_sha(source)[:16]}"
    versions = prov["versions"]
    assert {"corraoi", "kernel_sources", "python", "numpy", "numba", "rerun-sdk"} <= set(versions)
    assert versions["kernel_sources"] == kernel_sources_hash() and prov["backend"] == "cpu"
    if (Path(__file__).parents[1] / ".git").exists():  # run from a checkout: its commit
        assert re.fullmatch(r"[0-9a-f]{40}(\+dirty)?", versions["git"])
    with open(tmp_path / "g.mcap", "rb") as f:  # the official reader finds it too
        found = [(a.name, a.data) for a in make_reader(f).iter_attachments()]
    assert found == [("greedyish.py", source)]
    info = _cli("info", "g.mcap", cwd=tmp_path).stdout
    assert f"greedyish.py sha256:{_sha(source)[:16]} (its source attached, byte for byte)" in info
    assert "backend                cpu" in info


def test_a_built_in_run_carries_versions_and_no_attachment(tmp_path: Path):
    res = _cli("record", "-p", "ucb", "-T", 30, "--no-rrd", "-o", "u.mcap", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    log = open_log(tmp_path / "u.mcap")
    assert log.attachments == [] and Provenance.read(log.provenance)["plugins"] == []
    assert "kernel_sources" in log.provenance


def test_the_kernel_hash_covers_the_kernel_sources():
    root = Path(__file__).parents[1] / "corraoi"
    assert all((root / rel).is_file() for rel in KERNEL_SOURCES)
    assert kernel_sources_hash().startswith("sha256:") and len(kernel_sources_hash()) == 71


def test_a_sweep_folder_keeps_a_copy_beside_the_hash_and_its_log_carries_it(swept: Path):
    data = (swept.parent / "greedyish.py").read_bytes()
    manifest = json.loads((swept / "manifest.json").read_text())
    (entry,) = manifest["provenance"]["plugins"]
    assert entry["sha256"] == _sha(data) and entry["file"] == "greedyish.py"
    assert entry["copy"] == f"plugins/{_sha(data)[:16]}/greedyish.py"
    assert (swept / entry["copy"]).read_bytes() == data
    assert manifest["provenance"]["backend"] == "cpu"
    with open(swept / "sweep.mcap", "rb") as f:
        assert [(a.name, a.data) for a in make_reader(f).iter_attachments()] == [
            ("greedyish.py", data)]  # fmt: skip
    assert read_sweep(swept / "sweep.mcap").messages > 0


# ---------------------------------------------------------------------------- code changed


def test_record_from_refuses_an_edited_plugin_in_one_line(swept: Path):
    tmp = swept.parent
    before = _sha((tmp / "greedyish.py").read_bytes())
    (tmp / "greedyish.py").write_text(EDITED)
    after = _sha(EDITED.encode())
    line = _one_line(_cli("record", "--from", "sw", "--cell", "greedyish", "--run", 2,
                          "--no-rrd", "-o", "r.mcap", cwd=tmp), 2)  # fmt: skip
    assert line == (
        f"corraoi: error: {tmp / 'greedyish.py'}: the plug-in's code has changed "
        f"(sha256:{before[:16]} recorded, sha256:{after[:16]} now); the sweep's copy is "
        f"sw/plugins/{before[:16]}/greedyish.py; --kept-code runs that copy, "
        "--allow-changed-code (record and compare --from) records with the current code and "
        "says so in the log"
    )
    assert not list(tmp.glob("r.mcap*"))  # nothing written
    line = _one_line(_cli("compare", "--from", "sw", "--cell", "greedyish", "--no-rrd",
                          cwd=tmp), 2)  # fmt: skip
    assert "the plug-in's code has changed" in line and not (tmp / "runs").exists()


def test_allow_changed_code_records_the_current_code_and_says_so(swept: Path):
    tmp = swept.parent
    (tmp / "greedyish.py").write_text(EDITED)
    res = _cli("record", "--from", "sw", "--cell", "greedyish", "--run", 2, "--no-rrd", "-o",
               "r.mcap", "--allow-changed-code", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "corraoi: warning: recorded with changed code" in res.stderr
    log = open_log(tmp / "r.mcap")
    new = _sha(EDITED.encode())
    assert log.config.policy.sha256 == new  # never the sweep's hash for other code
    assert log.attachments[0][2] == EDITED.encode()
    notes = Provenance.read(log.provenance)["notes"]
    old = _sha(PLUGIN.encode())
    assert notes == [f"recorded with changed code: {tmp / 'greedyish.py'} is "
                     f"sha256:{new[:16]} now, the sweep ran sha256:{old[:16]} "
                     "(--allow-changed-code)"]  # fmt: skip
    assert "note                   recorded with changed code" in _cli("info", "r.mcap",
                                                                         cwd=tmp).stdout


def test_kept_code_records_the_sweeps_copy_and_its_row(swept: Path):
    tmp = swept.parent
    (tmp / "greedyish.py").write_text(EDITED)
    res = _cli("record", "--from", "sw", "--cell", "greedyish", "--run", 4, "--no-rrd", "-o",
               "k.mcap", "--kept-code", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    log = open_log(tmp / "k.mcap")
    assert log.attachments[0][2] == PLUGIN.encode()  # the bytes that ran: the kept copy
    assert log.config.policy.sha256 == _sha(PLUGIN.encode())
    assert (tmp / "greedyish.py").read_text() == EDITED  # the file is not touched
    finals = _finals(swept, "greedyish")  # the sweep's own final regrets
    assert int(log.end["regret"]) == finals[4]
    summary = json.loads((swept / "summary.json").read_text())
    assert summary["policies"]["greedyish"]["regret_mean"] == pytest.approx(np.mean(finals))


def _finals(folder: Path, label: str) -> list[int]:
    from corraoi.experiments.folder import CellRuns, read_manifest, read_parts

    grid = read_manifest(folder)
    assert grid is not None
    (cell,) = [c for c in grid.cells if grid.labels()[c.key] == label]
    runs = CellRuns.join(cell, label, read_parts(folder, grid)[cell.key], grid.runs)
    return [int(v) for v in runs.regret[:, -1]]


def test_resume_refuses_an_edited_plugin_and_kept_code_resumes(swept: Path):
    tmp = swept.parent
    (tmp / "greedyish.py").write_text(EDITED)
    manifest = (swept / "manifest.json").read_bytes()
    parts = sorted(p.name for p in (swept / "parts").iterdir())
    line = _one_line(_cli("sweep", "-i", "I1", "-p", "cucb,greedyish.py:Greedyish", "-n", 9,
                          "-T", 400, "--chunk", 3, "-o", "sw", "--resume", cwd=tmp), 2)  # fmt: skip
    assert "the plug-in's code has changed" in line and "--kept-code runs that copy" in line
    assert (swept / "manifest.json").read_bytes() == manifest  # untouched
    assert sorted(p.name for p in (swept / "parts").iterdir()) == parts
    res = _cli("sweep", "-i", "I1", "-p", "cucb,greedyish.py:Greedyish", "-n", 9, "-T", 400,
               "--chunk", 3, "-o", "sw", "--resume", "--kept-code", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    after = json.loads((swept / "manifest.json").read_text())
    assert after["status"] == "complete" and len(after["grid"]["cells"]) == 2
    assert after["provenance"]["plugins"][0]["sha256"] == _sha(PLUGIN.encode())
    # the new runs come from the kept code: the same numbers a fresh sweep of it gives
    (tmp / "greedyish.py").write_text(PLUGIN)
    fresh = _cli("sweep", "-i", "I1", "-p", "cucb,greedyish.py:Greedyish", "-n", 9, "-T", 400,
                 "--chunk", 3, "-o", "fresh", cwd=tmp)  # fmt: skip
    assert fresh.returncode == 0, fresh.stderr
    assert _finals(swept, "greedyish") == _finals(tmp / "fresh", "greedyish")


def test_a_spec_never_resolves_to_other_code(tmp_path: Path):
    path = tmp_path / "greedyish.py"
    path.write_text(PLUGIN)
    spec = make_policy(f"{path}:Greedyish")
    assert spec.sha256 == _sha(PLUGIN.encode())
    path.write_text(EDITED)
    assert spec.resolve().name == "greedyish"  # the module loaded with its code is kept
    plugin = {**spec.to_dict()["plugin"], "sha256": "0" * 64, "version": "sha256:" + "0" * 16}
    other = PolicySpec.from_dict({**spec.to_dict(), "plugin": plugin})
    with pytest.raises(CodeChanged) as info:
        other.resolve()  # a log naming other code: never run under its hash
    assert info.value.expected == "0" * 64 and info.value.found == _sha(EDITED.encode())
    assert str(info.value) == (f"{path}: the plug-in's code has changed (sha256:{'0' * 16} "
                               f"recorded, sha256:{_sha(EDITED.encode())[:16]} now)")


def test_resume_of_a_folder_whose_manifest_predates_the_full_hash_keeps_its_cells(swept: Path):
    manifest = json.loads((swept / "manifest.json").read_text())
    for cell in manifest["grid"]["cells"]:  # as written before the full hash was recorded
        cell["policy"].get("plugin", {}).pop("sha256", None)
    del manifest["provenance"]
    (swept / "manifest.json").write_text(json.dumps(manifest))
    res = _cli("sweep", "-i", "I1", "-p", "cucb,greedyish.py:Greedyish", "-n", 6, "-T", 400,
               "--chunk", 3, "-o", "sw", "--resume", cwd=swept.parent)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "(0 chunks run, 4 already done)" in res.stdout + res.stderr
    assert len(json.loads((swept / "manifest.json").read_text())["grid"]["cells"]) == 2


# ---------------------------------------------------------------------------- the row checked


def test_a_rerecorded_run_that_differs_from_the_sweeps_row_is_refused(swept: Path, monkeypatch):
    """The engine changed since the sweep (simulated: one slot of age more from slot 100):
    one line, exit 1, the log finished as failed with the mismatch, never under its final
    name; once the engine agrees again, the next attempt is not blocked by that log."""
    from click.testing import CliRunner

    import corraoi.face.slots
    from corraoi.cli import main

    real = corraoi.face.slots.slots_of

    def changed_engine(config):
        for block in real(config):
            block.regret = block.regret + (block.t >= 100)
            yield block

    out = swept.parent / "m.mcap"
    args = ["record", "--from", str(swept), "--cell", "cucb", "--run", 1, "--no-rrd", "-o", out]
    monkeypatch.setattr(corraoi.face.slots, "slots_of", changed_engine)
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 1, res.output
    line = res.output.strip().splitlines()[-1]
    grid_t = [t for t, _ in _row(swept, "cucb", 1)]
    first = min(t for t in grid_t if t >= 100)
    want = dict(_row(swept, "cucb", 1))[first]
    assert line == (f"corraoi: error: cucb-I1-s1: the re-recorded run's regret at slot {first} "
                    f"is {want + 1:g}, the sweep's row says {want:g}: the engine or the code "
                    f"changed since the sweep; the log is left as {out}.partial, marked failed")
    assert not out.exists()
    log = open_log(f"{out}.partial")
    assert log.status == "failed" and "the sweep's row says" in log.end["error"]
    monkeypatch.setattr(corraoi.face.slots, "slots_of", real)
    res = CliRunner().invoke(main, [str(a) for a in args])  # no --force needed: the same run
    assert res.exit_code == 0, res.output
    assert open_log(out).status == "complete" and not Path(f"{out}.partial").exists()
    assert int(open_log(out).end["regret"]) == _finals(swept, "cucb")[1]


def _row(folder: Path, label: str, run: int) -> list[tuple[int, float]]:
    from corraoi.experiments.drill import expected_row
    from corraoi.experiments.folder import read_manifest

    grid = read_manifest(folder)
    assert grid is not None
    (cell,) = [c for c in grid.cells if grid.labels()[c.key] == label]
    return list(expected_row(folder, grid, cell, run))


COMPILED = '''"""A compiled plug-in: decaying epsilon-greedy."""
from numba import njit

from corraoi.policies import CompiledPolicy, Param
from corraoi.rng import uniform


@njit(cache=True)
def decay_score(t, K, npull, nsucc, muhat, cand, vals, params, ps, pst, cache):
    explore = uniform(pst) < min(1.0, params[0] / t)
    for k in range(K):
        vals[k] = uniform(pst) if explore else muhat[k]


class DecayEps(CompiledPolicy):
    name = "decay-eps"
    params = {"c": Param(5.0, "exploration scale", low=0.0)}
    forced = "corraoi.policies.hooks:first_unpulled"
    score = decay_score
'''


@pytest.mark.slow
def test_kept_code_of_a_compiled_plugin_runs_the_kept_kernel(tmp_path: Path):
    """The kernel cache is keyed by the bytes a hook was loaded from, not by the file read
    again: the kept copy never runs a kernel compiled from the edited file (nor the other
    way round), so the re-recorded run gives the sweep's row at every checkpoint."""
    (tmp_path / "decay_eps.py").write_text(COMPILED)
    res = _cli("sweep", "-i", "I1", "-p", "decay_eps.py:DecayEps", "-n", 4, "-T", 600, "-o",
               "sw", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    (tmp_path / "decay_eps.py").write_text(COMPILED.replace("params[0] / t", "params[0] / t**2"))
    edited = _cli("record", "-p", "decay_eps.py:DecayEps", "--seed", 3, "-T", 600, "--no-rrd",
                  "-o", "e.mcap", cwd=tmp_path)  # the edited code's kernel, compiled now
    assert edited.returncode == 0, edited.stderr
    kept = _cli("record", "--from", "sw", "--run", 3, "--no-rrd", "-o", "k.mcap", "--kept-code",
                cwd=tmp_path)  # fmt: skip
    assert kept.returncode == 0, kept.stderr  # the row check passed at every checkpoint
    assert int(open_log(tmp_path / "k.mcap").end["regret"]) == _finals(tmp_path / "sw",
                                                                       "decay-eps")[3]
    assert open_log(tmp_path / "k.mcap").attachments[0][2] == COMPILED.encode()


def test_results_parquet_says_what_made_its_rows(swept: Path):
    pq = pytest.importorskip("pyarrow.parquet")

    (part,) = (swept / "results.parquet").rglob("*.parquet")
    meta = {k.decode(): v.decode() for k, v in pq.read_schema(part).metadata.items()}
    prov = json.loads(meta["provenance"])
    assert prov["plugins"][0]["sha256"] == _sha((swept.parent / "greedyish.py").read_bytes())
    assert prov["backend"] == "cpu" and "kernel_sources" in prov["versions"]


def test_a_plugin_file_gone_since_the_sweep_points_to_its_kept_copy(swept: Path):
    tmp = swept.parent
    (tmp / "greedyish.py").unlink()
    line = _one_line(_cli("record", "--from", "sw", "--cell", "greedyish", "--run", 1,
                          "--no-rrd", "-o", "g.mcap", cwd=tmp), 2)  # fmt: skip
    digest = _sha(PLUGIN.encode())[:16]
    assert "no such file" in line and f"the sweep ran sha256:{digest}" in line
    assert f"the sweep's copy is sw/plugins/{digest}/greedyish.py; --kept-code" in line
    res = _cli("record", "--from", "sw", "--cell", "greedyish", "--run", 1, "--no-rrd", "-o",
               "g.mcap", "--kept-code", cwd=tmp)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert int(open_log(tmp / "g.mcap").end["regret"]) == _finals(swept, "greedyish")[1]
