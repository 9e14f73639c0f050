"""The replay, compare, diff, info and recover commands: output, exit status, bad input."""

from __future__ import annotations

import json
import socket
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from mcap.writer import Writer

from corraoi.cli import main
from corraoi.engine.block import RunConfig
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy


def run(*args: str):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_error_line(res, code: int = 2) -> str:
    assert res.exit_code == code, (res.exit_code, res.output, res.stderr)
    assert res.exception is None or isinstance(res.exception, SystemExit)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("corraoi: error: "), lines[0]
    assert "Traceback" not in res.output + res.stderr
    return lines[0]


# ---------------------------------------------------------------------------- bad input


def _other_tool(path: Path) -> Path:
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="", library="someone-else/1.0")
        sid = w.register_schema(name="foo.Bar", encoding="jsonschema", data=b"{}")
        cid = w.register_channel(topic="/other", message_encoding="json", schema_id=sid)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()
    return path


def _newer(path: Path) -> Path:
    from corraoi.recorder.slotlog.encode import run_metadata
    from corraoi.recorder.vocab import RUN_METADATA

    config = RunConfig(load_instance("I1"), make_policy("ucb"), 0, 100)
    meta = run_metadata(config)
    meta["format_version"] = "99"
    with path.open("wb") as f:
        w = Writer(f)
        w.start(profile="", library="corraoi/99.0")
        w.add_metadata(RUN_METADATA, meta)
        w.finish()
    return path


def _bad_crc(path: Path, good: Path) -> Path:
    data = bytearray(good.read_bytes())
    pos = 8
    while True:  # find the first chunk record (opcode 6) and break its CRC
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x06:
            crc_at = pos + 9 + 24  # start, end, uncompressed size, then the CRC
            (crc,) = struct.unpack_from("<I", data, crc_at)
            struct.pack_into("<I", data, crc_at, crc ^ 0xFFFF)
            break
        pos += 9 + length
    path.write_bytes(bytes(data))
    return path


@pytest.fixture
def bad_inputs(tmp_path, record_mcap):
    good, _, _ = record_mcap("ucb", horizon=1500, name="good.mcap")
    d = tmp_path / "bad"
    d.mkdir()
    (d / "empty.mcap").write_bytes(b"")
    (d / "text.mcap").write_text("time,aoi\n1,1\n")
    (d / "a-directory.mcap").mkdir()
    return good, {
        "missing": (d / "missing.mcap", "no such file"),
        "directory": (d / "a-directory.mcap", "is a directory"),
        "empty": (d / "empty.mcap", "empty file"),
        "not MCAP": (d / "text.mcap", "not an MCAP file"),
        "another tool's MCAP": (_other_tool(d / "other.mcap"), "not a corraoi log"),
        "newer format": (_newer(d / "newer.mcap"), "newer than the version"),
        "bad CRC": (_bad_crc(d / "crc.mcap", good), "CRC"),
    }


def _commands(bad: Path, good: Path, out: Path) -> dict[str, list]:
    return {
        "replay": ["replay", bad, "--rrd", out, "--force"],
        "compare": ["compare", good, bad, "-o", out, "--force"],
        "diff": ["diff", good, bad],
        "diff (b first)": ["diff", bad, good],
        "info": ["info", bad],
        "recover": ["recover", bad, "-o", out, "--force"],
    }


def test_bad_input_is_one_line_exit_2_and_nothing_is_written_over(tmp_path, bad_inputs):
    good, cases = bad_inputs
    out = tmp_path / "precious.out"
    for what, (bad, phrase) in cases.items():
        for name, args in _commands(bad, good, out).items():
            out.write_bytes(b"keep me")
            res = run(*args)
            line = one_error_line(res)
            assert str(bad) in line, (what, name, line)
            assert phrase in line, (what, name, line)
            assert out.read_bytes() == b"keep me", (what, name)
            assert not Path(f"{out}.partial").exists(), (what, name)
            assert res.stdout == "", (what, name, res.stdout)


def test_usage_errors_are_one_line_exit_2(tmp_path, record_mcap):
    a, _, _ = record_mcap("ucb", horizon=1000)
    assert "unknown field 'bogus'" in one_error_line(run("diff", a, a, "--fields", "x,bogus"))
    assert "atol" in one_error_line(run("diff", a, a, "--atol", "-1"))
    assert "choose one" in one_error_line(run("replay", a, "--spawn", "--serve-web"))
    assert "--connect" in one_error_line(run("compare", a, "--connect", "http://x:1/nope"))
    assert "--no-rrd" in one_error_line(run("compare", a, "--no-rrd", "-o", tmp_path / "x.rrd"))
    before = a.read_bytes()
    assert "is one of the logs being read" in one_error_line(run("replay", a, "--rrd", a, "-f"))
    assert "is one of the logs being read" in one_error_line(run("compare", a, "-o", a, "-f"))
    assert a.read_bytes() == before
    (tmp_path / "exists.rrd").write_bytes(b"keep me")
    line = one_error_line(run("replay", a, "--rrd", tmp_path / "exists.rrd"))
    assert "already exists (use --force" in line
    assert (tmp_path / "exists.rrd").read_bytes() == b"keep me"


# ---------------------------------------------------------------------------- diff


def test_diff_exit_status_as_diff1(record_mcap):
    a, _, _ = record_mcap("ucb", seed=1, horizon=2000, name="a.mcap")
    a2, _, _ = record_mcap("ucb", seed=1, horizon=2000, name="a2.mcap")
    b, _, _ = record_mcap("cucb", seed=1, horizon=2000, name="b.mcap")
    same = run("diff", a, a2)
    assert same.exit_code == 0 and "identical: 2000 slots" in same.stdout
    different = run("diff", a, b)
    assert different.exit_code == 1
    text = different.stdout
    assert text.index("configuration differs") < text.index("per field") < text.index("final")
    assert "policy.name: ucb != cucb" in text
    x_row = next(line for line in text.splitlines() if line.split()[:1] == ["x"])
    assert x_row.split()[1:] == ["-", "0", "of", "2000"]
    assert run("diff", a, b, "-q").stdout == ""
    assert run("diff", a, b, "-q").exit_code == 1


def test_diff_json(record_mcap):
    a, _, ra = record_mcap("ucb", seed=2, horizon=1000)
    b, _, rb = record_mcap("ts", seed=2, horizon=1000)
    res = run("diff", a, b, "--json", "--fields", "x", "--fields", "arm")
    assert res.exit_code == 1
    data = json.loads(res.stdout)
    assert list(data["fields"]) == ["x", "arm"]
    assert data["fields"]["x"]["identical"] is True
    assert data["fields"]["arm"]["slots_differing"] == int((ra.arm != rb.arm).sum())
    assert data["finals"]["regret"]["b_minus_a"] == int(rb.regret[-1] - ra.regret[-1])


# ---------------------------------------------------------------------------- info


def test_info_of_a_finished_and_of_a_cut_short_log(tmp_path, record_mcap):
    path, config, ref = record_mcap("aoi-aware-ucb", seed=6, horizon=3000)
    res = run("info", path, "--json")
    assert res.exit_code == 0, res.stderr
    data = json.loads(res.stdout)
    assert (data["status"], data["slots"], data["cut_short"]) == ("complete", 3000, False)
    assert data["config"] == json.loads(json.dumps(config.to_dict()))
    assert data["summary"]["regret"] == int(ref.regret[-1])
    assert data["summary"]["overrides"] == int(ref.override.sum())
    assert data["summary"]["pulls"] == [int(v) for v in ref.pulls[-1]]
    text = run("info", path).stdout
    assert "complete: 3000 of 3000 slots" in text and "aoi-aware-ucb" in text
    assert f"3000 (in {data['chunks']} chunks)" in text and data["chunks"] > 1
    one, _, _ = record_mcap("ucb", seed=6, horizon=300)  # one chunk: not "1 chunks"
    assert "300 (in 1 chunk)\n" in run("info", one).stdout

    data = bytearray(path.read_bytes())
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bytes(data[: len(data) * 3 // 4]))  # the writer died mid-file
    res = run("info", cut, "--json")
    assert res.exit_code == 0, res.stderr
    info = json.loads(res.stdout)
    assert info["cut_short"] is True and info["status"] == "truncated"
    assert 0 < info["last_slot"] < 3000 and info["last_slot"] % 1000 == 0
    assert info["summary"]["regret"] == int(ref.regret[info["last_slot"] - 1])
    assert f"{info['last_slot']} of 3000" in run("info", cut).stdout


# ---------------------------------------------------------------------------- replay, compare


def test_replay_writes_beside_the_log_and_says_how_far(tmp_path, record_mcap):
    path, config, _ = record_mcap("cts", horizon=2000)
    res = run("replay", path)
    assert res.exit_code == 0, res.stderr
    rrd = path.with_suffix(".rrd")
    assert rrd.exists() and rrd.stat().st_size > 0
    assert f"replayed {config.label}: slots 1..2000 of 2000 (complete) to {rrd}" in res.stdout
    again = run("replay", path)  # the .rrd is there now: refused, kept
    assert "already exists" in one_error_line(again)
    data = bytearray(path.read_bytes())
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bytes(data[: len(data) * 2 // 3]))
    res = run("replay", cut, "--rrd", tmp_path / "cut.rrd")
    assert res.exit_code == 0, res.stderr
    assert "slots 1..1000 of 2000 (truncated)" in res.stdout
    assert "cut short" in res.stderr and "replaying slots 1..1000" in res.stderr


def test_compare_prints_the_table_and_warns_about_other_instances(tmp_path, record_mcap):
    a, _, ra = record_mcap("ucb", horizon=1500)
    b, _, rb = record_mcap("ucb", instance="I2", horizon=1500)
    out = tmp_path / "cmp.rrd"
    res = run("compare", a, b, "-o", out)
    assert res.exit_code == 0, res.stderr
    assert "regret is not comparable" in res.stderr
    lines = res.stdout.splitlines()
    assert lines[0].split() == ["ucb-I1", "ucb-I2"]
    regret = next(line for line in lines if line.startswith("pathwise regret"))
    assert regret.split()[-2:] == [str(int(ra.regret[-1])), str(int(rb.regret[-1]))]
    best = next(line for line in lines if line.startswith("best arm"))
    assert best.split()[-2:] == ["2", "4"]
    assert out.exists() and f"Rerun recording: {out}" in res.stdout
    res = run("compare", a, b, "--no-rrd", "--json")
    assert res.exit_code == 0
    data = json.loads(res.stdout)
    assert data["path"] is None and [r["label"] for r in data["runs"]] == ["ucb-I1", "ucb-I2"]


def test_compare_writes_compare_rrd_by_default(tmp_path, record_mcap, monkeypatch):
    a, _, _ = record_mcap("ucb", horizon=1000)
    monkeypatch.chdir(tmp_path)
    res = run("compare", a)
    assert res.exit_code == 0, res.stderr
    assert (tmp_path / "compare.rrd").stat().st_size > 0


def test_recover_cli(tmp_path, record_mcap):
    path, _, _ = record_mcap("ts", horizon=3000)
    data = path.read_bytes()
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[: len(data) // 2])
    res = run("recover", broken, "-o", tmp_path / "fixed.mcap")
    assert res.exit_code == 0, res.stderr
    assert "recovered 1000 of 3000 slots (slots 1..1000)" in res.stdout
    assert "truncated" in res.stdout
    assert run("diff", broken, tmp_path / "fixed.mcap").exit_code == 0
    assert "already exists" in one_error_line(run("recover", broken, "-o", tmp_path / "fixed.mcap"))


# ---------------------------------------------------------------------------- logs only


def test_no_viewer_command_simulates(tmp_path, record_mcap, monkeypatch):
    a, _, _ = record_mcap("ucb", horizon=2000)
    b, _, _ = record_mcap("cucb", horizon=2000)
    import corraoi.engine.kernels
    import corraoi.engine.simulation
    import corraoi.rng

    def forbidden(*args, **kwargs):
        raise AssertionError("the simulation engine was called")

    for name in ("simulate", "simulate_run", "Simulation"):
        monkeypatch.setattr(corraoi.engine.simulation, name, forbidden)
    monkeypatch.setattr(corraoi.rng, "streams_for_seed", forbidden)
    monkeypatch.setattr(corraoi.engine.kernels, "kernel_for", forbidden)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(a.read_bytes()[:60_000])
    for args in (
        ["replay", a, "--rrd", tmp_path / "r.rrd"],
        ["replay", cut, "--rrd", tmp_path / "cut.rrd"],
        ["compare", a, b, "-o", tmp_path / "c.rrd"],
        ["compare", a, b, "--no-rrd", "--json"],
        ["info", a],
        ["info", cut, "--json"],
        ["recover", cut, "-o", tmp_path / "fixed.mcap"],
    ):
        res = run(*args)
        assert res.exit_code == 0, (args, res.stderr, res.exception)
    assert run("diff", a, b).exit_code == 1
    assert run("diff", a, a).exit_code == 0


def test_the_viewer_does_not_import_the_engine():
    code = (
        "import sys, corraoi.viewer, corraoi.viewer.compare, corraoi.viewer.replay, "
        "corraoi.viewer.diffs, corraoi.viewer.info, corraoi.viewer.recover, corraoi.cli.viewer, "
        "corraoi.recorder.slotlog.reader, corraoi.recorder.rerun.sink\n"
        "bad = sorted(m for m in ('corraoi.engine.simulation', 'corraoi.engine.kernels', 'numba') "
        "if m in sys.modules)\n"
        "print(','.join(bad))"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == ""


def test_an_unreachable_viewer_is_one_line_and_writes_nothing(tmp_path, record_mcap, monkeypatch):
    a, _, _ = record_mcap("ucb", horizon=1000)
    monkeypatch.chdir(tmp_path)
    with socket.socket() as s:  # a port where nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    line = one_error_line(run("replay", a, "--connect", str(port)), code=1)
    assert f"127.0.0.1:{port}" in line and "no Rerun viewer there" in line
    line = one_error_line(run("compare", a, "--connect", str(port)), code=1)
    assert "no Rerun viewer there" in line
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    line = one_error_line(run("replay", a, "--spawn"), code=1)
    assert "--spawn" in line and "no display" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == [a.name]


def test_a_log_with_no_complete_slot_is_refused(tmp_path, record_mcap):
    path, _, _ = record_mcap("cucb", horizon=3000)
    empty = tmp_path / "empty.mcap.partial"
    empty.write_bytes(path.read_bytes()[:5000])  # killed before the first chunk was written
    from corraoi.recorder.slotlog.reader import open_log

    assert open_log(empty).n_slots == 0
    for cmd, out in (
        (["replay", empty, "--rrd", tmp_path / "r.rrd"], tmp_path / "r.rrd"),
        (["compare", empty, path, "-o", tmp_path / "c.rrd"], tmp_path / "c.rrd"),
        (["recover", empty, "-o", tmp_path / "f.mcap"], tmp_path / "f.mcap"),
    ):
        line = one_error_line(run(*cmd))
        assert "no complete slot" in line and str(empty) in line
        assert not out.exists() and not list(tmp_path.glob("*.partial.*"))
    # info still describes it
    assert run("info", empty).exit_code == 0


def test_ctrl_c_in_replay_or_compare_leaves_no_half_written_rrd(tmp_path, record_mcap):
    import pytest

    from corraoi.viewer import compare, replay

    path, _, _ = record_mcap("cucb", horizon=3000)
    good = tmp_path / "out.rrd"
    good.write_bytes(b"an earlier, complete recording")

    def interrupt(n: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        replay(path, rrd_path=good, overwrite=True, on_block=interrupt)
    with pytest.raises(KeyboardInterrupt):
        compare([path, path], rrd_path=good, overwrite=True, on_block=interrupt)
    assert good.read_bytes() == b"an earlier, complete recording"
    assert not list(tmp_path.glob("*.partial"))


def test_a_sweep_log_is_named_as_such(tmp_path):
    out = tmp_path / "s"
    assert run("sweep", "-p", "ucb", "-n", "2", "-T", "50", "-o", out).exit_code == 0
    for cmd in (["info", out / "sweep.mcap"], ["replay", out / "sweep.mcap"]):
        line = one_error_line(run(*cmd))
        assert "a corraoi sweep log" in line and "corraoi figure" in line
