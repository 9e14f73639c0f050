"""corraoi.viewer.recover: a log whose writer died becomes a finished, indexed MCAP file."""

from __future__ import annotations

import hashlib
import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from corraoi.engine.block import FIELDS, SlotBlock
from corraoi.errors import LogError, OutputError
from corraoi.recorder.slotlog.reader import open_log
from corraoi.viewer import diff, recover

#: A chunk record (opcode 6) announcing 10,000 bytes, of which only a few were written.
TORN = bytes([0x06]) + struct.pack("<Q", 10_000) + b"\x00" * 37


def _killed(tmp_path: Path, make_config, engine, *, slots: int = 3000, torn: bool = True):
    """A .partial log as a writer killed after ``slots`` slots leaves it."""
    from corraoi.recorder.slotlog.sink import McapSink

    config = make_config("cts", horizon=5000, seed=9)
    ref = SlotBlock.concat(engine(config))
    sink = McapSink(tmp_path / "run.mcap", config, fsync=False)
    for start in range(0, slots, 1000):
        sink.write(ref.slice(start, start + 1000))
    sink._writer.flush()  # what the writer does every 1000 slots
    sink._file.flush()
    sink._file.close()  # killed: no summary, no footer, not renamed
    part = tmp_path / "run.mcap.partial"
    if torn:
        with part.open("ab") as f:
            f.write(TORN)
    return part, config, ref


def _payloads(path: Path) -> list[bytes]:
    out = []
    with path.open("rb") as f:
        try:
            for rec in StreamReader(f).records:
                if isinstance(rec, Message):
                    out.append(rec.data)
        except (EndOfFile, struct.error):  # the torn record at the end
            pass
    return out


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_killed_writers_log_becomes_finished_and_indexed(tmp_path, make_config, engine):
    part, config, ref = _killed(tmp_path, make_config, engine)
    before = _sha(part)
    with part.open("rb") as f:  # the indexed reader finds nothing in the broken file
        with pytest.raises(Exception):  # noqa: B017 - mcap raises several kinds here
            list(make_reader(f).iter_messages())
    done = recover(part, tmp_path / "fixed.mcap")
    assert (done.slots, done.horizon, done.source_status, done.status) == (
        3000, 5000, "truncated", "interrupted",
    )  # fmt: skip
    assert done.dropped_bytes == len(TORN)
    assert _sha(part) == before  # the source is never modified
    fixed = tmp_path / "fixed.mcap"
    with fixed.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 3000
        assert len(summary.chunk_indexes) == 3  # chunked every 1000 slots, as written
        messages = [m for _, _, m in reader.iter_messages()]
        assert [m.log_time for m in messages] == [t * 10**9 for t in range(1, 3001)]
        assert [m.sequence for m in messages] == list(range(1, 3001))
        meta = {r.name: r.metadata for r in reader.iter_metadata()}
    with fixed.open("rb") as f:
        assert sum(1 for _ in NonSeekingReader(f).iter_messages()) == 3000
    assert [m.data for m in messages] == _payloads(part)  # byte for byte
    assert meta["corraoi.run"]["label"] == config.label
    assert meta["corraoi.end"]["slots"] == "3000"
    assert meta["corraoi.end"]["status"] == "interrupted"
    assert meta["corraoi.end"]["regret"] == str(int(ref.regret[2999]))
    assert "truncated" in meta["corraoi.end"]["recovered_from"]
    log = open_log(fixed)
    assert log.finished and log.n_slots == 3000 and log.status == "interrupted"
    got = log.read_all()
    for f in FIELDS:
        assert np.array_equal(got.column(f), ref.column(f)[:3000]), f
    assert diff(part, fixed).identical


def test_recover_the_partial_file_into_its_own_name(tmp_path, make_config, engine):
    part, _, _ = _killed(tmp_path, make_config, engine, torn=False)
    done = recover(part, tmp_path / "run.mcap")  # the natural call: run.mcap.partial -> run.mcap
    assert done.path == tmp_path / "run.mcap" and done.dropped_bytes == 0
    assert part.exists()
    assert open_log(tmp_path / "run.mcap").finished
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap", "run.mcap.partial"]


def test_an_existing_output_is_not_written_over(tmp_path, make_config, engine):
    part, _, _ = _killed(tmp_path, make_config, engine)
    out = tmp_path / "fixed.mcap"
    out.write_bytes(b"precious")
    with pytest.raises(OutputError, match="already exists"):
        recover(part, out)
    assert out.read_bytes() == b"precious"
    with pytest.raises(OutputError, match="is the log being recovered"):
        recover(part, part, overwrite=True)
    with pytest.raises(OutputError, match="is a directory"):
        recover(part, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fixed.mcap", "run.mcap.partial"]
    recover(part, out, overwrite=True)
    assert open_log(out).n_slots == 3000


@pytest.mark.parametrize("content", [b"", b"hello, not an MCAP file", b"\x89MCAP0\r\n"])
def test_bad_sources_are_refused_and_nothing_is_left(tmp_path, content):
    src = tmp_path / "bad.mcap"
    src.write_bytes(content)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.raises(LogError):
        recover(src, out_dir / "fixed.mcap")
    assert list(out_dir.iterdir()) == []


def test_a_finished_log_is_copied_with_the_same_slots(tmp_path, record_mcap):
    path, _, _ = record_mcap("aoi-aware-ucb", horizon=2500)
    done = recover(path, tmp_path / "copy.mcap")
    assert (done.source_status, done.status, done.slots) == ("complete", "complete", 2500)
    assert diff(path, tmp_path / "copy.mcap").identical
    assert _payloads(path) == _payloads(tmp_path / "copy.mcap")


def test_a_writer_killed_with_sigkill(tmp_path):
    """The real case: `corraoi record` killed with SIGKILL mid-run, then recover."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run.mcap"
    part = tmp_path / "run.mcap.partial"
    cmd = [sys.executable, "-m", "corraoi.cli", "record", "-p", "cts", "-T", "50000000",
           "-o", str(out), "--no-rrd"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # wait for a few flushed chunks
            if part.exists() and part.stat().st_size > 200_000:
                break
            time.sleep(0.05)
        else:
            pytest.fail("corraoi record wrote nothing within 60 s")
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not out.exists()
    log = open_log(part)
    assert log.status == "truncated" and log.n_slots > 0 and log.n_slots % 1000 == 0
    done = recover(part, out)
    assert done.slots == log.n_slots and done.status == "interrupted"
    with out.open("rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == log.n_slots
    assert diff(part, out).identical
