"""Adversarial logs: lying messages, flipped bytes, special files. Each gets one line and exit 2.

Lying logs are made by rewriting valid slot messages (the real writer, with one message
edited on its way to the file); damaged logs by flipping bytes of a finished one.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.engine.block import RunConfig
from corraoi.engine.simulation import simulate_run
from corraoi.errors import LogError
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.encode import BlockEncoder
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink

T = 2500
EDIT_SLOT = 1500  # in the second chunk (slots 1001..2000)


def cli(*args: str):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_line_error(res, code: int = 2) -> str:
    """The single stderr line of a refused command, checked for shape."""
    assert res.exit_code == code, res.output
    assert (
        "Traceback" not in res.output
        and res.exception is None
        or isinstance(res.exception, SystemExit)
    )
    err = res.stderr
    assert err.count("\n") == 1 and err.startswith("corraoi: error: "), err
    assert "\x1b" not in err
    return err.strip()


def _config(horizon: int = T) -> RunConfig:
    return RunConfig(load_instance("I1"), make_policy("cucb"), 0, horizon)


class _Editing(BlockEncoder):
    """The writer's encoder, with the message of one slot rewritten."""

    def __init__(self, K: int, edit) -> None:
        super().__init__(K)
        self.edit = edit

    def encode(self, b):  # type: ignore[override]
        out = super().encode(b)
        for i, t in enumerate(b.t.tolist()):
            if t == EDIT_SLOT:
                out[i] = self.edit(out[i])
        return out

    def encode_framed(self, b, room):  # type: ignore[override]
        return bytearray(b"".join(room + m for m in self.encode(b)))  # what McapSink asks


def write_log(path: Path, edit=None, horizon: int = T) -> Path:
    config = _config(horizon)
    with McapSink(path, config, fsync=False) as sink:
        if edit is not None:
            sink._encoder = _Editing(config.instance.K, edit)
        for block in simulate_run(config.instance, config.policy, 0, horizon):
            sink.write(block)
    return path


def set_field(name: str, value):
    def edit(data: bytes) -> bytes:
        msg = json.loads(data)
        msg[name] = value
        return json.dumps(msg, separators=(",", ":")).encode()

    return edit


def raw(text: bytes):
    return lambda data: text


# (case id, edit, the tail of the one-line message)
LIES = [
    (
        "success-string",
        set_field("success", "no"),
        'success is "no" (a string), expected a JSON bool (true or false)',
    ),
    ("success-int", set_field("success", 1), "success is 1, expected a JSON bool (true or false)"),
    (
        "override-null",
        set_field("override", None),
        "override is null, expected a JSON bool (true or false)",
    ),
    ("x-zero", set_field("x", 0), "x is 0, expected an integer in 1..4"),
    ("x-too-big", set_field("x", 5), "x is 5, expected an integer in 1..4"),
    ("arm-too-big", set_field("arm", 99), "arm is 99, expected an integer in 1..4"),
    (
        "arm-float",
        set_field("arm", 2.5),
        "arm is 2.5 (a number with a fraction), expected an integer (int64)",
    ),
    ("arm-bool", set_field("arm", True), "arm is true (a bool), expected a number, not a bool"),
    ("aoi-zero", set_field("aoi", 0), "aoi is 0, expected an integer >= 1"),
    (
        "aoi-beyond-int64",
        set_field("aoi", 2**63),
        "aoi is 9223372036854775808 (outside the 64-bit integer range), "
        "expected an integer (int64)",
    ),
    (
        "regret-beyond-uint64",
        set_field("regret", 2**70),
        "regret is 1.18059e+21 (outside the 64-bit integer range), expected an integer (int64)",
    ),
    (
        "regret-below-int64",
        set_field("regret", -(2**63) - 1),
        "regret is -9.22337e+18 (outside the 64-bit integer range), expected an integer (int64)",
    ),
    (
        "estimator-string",
        set_field("estimator", "1.5"),
        'estimator is "1.5" (a string), expected a number',
    ),
    (
        "mu-hat-above-one",
        set_field("mu_hat", [0.5, 1.5, 0.0, 0.0]),
        "mu_hat[2] is 1.5, expected a value in [0, 1]",
    ),
    (
        "mu-hat-short",
        set_field("mu_hat", [0.5]),
        "mu_hat is a list of 1 items, expected a list of 4 numbers (one per arm)",
    ),
    ("pulls-negative", set_field("pulls", [1, -1, 0, 0]), "pulls[2] is -1, expected a value >= 0"),
    (
        "pulls-float",
        set_field("pulls", [1, 2.5, 0, 0]),
        "pulls[2] is 2.5 (a number with a fraction), expected integers >= 0",
    ),
    (
        "pulls-bool",
        set_field("pulls", [1, True, 0, 0]),
        "pulls is true (a bool), expected a number, not a bool",
    ),
    (
        "candidates-out-of-range",
        set_field("candidates", [0]),
        "candidates is 0, expected arms in 1..4",
    ),
    (
        "candidates-duplicate",
        set_field("candidates", [2, 2]),
        "candidates is [2, 2], expected distinct arms",
    ),
    (
        "candidates-empty",
        set_field("candidates", []),
        "candidates is a list of 0 items, expected a list of 1..4 distinct arms",
    ),
]


@pytest.mark.parametrize(("edit", "tail"), [c[1:] for c in LIES], ids=[c[0] for c in LIES])
def test_a_lying_slot_is_one_line_naming_file_and_slot(tmp_path, edit, tail):
    log = write_log(tmp_path / "lie.mcap", edit)
    err = one_line_error(cli("info", log))
    assert err.startswith(f"corraoi: error: {log}: chunk at byte ")
    assert err.endswith(f": slot {EDIT_SLOT}: {tail}"), err


@pytest.mark.parametrize(
    ("edit", "tail"),
    [
        (set_field("t", "x"), ': t is "x" (a string), expected an integer (int64)'),
        (raw(b'{"t":1500,'), "is not valid JSON"),
        (raw(b"[1,2,3]"), "is a list of 3 items, expected a JSON object"),
        (
            set_field("extra", 1),
            "has extra keys ['extra']; expected exactly the fields t, x, arm, "
            "success, aoi, oracle_aoi, regret, estimator, override, mu_hat, pulls, candidates",
        ),
        (raw(b'{"t":1500,"x":1e999}'), "is not valid JSON"),
    ],
    ids=["t-string", "torn-json", "not-an-object", "extra-key", "infinite-number"],
)
def test_a_malformed_message_is_one_line(tmp_path, edit, tail):
    log = write_log(tmp_path / "bad.mcap", edit)
    err = one_line_error(cli("info", log))
    assert err.startswith(f"corraoi: error: {log}: chunk at byte ") and tail in err, err


@pytest.mark.parametrize("command", ["replay", "diff", "compare"])
def test_values_beyond_int64_are_one_line_in_every_reader(tmp_path, command):
    bad = write_log(tmp_path / "big.mcap", set_field("regret", 2**64))
    good = write_log(tmp_path / "good.mcap")
    args = {
        "replay": ("replay", bad, "-o", tmp_path / "r.rrd"),
        "diff": ("diff", good, bad),
        "compare": ("compare", good, bad, "--no-rrd"),
    }[command]
    err = one_line_error(cli(*args))
    assert f"slot {EDIT_SLOT}: regret is 1.84467e+19 (outside the 64-bit integer range)" in err
    assert not (tmp_path / "r.rrd").exists() and not (tmp_path / "r.rrd.partial").exists()


# ------------------------------------------------------------------ flipped bytes


def _chunks(path: Path) -> list[int]:
    """Byte offsets of the chunk records of a log."""
    data = path.read_bytes()
    pos, out = 8, []
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == 0x06:
            out.append(pos)
        if op == 0x02:
            break
        pos += 9 + length
    return out


def _flip(path: Path, offset: int, value: bytes) -> None:
    data = bytearray(path.read_bytes())
    data[offset : offset + len(value)] = value
    path.write_bytes(bytes(data))


@pytest.mark.parametrize(
    ("where", "value", "tail"),
    [
        ("crc", b"\x00\x00\x00\x01", "is damaged (CRC mismatch)"),
        ("length", struct.pack("<Q", 2**40), "past the end of the file"),
        ("usize", struct.pack("<Q", 2**50), "claims 1125899906842624 bytes uncompressed"),
        ("data", b"\xff\xff\xff\xff", "is damaged (zstd:"),
        ("opcode", b"\x00", "unknown MCAP record opcode 0x00"),
        ("compression", b"zzzz", "unknown compression 'zzzz'"),
    ],
)
def test_a_damaged_finished_log_is_damage_not_a_killed_writer(tmp_path, where, value, tail):
    log = write_log(tmp_path / "run.mcap")
    second = _chunks(log)[1]
    offset = {
        "crc": second + 9 + 24,
        "length": second + 1,
        "usize": second + 9 + 16,
        "data": second + 9 + 28 + 4 + 8 + 40,
        "opcode": second,
        "compression": second + 9 + 28 + 4,
    }[where]
    _flip(log, offset, value)
    err = one_line_error(cli("info", log))
    assert str(log) in err and tail in err, err
    assert f"byte {second}" in err
    assert "killed" not in err and "cut short" not in err


def test_a_torn_tail_is_cut_short_not_damage(tmp_path):
    log = write_log(tmp_path / "run.mcap")
    third = _chunks(log)[2]
    part = tmp_path / "run.mcap.partial"
    part.write_bytes(log.read_bytes()[: third + 50])
    res = cli("info", part, "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert (data["status"], data["slots"], data["finished"]) == ("truncated", 2000, False)


@pytest.mark.parametrize("where", ["crc", "json"])
def test_recover_salvages_the_slots_before_the_damage(tmp_path, where):
    if where == "crc":
        log = write_log(tmp_path / "run.mcap")
        _flip(log, _chunks(log)[2] + 9 + 24, b"\x01\x02\x03\x04")
        kept, tail = 2000, "is damaged (CRC mismatch)"
    else:
        log = write_log(tmp_path / "run.mcap", set_field("x", 9))
        kept, tail = 1000, f"slot {EDIT_SLOT}: x is 9, expected an integer in 1..4"
    res = cli("recover", log, "--json")
    assert res.exit_code == 0, res.output
    done = json.loads(res.stdout)
    out = tmp_path / "run.recovered.mcap"
    assert done["output"] == str(out) and done["slots"] == kept
    assert done["source_status"] == "damaged" and tail in done["damage"]
    fixed = open_log(out)
    assert fixed.n_slots == kept and fixed.finished and fixed.status == "interrupted"
    assert len(fixed.read_all()) == kept


@pytest.mark.parametrize("kind", ["fifo", "dev-zero", "directory", "empty", "socket-like-dev"])
def test_special_files_as_logs_are_refused_at_once(tmp_path, kind):
    target = tmp_path / "thing.mcap"
    tail = {
        "fifo": "is a FIFO, not a regular file; expected an MCAP log file",
        "dev-zero": "is a device, not a regular file; expected an MCAP log file",
        "directory": "is a directory, expected an MCAP log file",
        "empty": "empty file (0 bytes), not an MCAP log",
        "socket-like-dev": "is a device, not a regular file; expected an MCAP log file",
    }[kind]
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "dev-zero":
        target.symlink_to("/dev/zero")
    elif kind == "socket-like-dev":
        target.symlink_to("/dev/null")
    elif kind == "directory":
        target.mkdir()
    else:
        target.write_bytes(b"")
    err = one_line_error(cli("info", target))
    assert err == f"corraoi: error: {target}: {tail}"


def test_open_log_raises_log_error_not_overflow(tmp_path):
    log = write_log(tmp_path / "big.mcap", set_field("aoi", 2**64 + 5))
    run = open_log(log)
    with pytest.raises(LogError, match=f"slot {EDIT_SLOT}: aoi is .*outside the 64-bit"):
        run.read_all()


def test_info_on_a_missing_log_points_to_its_partial(tmp_path):
    log = write_log(tmp_path / "run.mcap")
    part = tmp_path / "gone.mcap.partial"
    part.write_bytes(log.read_bytes()[:-200])
    err = one_line_error(cli("info", tmp_path / "gone.mcap"))
    assert err == (
        f"corraoi: error: {tmp_path / 'gone.mcap'}: no such file, but {part} is there (a "
        f"writer that did not finish, or one still writing): read it with `corraoi info "
        f"{part}`, finish it with `corraoi recover {part}`"
    )


def test_info_on_a_log_being_written_names_its_writer(tmp_path):
    config = _config()
    blocks = list(simulate_run(config.instance, config.policy, 0, T))
    # chunks written before write() returns (a background writer's last chunk may still be
    # on its way when info reads)
    with McapSink(tmp_path / "live.mcap", config, fsync=False, background=False) as sink:
        for b in blocks[:2]:
            sink.write(b)
        res = cli("info", tmp_path / "live.mcap.partial", "--json")
        assert res.exit_code == 0, res.output
        data = json.loads(res.stdout)
        assert data["description"] == (
            f"being written right now by process {os.getpid()}: 2000 of {T} slots so far, up "
            "to the last complete chunk"
        )
        for b in blocks[2:]:
            sink.write(b)
    assert open_log(tmp_path / "live.mcap").writer is None


@pytest.mark.parametrize(
    ("old", "new", "tail"),
    [
        (b'"seed": 0,', b'"seed": 7,', "seed is '0' in its own field but '7' in the configuration"),
        (
            b"horizon\x04\x00\x00\x002500",
            b"horizon\x04\x00\x00\x002501",
            "horizon is '2501' in its own field but '2500' in the configuration",
        ),
    ],
    ids=["config-seed", "flat-horizon"],
)
def test_a_flipped_digit_in_the_run_metadata_is_damage(tmp_path, old, new, tail):
    log = write_log(tmp_path / "run.mcap")
    data = log.read_bytes()
    assert data.count(old) == 1
    log.write_bytes(data.replace(old, new))
    err = one_line_error(cli("info", log))
    assert err == f"corraoi: error: {log}: damaged run metadata: {tail}; expected both to agree"


@pytest.mark.parametrize("seed", range(12))
def test_random_byte_flips_never_give_a_traceback(tmp_path, seed):
    import random

    rng = random.Random(seed)
    log = write_log(tmp_path / "run.mcap", horizon=1200)
    data = bytearray(log.read_bytes())
    for _ in range(rng.choice([1, 2, 4])):
        data[rng.randrange(len(data))] = rng.randrange(256)
    if seed % 3 == 0:
        data = data[: rng.randrange(len(data))]
    log.write_bytes(bytes(data))
    for args in (("info", log), ("recover", log, "-o", tmp_path / "fixed.mcap", "-f")):
        res = cli(*args)
        assert res.exit_code in (0, 2), res.output
        assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
        if res.exit_code == 2:
            one_line_error(res)
        elif args[0] == "recover":  # what recover wrote reads back as a finished log
            assert open_log(tmp_path / "fixed.mcap").finished


def _rewritten(src: Path, dest: Path, *, metadata=None, attachment=None) -> Path:
    """``src`` copied record by record (mcap's writer), with metadata records replaced by
    ``metadata(name, dict)`` and an attachment added (name, bytes, CRC broken or not)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        metas = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        summary = reader.get_summary()
        assert summary is not None
        messages = list(reader.iter_messages())
    with open(dest, "wb") as out:
        w = Writer(out)
        w.start(profile=header.profile, library=header.library)
        for name, md in metas:
            w.add_metadata(name, metadata(name, md) if metadata else md)
        if attachment is not None:
            w.add_attachment(0, 0, attachment[0], "text/x-python", attachment[1])
        ids = {}
        for sid, schema in summary.schemas.items():
            ids[sid] = w.register_schema(schema.name, schema.encoding, schema.data)
        chans = {cid: w.register_channel(c.topic, c.message_encoding, ids[c.schema_id],
                                         dict(c.metadata)) for cid, c in summary.channels.items()}
        for _, channel, message in messages:
            w.add_message(chans[channel.id], message.log_time, message.data,
                          message.publish_time, message.sequence)
        w.finish()
    return dest


@pytest.mark.parametrize("config", ["[" * 100_000, '{"instance": [1, 2], "policy": 3}',
                                    '{"instance": {"p": "x"}}', "null"])  # fmt: skip
def test_a_hostile_run_configuration_is_one_line(tmp_path, config):
    good = write_log(tmp_path / "good.mcap", horizon=50)

    def edit(name, md):
        return {**md, "config": config} if name == "corraoi.run" else md

    bad = _rewritten(good, tmp_path / "bad.mcap", metadata=edit)
    err = one_line_error(cli("info", bad))
    assert "the run configuration in the log is unusable" in err


def test_a_hostile_provenance_record_is_shown_as_far_as_it_reads(tmp_path):
    good = write_log(tmp_path / "good.mcap", horizon=50)

    def edit(name, md):
        if name != "corraoi.provenance":
            return md
        return {**md, "plugins": "[" * 50_000, "notes": "{\"a\": 1}", "git": "\x1b[2J"}

    bad = _rewritten(good, tmp_path / "bad.mcap", metadata=edit)
    res = cli("info", bad)
    assert res.exit_code == 0, res.output
    assert "\x1b" not in res.output and "code                   corraoi" in res.output


def test_an_attachment_with_a_broken_crc_is_damage(tmp_path):
    good = write_log(tmp_path / "good.mcap", horizon=50)
    bad = _rewritten(good, tmp_path / "bad.mcap", attachment=("evil.py", b"print('hi')\n"))
    data = bytearray(bad.read_bytes())
    at = bytes(data).index(b"print('hi')")
    data[at] ^= 0x01  # a byte of the attached source flipped: its CRC no longer holds
    bad.write_bytes(bytes(data))
    err = one_line_error(cli("info", bad))
    assert "damaged" in err and str(bad) in err
