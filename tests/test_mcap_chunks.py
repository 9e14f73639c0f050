"""The hand-framed MCAP writer (corraoi.recorder.slotlog.chunks) against mcap's own writer and
readers."""

from __future__ import annotations

import io
import struct
import threading

import numpy as np
import orjson
import pytest
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Schema
from mcap.writer import CompressionType, IndexType, Writer

from corraoi.engine.block import SlotBlock
from corraoi.recorder.slotlog.chunks import RECORD_ROOM, ZSTD_LEVEL, ChunkWriter
from corraoi.recorder.slotlog.encode import BlockEncoder
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.recorder.vocab import NS_PER_SLOT
from corraoi.recorder.vocab import SLOT_FLUSH_EVERY as FLUSH_EVERY


def _reference(messages: list[tuple[int, bytes]], every: int) -> bytes:
    """What mcap's Writer writes for the same calls, without the (empty) attachment group."""
    buf = io.BytesIO()
    w = Writer(
        buf,
        chunk_size=1 << 30,
        compression=CompressionType.ZSTD,
        index_types=IndexType.ALL & ~IndexType.ATTACHMENT,
    )
    w.start(profile="", library="corraoi/test")
    sid = w.register_schema(name="s", encoding="jsonschema", data=b'{"type":"object"}')
    cid = w.register_channel(topic="/x", message_encoding="json", schema_id=sid,
                             metadata={"format_version": "1"})  # fmt: skip
    w.add_metadata("a", {"k": "v"})
    for t, data in messages:
        w.add_message(cid, t * NS_PER_SLOT, data, t * NS_PER_SLOT, t)
        if t % every == 0:
            w.flush()
    w.flush()
    w.add_metadata("b", {"end": "1"})
    w.finish()
    return buf.getvalue()


def _ours(messages: list[tuple[int, bytes]], every: int, zstd_level: int = 3,
          framed: int = 0, background: bool = False) -> bytes:  # fmt: skip
    """ChunkWriter's file: a message an ``add_messages`` call, or (``framed`` > 0) that many
    messages a ``frame`` call, added a message at a time (``add_framed`` of its slices);
    ``background``: its chunks written by its thread."""
    buf = io.BytesIO()
    w = ChunkWriter(
        buf,
        schema=Schema(id=1, name="s", encoding="jsonschema", data=b'{"type":"object"}'),
        channel=Channel(
            id=1, topic="/x", message_encoding="json", schema_id=1, metadata={"format_version": "1"}
        ),  # fmt: skip
        library="corraoi/test",
        zstd_level=zstd_level,
        background=background,
    )
    w.start()
    w.add_metadata("a", {"k": "v"})
    for i, (t, data) in enumerate(messages):  # one at a time, as mcap's writer is called
        if not framed:
            w.add_messages(np.array([t * NS_PER_SLOT], dtype=np.uint64), np.array([t]), [data])
        else:
            if i % framed == 0:  # the next `framed` messages as one text, each after the room
                batch = messages[i : i + framed]
                ts = np.array([u for u, _ in batch], dtype=np.uint64)
                text = bytearray(b"".join(RECORD_ROOM + d for _, d in batch))
                frame = w.frame(ts * np.uint64(NS_PER_SLOT), ts, text)
            w.add_framed(frame[i % framed : i % framed + 1])
        if t % every == 0:
            w.flush()
    w.flush()
    w.add_metadata("b", {"end": "1"})
    w.finish()
    return buf.getvalue()


@pytest.mark.parametrize("count", [1, 7, 25])
def test_same_bytes_as_the_mcap_writer_without_its_empty_group(count):
    rng = np.random.default_rng(count)
    values = rng.integers(0, 10**6, count).tolist()
    messages = [(t, b'{"v":%d}' % v * (1 + t % 3)) for t, v in enumerate(values, start=1)]
    assert _ours(messages, every=10, zstd_level=3) == _reference(messages, every=10)
    assert _ours(messages, every=10, zstd_level=3, background=True) == _reference(messages, 10)
    ours = _ours(messages, every=10, zstd_level=ZSTD_LEVEL)  # what McapSink writes
    reader = make_reader(io.BytesIO(ours), validate_crcs=True)
    got = [(m.log_time, m.publish_time, m.sequence, m.data) for _, _, m in reader.iter_messages()]
    assert got == [(t * NS_PER_SLOT, t * NS_PER_SLOT, t, d) for t, d in messages]


@pytest.mark.parametrize("framed", [1, 4, 13])
def test_framed_messages_are_the_same_bytes(framed):
    """Messages given as one text with room for their record headers (what McapSink gives,
    BlockEncoder.encode_framed's) make the file add_messages makes, chunks ending inside a
    framed batch or not."""
    rng = np.random.default_rng(framed)
    messages = [(t, b'{"v":%d}' % v * (1 + t % 3))
                for t, v in enumerate(rng.integers(0, 10**6, 30).tolist(), start=1)]  # fmt: skip
    assert _ours(messages, every=10, framed=framed) == _ours(messages, every=10)
    assert _ours(messages, every=10, framed=framed, background=True) == _ours(messages, 10)
    assert _ours(messages, every=10, zstd_level=3, framed=framed) == _reference(messages, 10)
    buf = io.BytesIO()
    w = ChunkWriter(buf, schema=Schema(id=1, name="s", encoding="jsonschema", data=b"{}"),
                    channel=Channel(id=1, topic="/x", message_encoding="json", schema_id=1,
                                    metadata={}), library="corraoi/test")  # fmt: skip
    with pytest.raises(ValueError, match="2 messages in the text, 3 times"):
        w.frame(np.arange(3, dtype=np.uint64), np.arange(3), RECORD_ROOM + b"{}" + RECORD_ROOM)
    with pytest.raises(ValueError, match="each after a RECORD_ROOM"):
        w.frame(np.arange(1, dtype=np.uint64), np.arange(1), b"{}" + RECORD_ROOM)


def test_the_framed_encoding_is_the_messages_each_after_the_room(make_config, engine):
    """BlockEncoder.encode_framed: encode's messages, each after the room, in one buffer."""
    config = make_config("aoi-aware-cucb", horizon=300)  # scores, flags, a threshold
    block = SlotBlock.concat(engine(config))
    enc = BlockEncoder(config.instance.K)
    framed = bytes(enc.encode_framed(block, RECORD_ROOM))
    assert framed == b"".join(RECORD_ROOM + m for m in enc.encode(block))
    assert enc.encode_framed(block.slice(0, 0), RECORD_ROOM) == b""


def _summary_groups(data: bytes) -> list[tuple[int, int]]:
    """(opcode, length) of every summary group, from the footer's summary offset records."""
    footer = len(data) - 8 - 29  # footer record: opcode, length, 8 + 8 + 4 bytes
    assert data[footer] == Opcode.FOOTER
    _, offsets_start, _ = struct.unpack_from("<QQI", data, footer + 9)
    out, pos = [], offsets_start
    while data[pos] == Opcode.SUMMARY_OFFSET:
        op, _, length = struct.unpack_from("<BQQ", data, pos + 9)
        out.append((op, length))
        pos += 9 + 17
    assert pos == footer and out
    return out


def test_a_log_without_messages_has_no_empty_group_either():
    data = _ours([], every=10)
    assert all(length > 0 for _, length in _summary_groups(data))
    assert {op for op, _ in _summary_groups(data)} == {
        Opcode.SCHEMA, Opcode.CHANNEL, Opcode.STATISTICS, Opcode.METADATA_INDEX}  # fmt: skip
    assert list(make_reader(io.BytesIO(data)).iter_messages()) == []


def test_a_recorded_log_has_no_empty_summary_group_and_reads_back(record_mcap):
    path, _, ref = record_mcap(horizon=2345, block=611)
    data = path.read_bytes()
    groups = _summary_groups(data)
    assert {op for op, _ in groups} == {Opcode.SCHEMA, Opcode.CHANNEL, Opcode.STATISTICS,
                                        Opcode.CHUNK_INDEX, Opcode.METADATA_INDEX}  # fmt: skip
    assert all(length > 0 for _, length in groups)
    summary = make_reader(io.BytesIO(data)).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == 2345
    assert summary.statistics.chunk_count == 3  # 1..1000, 1001..2000, 2001..2345
    assert [c.message_start_time // NS_PER_SLOT for c in summary.chunk_indexes] == [1, 1001, 2001]
    assert open_log(path).read_all().equals(ref)


@pytest.mark.parametrize("block", [1, 999, 1001, 4096])
def test_bytes_do_not_depend_on_the_block_size(tmp_path, make_config, engine, block):
    config = make_config("cts", horizon=2 * FLUSH_EVERY + 17)
    paths = []
    for b_size in (1000, block):
        path = tmp_path / f"b{b_size}.mcap"
        with McapSink(path, config, fsync=False) as sink:
            for b in engine(config, block=b_size):
                sink.write(b)
        paths.append(path)
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert open_log(paths[1]).read_all().equals(SlotBlock.concat(engine(config)))


def _chunk_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "corraoi-mcap-chunks"]


@pytest.mark.parametrize("background", [True, False])
def test_a_log_written_in_the_background_is_the_same_file(tmp_path, make_config, engine,
                                                          background):  # fmt: skip
    """McapSink's chunks compressed and written by a thread (``background``, what
    ``corraoi record`` does on more than one core) make the same bytes; the thread ends
    with the file."""
    config = make_config("aoi-aware-cucb", horizon=3 * FLUSH_EVERY + 5)
    paths = []
    for bg in (False, background):
        path = tmp_path / f"{bg}-{len(paths)}.mcap"
        with McapSink(path, config, fsync=False, background=bg) as sink:
            for b in engine(config, block=700):
                sink.write(b)
                assert len(_chunk_threads()) == (1 if bg and sink.slots >= FLUSH_EVERY else 0)
        assert not _chunk_threads()
        paths.append(path)
    assert paths[0].read_bytes() == paths[1].read_bytes()


class _FullDisk(io.BytesIO):
    """A stream that refuses every write past ``room`` bytes, as a full disk does."""

    def __init__(self, room: int) -> None:
        super().__init__()
        self.room = room

    def write(self, data) -> int:  # type: ignore[no-untyped-def, override]
        if self.tell() + len(data) > self.room:
            raise OSError(28, "No space left on device")
        return super().write(data)


def test_a_chunk_that_fails_in_the_background_raises_in_the_writer():
    """A full disk met by the thread is raised by the writer's next call that writes
    (and by finish()), never lost; the thread ends."""
    schema = Schema(id=1, name="s", encoding="jsonschema", data=b"{}")
    channel = Channel(id=1, topic="/x", message_encoding="json", schema_id=1, metadata={})
    w = ChunkWriter(_FullDisk(600), schema=schema, channel=channel, library="corraoi/test",
                    background=True)  # fmt: skip
    w.start()
    rng = np.random.default_rng(0)
    with pytest.raises(OSError, match="No space left"):  # by a later flush()
        for t in range(1, 200):
            w.add_messages(np.array([t], dtype=np.uint64), np.array([t]),
                           [b'{"v":%d}' % rng.integers(10**9)])  # fmt: skip
            w.flush()
    assert t < 199
    with pytest.raises(OSError, match="No space left"):
        w.finish()
    w.stop()
    assert not _chunk_threads()


#: The per-slot template the encoder used before it joined whole columns: the reference.
_TEMPLATE = (
    b'{"t":%d,"x":%d,"arm":%d,"success":%b,"aoi":%d,"oracle_aoi":%d,"regret":%d,'
    b'"estimator":%b,"override":%b,"mu_hat":[%b],"pulls":[%b],"candidates":%b}'
)


def _slow_encode(b: SlotBlock) -> list[bytes]:
    def num(v: float) -> bytes:
        return orjson.dumps(v)

    def f32(v: float) -> bytes:  # float32's shortest text, +-infinity as +-FLOAT32_MAX
        top = float(np.finfo(np.float32).max)
        return orjson.dumps(np.float32(min(max(v, -top), top)), option=orjson.OPT_SERIALIZE_NUMPY)

    def later(i: int) -> bytes:
        """The fields added with the score (issue 40), each where the block has it: forced,
        the override's threshold, the candidates' scores in the candidates' order ([] where
        the slot was not scored)."""
        text = b""
        if b.forced is not None:
            text += b',"forced":' + (b"true" if b.forced[i] else b"false")
        if b.override_threshold is not None:
            text += b',"override_threshold":' + f32(float(b.override_threshold[i]))
        if b.score is not None:
            row = b.score[i]
            arms = [] if np.isnan(row).all() else np.flatnonzero(b.candidates[i])
            text += b',"score":[' + b",".join(f32(float(row[k])) for k in arms) + b"]"
        return text

    return [
        (_TEMPLATE % (int(b.t[i]), int(b.x[i]) + 1, int(b.arm[i]) + 1,
                     b"true" if b.success[i] else b"false", int(b.aoi[i]),
                     int(b.oracle_aoi[i]), int(b.regret[i]), num(float(b.estimator[i])),
                     b"true" if b.override[i] else b"false",
                     b",".join(num(float(v)) for v in b.mu_hat[i]),
                     b",".join(b"%d" % v for v in b.pulls[i]),
                     orjson.dumps([int(k) + 1 for k in np.flatnonzero(b.candidates[i])])))
        [:-1] + later(i) + b"}"
        for i in range(len(b))
    ]  # fmt: skip


@pytest.mark.parametrize("policy", ["cucb", "aoi-aware-cts", "ts"])
def test_the_column_encoder_writes_what_a_per_slot_encoder_writes(make_config, engine, policy):
    config = make_config(policy, horizon=1500)
    block = SlotBlock.concat(engine(config))
    got = BlockEncoder(config.instance.K).encode(block)
    assert got == _slow_encode(block)
    assert len(got) == 1500 and all(orjson.loads(m)["t"] == i + 1 for i, m in enumerate(got))
    assert block.candidates.sum(axis=1).min() < config.instance.K or policy != "cucb"
