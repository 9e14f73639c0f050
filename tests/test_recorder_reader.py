"""The log reader: blocks back, cut-short logs recovered, bad files refused in one line."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from corraoi.errors import LogError, UsageError
from corraoi.recorder.slotlog.encode import run_metadata
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.vocab import RUN_METADATA, SLOT_FORMAT_VERSION


@pytest.mark.parametrize("size", [1, 7, 1000, 4096])
def test_blocks_of_any_size_give_the_same_slots(record_mcap, size):
    path, _, ref = record_mcap("ts-gauss", horizon=2600)
    log = open_log(path)
    blocks = list(log.blocks(block=size))
    assert [len(b) for b in blocks[:-1]] == [size] * (len(blocks) - 1)
    assert 0 < len(blocks[-1]) <= size
    assert sum(len(b) for b in blocks) == 2600
    assert np.array_equal(np.concatenate([b.t for b in blocks]), np.arange(1, 2601))
    assert log.read_all().equals(ref)


def test_open_without_verifying_agrees(record_mcap):
    path, _, ref = record_mcap(horizon=3001)
    fast, full = open_log(path, verify=False), open_log(path)
    assert fast.n_slots == full.n_slots == 3001 and fast.n_chunks == full.n_chunks == 4
    assert fast.read_all().equals(ref)


def test_a_log_cut_anywhere_is_read_up_to_its_last_complete_chunk(record_mcap, tmp_path):
    path, _, ref = record_mcap(horizon=5000)
    data = path.read_bytes()
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    ends = sorted(c.chunk_start_offset + c.chunk_length for c in chunks)
    assert len(ends) == 5
    cut = tmp_path / "cut.mcap"
    offsets = sorted({*range(0, len(data), 2999), *(e - 1 for e in ends), *ends, len(data) - 1})
    recovered = []
    for at in offsets:
        cut.write_bytes(data[:at])
        try:
            log = open_log(cut)
        except LogError as exc:
            assert at < ends[0]  # only a file cut before its first chunk is refused...
            assert "\n" not in str(exc)
            continue
        whole = sum(1 for e in ends if e <= at)
        assert log.n_slots == 1000 * whole, at  # ...every complete chunk is recovered
        assert log.cut_short and log.status == "truncated" and not log.finished
        assert log.read_all().equals(_prefix(ref, log.n_slots))
        recovered.append(log.n_slots)
    assert recovered[-1] == 5000 and 0 in recovered
    assert "killed" in open_log(cut).summary


def _prefix(block, n):
    return block.slice(0, n)


def _bad(path) -> str:
    with pytest.raises(LogError) as info:
        open_log(path)
    assert isinstance(info.value, UsageError) and info.value.exit_code == 2
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    return message


def test_files_that_are_not_usable_logs_are_refused_in_one_line(tmp_path):
    assert "no such file" in _bad(tmp_path / "missing.mcap")
    assert "is a directory" in _bad(tmp_path)
    (tmp_path / "empty.mcap").write_bytes(b"")
    assert "empty file" in _bad(tmp_path / "empty.mcap")
    (tmp_path / "text.mcap").write_text("t,x,arm\n1,2,3\n")
    assert "not an MCAP file" in _bad(tmp_path / "text.mcap")
    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start(library="someone-else")
        schema = w.register_schema("x", "jsonschema", b"{}")
        channel = w.register_channel("/corraoi/slot", "json", schema)
        w.add_message(channel, 1, b'{"t": 1}', 1)
        w.finish()
    assert "not a corraoi log" in _bad(other) and "someone-else" in _bad(other)


def test_a_newer_format_version_is_refused(tmp_path, make_config):
    config = make_config(horizon=10)
    meta = run_metadata(config)
    meta["format_version"] = str(SLOT_FORMAT_VERSION + 1)
    newer = tmp_path / "newer.mcap"
    with open(newer, "wb") as f:
        w = Writer(f)
        w.start(library="corraoi/9.0")
        w.add_metadata(RUN_METADATA, meta)
        w.finish()
    message = _bad(newer)
    assert f"version {SLOT_FORMAT_VERSION + 1}" in message and "upgrade corraoi" in message


def test_a_chunk_with_a_bad_crc_is_refused(record_mcap, tmp_path):
    path, _, _ = record_mcap(horizon=2000)
    with open(path, "rb") as f:
        second = sorted(c.chunk_start_offset for c in make_reader(f).get_summary().chunk_indexes)[1]
    data = bytearray(path.read_bytes())
    at = second + 9 + 24  # opcode, length, start, end, uncompressed size -> CRC
    (crc,) = struct.unpack_from("<I", data, at)
    struct.pack_into("<I", data, at, crc ^ 0x5A5A5A5A)
    bad = tmp_path / "crc.mcap"
    bad.write_bytes(bytes(data))
    message = _bad(bad)
    assert f"chunk at byte {second}" in message and "CRC" in message
    flipped = bytearray(path.read_bytes())
    flipped[second + 200] ^= 0xFF  # damage inside the compressed data
    bad.write_bytes(bytes(flipped))
    assert "damaged" in _bad(bad)
