"""Adversarial command lines: hostile names, huge numbers, hostile outputs, the newcomer's path.

Each case asserts the exact outcome: the exit status, the one line on stderr, no traceback,
no file outside the output folder, and no finished run lost.
"""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from corraoi import limits
from corraoi.cli import main
from corraoi.engine.block import RunConfig
from corraoi.engine.simulation import simulate_run
from corraoi.files import partial as partial_file
from corraoi.files.locks import lock_holder
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.text import MAX_NAME, safe_name, safe_text

T = 1500


def cli(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_error(res, code: int = 2) -> str:
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output
    err = res.stderr
    assert err.count("\n") == 1 and err.startswith("corraoi: error: "), err
    return err.strip()


def files_under(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() or p.is_symlink()}


# ------------------------------------------------------------------ names are data


HOSTILE = {
    "traversal": "../../x",
    "absolute": "/etc/passwd",
    "nested": "a/b/c",
    "dotdot": "..",
    "ansi": "\x1b[31mred\x1b[0m",
    "newline": "two\nlines",
    "bidi": "abc\u202egpj.exe",
    "empty": "",
    "long": "n" * 300,
    "nul-like": "a\x00b",
}


@pytest.mark.parametrize("name", list(HOSTILE.values()), ids=list(HOSTILE))
def test_a_hostile_instance_name_stays_in_the_output_folder(tmp_path, monkeypatch, name):
    work = tmp_path / "work"
    work.mkdir()
    spec = tmp_path / "inst.json"
    spec.write_text(json.dumps({"name": name, **{k: v for k, v in _I1().items()}}))
    monkeypatch.chdir(work)
    res = cli("record", "-i", spec, "-T", T, "--no-rrd")
    assert res.exit_code == 0, res.output
    expected = f"runs/{safe_name(f'cucb-{name}-s0')}.mcap"
    assert files_under(tmp_path) == {"inst.json", f"work/{expected}"}
    assert "/" not in expected.removeprefix("runs/") and len(Path(expected).name) <= 125
    assert "\x1b" not in res.output and "\u202e" not in res.output
    info = cli("info", work / expected)
    assert info.exit_code == 0 and "\x1b" not in info.output and "\u202e" not in info.output
    if name:
        assert safe_text(name) in info.output


def _I1() -> dict:
    return {
        "p": [0.2, 0.3, 0.3, 0.2],
        "Y": [[1, 0, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [0, 0, 0, 1]],
    }


def _hash(name: str) -> str:
    import hashlib
    import unicodedata

    return hashlib.sha256(unicodedata.normalize("NFC", name).encode()).hexdigest()[:8]


@pytest.mark.parametrize(
    ("raw", "safe"),
    [
        ("../../x", "__.._x-{h}"),
        ("cucb-I1-s0", "cucb-I1-s0"),
        ("a b/c", "a_b_c-{h}"),
        (".hidden", "_hidden-{h}"),
        ("\x1b[2J", "_2J-{h}"),
        ("", "_-{h}"),
        ("é", "é"),
        ("ucb-東京-s0", "ucb-東京-s0"),
        ("my plugin.py", "my_plugin-{h}.py"),
        ("x-0123abcd", "x-0123abcd-{h}"),  # looks hashed: hashed, so no lossy name gives it
    ],
)
def test_safe_name(raw, safe):
    assert safe_name(raw) == safe.format(h=_hash(raw))


def _named(name: str):
    from corraoi.model.instance import Instance

    return Instance(name, **_I1())


def test_two_unicode_instance_names_get_two_files(tmp_path, monkeypatch):
    import corraoi

    monkeypatch.chdir(tmp_path)
    tokyo = corraoi.record("ucb", _named("東京"), horizon=200, rrd=False)
    osaka = corraoi.record("ucb", _named("大阪"), horizon=200, rrd=False)
    assert (tokyo.path.name, osaka.path.name) == ("ucb-東京-s0.mcap", "ucb-大阪-s0.mcap")
    assert files_under(tmp_path) == {"runs/ucb-東京-s0.mcap", "runs/ucb-大阪-s0.mcap"}


def test_names_differing_only_in_replaced_characters_get_two_files(tmp_path, monkeypatch):
    import corraoi

    monkeypatch.chdir(tmp_path)
    names = ["a/b", "a\\b", "a b", "a\x00b", "a_b"]
    paths = {corraoi.record("ucb", _named(n), horizon=100, rrd=False).path for n in names}
    assert len(paths) == len(names) and all(p.parent.name == "runs" for p in paths)
    assert Path("runs/ucb-a_b-s0.mcap").resolve() in {p.resolve() for p in paths}


def test_one_name_in_nfc_or_nfd_is_one_file_name(tmp_path, monkeypatch):
    import unicodedata

    import corraoi

    nfc, nfd = "Zürich-é", unicodedata.normalize("NFD", "Zürich-é")
    assert nfc != nfd and safe_name(nfc) == safe_name(nfd) == nfc
    monkeypatch.chdir(tmp_path)
    run = corraoi.record("ucb", _named(nfd), horizon=100, rrd=False)
    assert os.listdir(tmp_path / "runs") == [f"ucb-{nfc}-s0.mcap"] and run.path.exists()


def test_a_long_cjk_name_is_at_most_255_bytes_and_keeps_apart(tmp_path, monkeypatch):
    import corraoi

    long = "東" * 300
    assert len(safe_name(long).encode()) <= MAX_NAME
    assert safe_name(long) != safe_name(long + "京") and safe_name(long) != safe_name(long[:-1])
    monkeypatch.chdir(tmp_path)
    run = corraoi.record("ucb", _named(long), horizon=100, rrd=False)
    assert len(run.path.name.encode()) <= 255 and run.path.name.startswith("ucb-東東")
    assert len(f"{run.path.name}.partial".encode()) <= 255


@pytest.mark.parametrize(
    ("raw", "shown"),
    [
        ("plain text", "plain text"),
        ("\x1b[31mred", "\\x1b[31mred"),
        ("a\nb", "a\\x0ab"),
        ("rtl\u202e", "rtl\\u202e"),
        ("bell\x07", "bell\\x07"),
    ],
)
def test_safe_text(raw, shown):
    assert safe_text(raw) == shown


def test_an_error_quoting_a_hostile_name_is_escaped(tmp_path):
    hostile = tmp_path / "\x1b]0;pwned\x07\x1b[31mx.json"
    err = one_line_error(cli("record", "-i", hostile, "-T", 10))
    assert "\x1b" not in err and "\x07" not in err
    assert "\\x1b]0;pwned\\x07\\x1b[31mx.json" in err


# ------------------------------------------------------------------ numeric limits

H = limits.MAX_HORIZON
LIMIT_CASES = [
    (("record", "-T", "0"), "'--horizon' / '-T': 0 is not in the range 1..4294967294"),
    (("record", "-T", str(H + 1)), f"'--horizon' / '-T': {H + 1} is not in the range 1..{H}"),
    (("record", "-T", "1e30"), "'--horizon' / '-T': '1e30' is not a valid integer"),
    (("record", "-T", str(2**64)), "'--horizon' / '-T': 18446744073709551616 is not in the range"),
    (("record", "-T", "9" * 400), "'--horizon' / '-T': 99999999999999999999... is not in the"),
    (("record", "--seed", "-1"), "'--seed' / '-s': -1 is not in the range 0..9223372036854775807"),
    (("record", "--seed", str(2**63)), "'--seed' / '-s': 9223372036854775808 is not in the range"),
    (("sweep", "--runs", str(10**10)), "'--runs' / '-n': 10000000000 is not in the range 1.."),
    (("sweep", "--runs", "0"), "'--runs' / '-n': 0 is not in the range 1..100000000"),
    (("sweep", "--checkpoints", "10000000"), "'--checkpoints': 10000000 is not in the range 2.."),
    (("sweep", "--workers", "0"), "'--workers' / '-j': 0 is not in the range 1..1024"),
    (("sweep", "--workers", "100000"), "'--workers' / '-j': 100000 is not in the range 1..1024"),
    (("record", "--web-port", "0"), "'--web-port': 0 is not in the range 1..65535 (a TCP port)"),
    (("record", "--web-port", "70000"), "'--web-port': 70000 is not in the range 1..65535"),
    (("reproduce", "--runs", "-5"), "'--runs' / '-n': -5 is not in the range 1..100000000"),
    (("sweep", "-T", "0.5"), "'--horizon' / '-T': '0.5' is not a valid integer"),
]


@pytest.mark.parametrize(
    ("args", "needle"), LIMIT_CASES, ids=[" ".join(a)[:40] for a, _ in LIMIT_CASES]
)
def test_numeric_options_are_range_checked(tmp_path, monkeypatch, args, needle):
    monkeypatch.chdir(tmp_path)
    err = one_line_error(cli(*args))
    assert err.startswith("corraoi: error: Invalid value for ") and needle in err, err
    assert files_under(tmp_path) == set()


def test_seed_plus_runs_must_fit_int64(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    err = one_line_error(cli("sweep", "--seed", limits.MAX_SEED, "--runs", 3, "-T", 10))
    assert err == (
        f"corraoi: error: --seed {limits.MAX_SEED}: out of range, expected "
        f"0..{limits.MAX_SEED - 2} (seeds are 64-bit and 3 runs use seed .. seed+2)"
    )


def test_a_sweep_too_big_for_memory_is_refused_before_allocating(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    err = one_line_error(cli("sweep", "--runs", limits.MAX_RUNS, "-T", 10, "-p", "ucb"))
    assert err.startswith(f"corraoi: error: --runs {limits.MAX_RUNS}: a sweep of ")
    assert "of memory, more than half of this machine's" in err


def test_the_largest_horizon_cannot_overflow_the_aoi_sum():
    T = limits.MAX_HORIZON
    assert T * (T + 3) // 2 <= 2**63 - 1 < (T + 1) * (T + 4) // 2
    assert limits.check_horizon(T) == T
    with pytest.raises(limits.ConfigError, match="expected 1..4294967294"):
        limits.check_horizon(T + 1)


# ------------------------------------------------------------------ outputs and locks


def _config(horizon: int = T) -> RunConfig:
    return RunConfig(load_instance("I1"), make_policy("cucb"), 0, horizon)


def test_force_never_touches_a_file_another_writer_holds(tmp_path):
    out = tmp_path / "run.mcap"
    config = _config()
    with McapSink(out, config, fsync=False) as sink:
        blocks = list(simulate_run(config.instance, config.policy, 0, T))
        sink.write(blocks[0])
        err = one_line_error(cli("record", "-T", T, "--no-rrd", "-o", out, "--force"))
        assert err == (
            f"corraoi: error: {out}.partial: is being written by process {os.getpid()} right "
            "now; not touched (wait for it, stop it, or give another output path)"
        )
        for b in blocks[1:]:
            sink.write(b)
    run = open_log(out)
    assert run.status == "complete" and run.n_slots == T  # the first writer's run is whole
    assert not (tmp_path / "run.mcap.partial").exists()


def test_a_second_writer_is_refused_naming_the_holders_pid(tmp_path):
    part = tmp_path / "run.mcap.partial"
    code = (
        "import sys, time; from corraoi.files.partial import PartialFile;"
        f"f = PartialFile({str(tmp_path / 'run.mcap')!r}).create();"
        "print('locked', flush=True); time.sleep(60)"
    )
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        assert lock_holder(part) == holder.pid
        err = one_line_error(cli("record", "-T", 10, "--no-rrd", "-o", tmp_path / "run.mcap", "-f"))
        assert f"{part}: is being written by process {holder.pid} right now" in err
    finally:
        holder.kill()
        holder.wait()
    assert lock_holder(part) is None  # the lock died with its process: no stale lock
    res = cli("record", "-T", 10, "--no-rrd", "-o", tmp_path / "run.mcap", "-f")
    assert res.exit_code == 0, res.output
    assert sorted(os.listdir(tmp_path)) == ["run.mcap"]  # no lock file beside it


@pytest.mark.parametrize("kind", ["dangling-link", "fifo", "parent-is-file", "partial-link"])
def test_hostile_output_paths_are_one_line(tmp_path, kind):
    out = tmp_path / "run.mcap"
    if kind == "dangling-link":
        out.symlink_to(tmp_path / "nowhere" / "x.mcap")
        want = (f"{out}: is a symbolic link to {tmp_path / 'nowhere' / 'x.mcap'}, which does "
                "not exist; remove the link or give another path for the MCAP log")  # fmt: skip
    elif kind == "fifo":
        os.mkfifo(out)
        want = (f"{out}: is not a regular file (a device, FIFO or socket); give a file path "
                "for the MCAP log")  # fmt: skip
    elif kind == "parent-is-file":
        (tmp_path / "file").write_text("x")
        out = tmp_path / "file" / "run.mcap"
        want = f"{out}: {tmp_path / 'file'} is not a directory"
    else:
        (tmp_path / "run.mcap.partial").symlink_to(tmp_path / "elsewhere")
        want = (f"{out}.partial: is a symbolic link to {tmp_path / 'elsewhere'}, which does "
                "not exist; remove the link or give another path for the MCAP log")  # fmt: skip
    before = files_under(tmp_path)
    err = one_line_error(cli("record", "-T", 10, "--no-rrd", "-o", out, "--force"))
    assert err == f"corraoi: error: {want}"
    assert files_under(tmp_path) == before


class _FullDisk:
    """A file object that takes ``room`` bytes and then fails as a full disk does."""

    def __init__(self, f, room: int) -> None:
        self.f, self.room = f, room

    def write(self, data) -> int:
        if len(data) > self.room:
            self.f.write(bytes(data)[: self.room])
            self.room = 0
            self.f.flush()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.room -= len(data)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


@pytest.mark.parametrize("room", [30_000, 120_000])
def test_a_full_disk_is_one_line_and_keeps_the_partial_readable(tmp_path, monkeypatch, room):
    real = partial_file.fdopen  # the seam where PartialFile opens its file
    monkeypatch.setattr(partial_file, "fdopen", lambda fd: _FullDisk(real(fd), room))
    out = tmp_path / "run.mcap"
    err = one_line_error(cli("record", "-T", 6000, "--no-rrd", "-o", out), code=1)
    part = tmp_path / "run.mcap.partial"
    assert err == (
        f"corraoi: error: {part}: cannot write the MCAP log: No space left on device "
        f"(the unfinished log is left as {part})"
    )
    assert not out.exists()
    kept = open_log(part)
    assert kept.status == "truncated" and kept.n_slots % 1000 == 0
    assert len(kept.read_all()) == kept.n_slots


@pytest.fixture
def small_tmpfs(tmp_path):
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=96k", "tmpfs", str(mnt)],
                         capture_output=True)  # fmt: skip
    if res.returncode != 0:
        pytest.skip("cannot mount a tmpfs here")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_real_full_disk(small_tmpfs):
    out = small_tmpfs / "run.mcap"
    err = one_line_error(cli("record", "-T", 20_000, "--no-rrd", "-o", out), code=1)
    part = small_tmpfs / "run.mcap.partial"
    assert err.startswith(f"corraoi: error: {part}: cannot write the MCAP log: No space left")
    assert not out.exists() and open_log(part).status == "truncated"


def test_a_read_only_folder(small_tmpfs):
    subprocess.run(["mount", "-o", "remount,ro", str(small_tmpfs)], check=True)
    out = small_tmpfs / "run.mcap"
    err = one_line_error(cli("record", "-T", 10, "--no-rrd", "-o", out))
    assert err == f"corraoi: error: {out}: the folder {small_tmpfs} is not writable"


# ------------------------------------------------------------------ the newcomer's path


def test_the_quick_start_twice_is_up_to_date(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    first = cli("record", "--policy", "cucb", "-T", T, "--no-rrd")
    assert first.exit_code == 0, first.output
    stamp = (tmp_path / "runs/cucb-I1-s0.mcap").stat().st_mtime_ns
    again = cli("record", "--policy", "cucb", "-T", T, "--no-rrd")
    assert again.exit_code == 0, again.output
    assert again.stdout == (
        "up to date: runs/cucb-I1-s0.mcap holds this run (same configuration, complete); "
        "use --force to record it again\n"
    )
    assert (tmp_path / "runs/cucb-I1-s0.mcap").stat().st_mtime_ns == stamp
    other = cli("record", "--policy", "cucb", "-T", T + 1, "--no-rrd")
    assert one_line_error(other) == (
        "corraoi: error: runs/cucb-I1-s0.mcap: already exists and holds another run (its "
        f"horizon is {T}, here {T + 1}); use --force to overwrite it"
    )


@pytest.mark.parametrize(
    ("args", "written"),
    [
        (("record", "-T", 20, "--no-rrd", "--out", "a.mcap"), "a.mcap"),
        (("record", "-T", 20, "--no-rrd", "--output", "b.mcap"), "b.mcap"),
        (("replay", "LOG", "--rrd", "c.rrd"), "c.rrd"),
        (("replay", "LOG", "-o", "d.rrd"), "d.rrd"),
        (("compare", "LOG", "LOG", "--out", "e.rrd"), "e.rrd"),
        (("recover", "LOG", "--out", "f.mcap"), "f.mcap"),
    ],
)
def test_old_output_spellings_are_hidden_aliases(tmp_path, monkeypatch, args, written):
    monkeypatch.chdir(tmp_path)
    assert cli("record", "-T", 20, "--no-rrd", "-o", "log.mcap").exit_code == 0
    res = cli(*["log.mcap" if a == "LOG" else a for a in args])
    assert res.exit_code == 0, res.output
    assert (tmp_path / written).is_file()


def test_two_spellings_of_one_output_are_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    err = one_line_error(cli("record", "-T", 20, "--out", "a.mcap", "-o", "b.mcap"))
    assert err == ("corraoi: error: -o/--output and --out: give the output once (see "
                   "'corraoi record --help')")  # fmt: skip
    assert files_under(tmp_path) == set()
    help_text = cli("replay", "--help").output
    assert "-o, --output OUT.rrd" in help_text and "--rrd" not in help_text


def test_recover_defaults_beside_the_partial_and_prints_json(tmp_path):
    config = _config(2500)
    with McapSink(tmp_path / "run.mcap", config, fsync=False) as sink:
        for b in simulate_run(config.instance, config.policy, 0, 2500):
            sink.write(b)
    data = (tmp_path / "run.mcap").read_bytes()
    (tmp_path / "run.mcap").unlink()
    (tmp_path / "run.mcap.partial").write_bytes(data[: len(data) // 2])
    res = cli("recover", tmp_path / "run.mcap.partial", "--json")
    assert res.exit_code == 0, res.output
    done = json.loads(res.stdout)
    assert done["output"] == str(tmp_path / "run.recovered.mcap")
    assert done["source_status"] == "truncated" and done["status"] == "interrupted"
    assert open_log(tmp_path / "run.recovered.mcap").n_slots == done["slots"] > 0


def test_replay_prints_json(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli("record", "-T", 300, "--no-rrd", "-o", "log.mcap").exit_code == 0
    res = cli("replay", "log.mcap", "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == {
        "log": "log.mcap", "label": "cucb-I1-s0", "slots": 300, "horizon": 300,
        "status": "complete", "rrd": "log.rrd", "viewer": None,
    }  # fmt: skip


def test_python_dash_m_corraoi(tmp_path):
    res = subprocess.run([sys.executable, "-m", "corraoi", "--version"], capture_output=True,
                         text=True, cwd=tmp_path, timeout=60)  # fmt: skip
    assert res.returncode == 0 and res.stdout.startswith("corraoi, version ")


def test_sweep_force_never_clears_a_folder_another_sweep_is_writing(tmp_path):
    out = tmp_path / "sw"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    held = partial_file.PartialFile(out / "sweep.mcap").create()
    try:
        err = one_line_error(cli("sweep", "-n", 2, "-T", 10, "-p", "ucb", "-o", out, "--force"))
        assert err == (
            f"corraoi: error: {out / 'sweep.mcap.partial'}: is being written by process "
            f"{os.getpid()} right now; not touched (wait for it, stop it, or give another "
            "output folder)"
        )
        assert sorted(os.listdir(out)) == ["summary.json", "sweep.mcap.partial"]
    finally:
        held.leave()


def test_only_the_runs_that_are_not_up_to_date_are_recorded(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli("record", "-p", "ucb", "-T", 200, "--no-rrd").exit_code == 0
    stamp = (tmp_path / "runs/ucb-I1-s0.mcap").stat().st_mtime_ns
    res = cli("record", "-p", "ucb,cucb", "-T", 200, "--no-rrd", "--json")
    assert res.exit_code == 0, res.output
    assert res.stderr.startswith("up to date: runs/ucb-I1-s0.mcap holds this run")
    assert [r["label"] for r in json.loads(res.stdout)["runs"]] == ["cucb-I1-s0"]
    assert (tmp_path / "runs/ucb-I1-s0.mcap").stat().st_mtime_ns == stamp
    again = cli("record", "-p", "ucb,cucb", "-T", 200, "--no-rrd", "--json")
    assert again.exit_code == 0 and json.loads(again.stdout) == {
        "runs": [], "up_to_date": ["runs/ucb-I1-s0.mcap", "runs/cucb-I1-s0.mcap"]
    }  # fmt: skip


def test_the_sweep_memory_estimate_grows_with_runs_policies_and_checkpoints():
    base = limits.sweep_memory(1000, 4)
    assert limits.sweep_memory(2000, 4) == 2 * base
    assert limits.sweep_memory(1000, 4, policies=12) > base
    assert limits.sweep_memory(1000, 4, checkpoints=200) > limits.sweep_memory(1000, 4)
    assert limits.check_sweep_memory(1000, 4, available=10 * base) == base
    with pytest.raises(limits.ConfigError, match=r"--runs 1000: a sweep of 1000 runs on 4 arms"):
        limits.check_sweep_memory(1000, 4, available=base)


def test_reproduce_and_figure_print_json(tmp_path):
    out = tmp_path / "paper"
    res = cli("reproduce", "-o", out, "-n", 2, "-T", 100, "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["output"] == str(out) and sorted(data["instances"]) == ["I1", "I2"]
    assert data["instances"]["I2"]["runs"] == 2 and data["instances"]["I2"]["horizon"] == 100
    pytest.importorskip("matplotlib")
    fig = cli("figure", out / "I1" / "sweep.mcap", "-o", tmp_path / "f.png", "--json",
              "--policies", "ucb,cucb")  # fmt: skip
    assert fig.exit_code == 0, fig.output
    assert json.loads(fig.stdout) == {
        "output": str(tmp_path / "f.png"), "sweep": str(out / "I1" / "sweep.mcap"),
        "policies": ["ucb", "cucb"], "instance": "I1", "runs": 2, "horizon": 100,
        "complete": True,
    }  # fmt: skip


@pytest.mark.parametrize("args", [["policies"], ["instance", "show", "I1"],
                                  ["record", "-T", "100", "--no-rrd", "-o", "p.mcap"]],
                         ids=["policies", "instance", "record"])  # fmt: skip
def test_a_reader_that_stops_reading_is_not_an_error(tmp_path, args):
    """`corraoi policies | head -1`: the reader goes away; no error line, exit 141 (as a
    tool that SIGPIPE ended), and what was being written is still finished."""
    proc = subprocess.Popen([sys.executable, "-m", "corraoi.cli", *args], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # before the command writes its first line
    err = proc.stderr.read().decode()
    assert (proc.wait(timeout=120), err) == (141, "")
    if args[0] == "record":
        from corraoi.recorder.slotlog.reader import open_log

        assert open_log(tmp_path / "p.mcap").status == "complete"


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_on_stdout_is_still_an_error(tmp_path):
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "corraoi.cli", "policies"], stdout=full,
                              stderr=subprocess.PIPE, text=True, timeout=60)  # fmt: skip
    assert proc.returncode == 1 and proc.stderr.startswith("corraoi: error: No space left")
