"""ChunkWriter: an MCAP file of one channel, written a whole chunk at a time.

Why hand-written framing earns its place here: ``mcap.writer.Writer.add_message`` builds a
``Message`` object, packs its header with ``struct`` and updates four statistics per
message. Measured on this machine (benchmarks/bench_record.py, 200,000 slots of cucb on
I1), that path cost 3.8-4.1 us a slot, 57% of ``corraoi record``'s main thread, against
about 0.4 us a slot to frame the same messages with numpy (one structured array of
message headers per chunk, one ``join``) plus 0.45 us of zstd. Everything that is written
once per file or once per chunk (header, schema, channel, metadata, chunk record, chunk
index, statistics, summary offsets, footer) still goes through ``mcap.records``, so only
the two per-message layouts below are spelled out by hand:

* Message (opcode 0x05): ``channel_id u16, sequence u32, log_time u64, publish_time u64,
  data``, as ``_MESSAGE_HEADER`` (31 bytes with the opcode and the record length);
* MessageIndex (opcode 0x07): ``channel_id u16, u32 byte length, (log_time u64,
  offset u64)*``.

With ``zstd_level=3`` the bytes are those ``mcap.writer.Writer`` writes for the same
calls (the first chunk carries the schema and channel records, then the messages;
``uncompressed_crc`` is set), except that no empty summary group is written: the mcap 1.6
writer always writes an attachment-index group, empty in our files. The tests pin both:
equal to the mcap writer's file without that group, and readable by mcap's readers and
:mod:`corraoi.recorder.slotlog.reader`. We write level 1 (:data:`ZSTD_LEVEL`).
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import BinaryIO

import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

from corraoi.recorder.vocab import MAGIC

#: opcode u8, record length u64, channel_id u16, sequence u32, log_time u64, publish_time u64
_MESSAGE_HEADER = np.dtype(
    [("op", "u1"), ("len", "<u8"), ("ch", "<u2"), ("seq", "<u4"), ("log", "<u8"), ("pub", "<u8")]
)
_MESSAGE_FIXED = _MESSAGE_HEADER.itemsize - 9  # the record length counts from channel_id
_INDEX_ENTRY = np.dtype([("log", "<u8"), ("offset", "<u8")])
#: zstd level of the chunks. Against mcap's default 3, on 200,000 slots of cucb (the
#: benchmarks/bench_record.py data): framing and compression 0.74-0.82 instead of
#: 0.83-0.93 us a slot, for files 6% larger (49.6 instead of 46.8 bytes a slot).
ZSTD_LEVEL = 1


class ChunkWriter:
    """Writes ``stream`` as an MCAP file with one schema and one channel (id 1), or with
    ``more_channels`` several (a run of several sources: a channel per source, sharing the
    schema; each message then names its channel).

    The calls of ``mcap.writer.Writer`` it replaces: ``start()``, ``add_metadata()``,
    ``add_messages()`` (a batch of ``add_message``), ``flush()`` to close the open chunk,
    write it and hand it to the OS (not fsynced: a killed writer leaves every flushed
    chunk on disk), ``finish()``. Chunks end only at ``flush()``, never by size.
    """

    def __init__(
        self,
        stream: BinaryIO,
        *,
        schema: Schema,
        channel: Channel,
        more_channels: Sequence[Channel] = (),
        library: str,
        profile: str = "",
        zstd_level: int = ZSTD_LEVEL,
    ) -> None:
        self._stream = stream
        self._library = library
        self._profile = profile
        self._schema = schema
        self._channel = channel
        self._channels = (channel, *more_channels)
        self._counts = dict.fromkeys((c.id for c in self._channels), 0)
        self._offset = 0
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._messages = 0
        self._start_time = 0
        self._end_time = 0
        self._zstd = zstandard.ZstdCompressor(level=zstd_level)
        # the open chunk: messages added since the last flush
        self._open: list[bytes] = []
        self._open_times: list[np.ndarray] = []
        self._open_seqs: list[np.ndarray] = []
        self._open_channels: list[np.ndarray] = []

    def _write(self, data: bytes) -> None:
        self._stream.write(data)
        self._offset += len(data)

    def start(self) -> None:
        b = RecordBuilder()
        Header(profile=self._profile, library=self._library).write(b)
        self._write(MAGIC + b.end())

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        b = RecordBuilder()
        Metadata(name=name, metadata=data).write(b)
        record = b.end()
        self._metadata_indexes.append(
            MetadataIndex(offset=self._offset, length=len(record), name=name)
        )
        self._write(record)

    def add_attachment(self, name: str, media_type: str, data: bytes) -> None:
        """A file carried in the log (a plug-in's source): its bytes as they are, with
        their CRC, indexed in the summary. No wall clock: its times are 0."""
        b = RecordBuilder()
        Attachment(create_time=0, log_time=0, name=name, media_type=media_type,
                   data=data).write(b)  # fmt: skip
        record = b.end()
        self._attachment_indexes.append(
            AttachmentIndex(offset=self._offset, length=len(record), log_time=0, create_time=0,
                            data_size=len(data), name=name, media_type=media_type)  # fmt: skip
        )
        self._write(record)

    def add_messages(
        self,
        log_times: np.ndarray,
        sequences: np.ndarray,
        messages: Sequence[bytes],
        channels: np.ndarray | None = None,
    ) -> None:
        """Add ``messages[i]`` at ``log_times[i]`` (= publish time) to the open chunk, in
        time order, on channel ``channels[i]`` (None: the first channel). Nothing is
        written until :meth:`flush` (or :meth:`finish`)."""
        if len(messages) != len(log_times) or len(messages) != len(sequences):
            raise ValueError("add_messages: times, sequences and messages differ in length")
        if len(messages):
            self._open.extend(messages)
            self._open_times.append(np.asarray(log_times, dtype=np.uint64))
            self._open_seqs.append(np.asarray(sequences, dtype=np.uint64))
            if channels is None:
                channels = np.full(len(messages), self._channel.id, dtype=np.uint16)
            self._open_channels.append(np.asarray(channels, dtype=np.uint16))

    def flush(self) -> None:
        """Write the open chunk (if it holds a message) and hand everything to the OS, as
        ``mcap.writer.Writer.flush`` does. Not fsynced."""
        if self._open:
            messages, self._open = self._open, []
            times, self._open_times = np.concatenate(self._open_times), []
            seqs, self._open_seqs = np.concatenate(self._open_seqs), []
            chans, self._open_channels = np.concatenate(self._open_channels), []
            self._write_chunk(times, seqs, messages, chans)
        self._stream.flush()

    def _write_chunk(
        self,
        log_times: np.ndarray,
        sequences: np.ndarray,
        messages: Sequence[bytes],
        channels: np.ndarray,
    ) -> None:
        n = len(messages)
        if n == 0:
            return
        prefix = b""
        if not self._chunk_indexes:  # the first chunk carries the schema and the channel
            b = RecordBuilder()
            self._schema.write(b)
            for c in self._channels:
                c.write(b)
            prefix = b.end()
        lengths = np.fromiter(map(len, messages), dtype=np.uint64, count=n)
        head = np.empty(n, dtype=_MESSAGE_HEADER)
        head["op"] = Opcode.MESSAGE
        head["len"] = lengths + _MESSAGE_FIXED
        head["ch"] = channels
        head["seq"] = sequences
        head["log"] = log_times
        head["pub"] = log_times
        size = _MESSAGE_HEADER.itemsize
        parts: list[bytes] = [b""] * (2 * n)
        parts[0::2] = head.view(f"V{size}").tolist()  # one bytes object per header
        parts[1::2] = messages
        records = prefix + b"".join(parts)
        offsets = np.empty(n, dtype=np.uint64)
        offsets[0] = len(prefix)
        np.cumsum(lengths[:-1] + size, out=offsets[1:])
        offsets[1:] += len(prefix)

        start, end = int(log_times[0]), int(log_times[-1])
        compressed = self._zstd.compress(records)
        b = RecordBuilder()
        Chunk(
            compression="zstd",
            data=compressed,
            message_start_time=start,
            message_end_time=end,
            uncompressed_crc=zlib.crc32(records),
            uncompressed_size=len(records),
        ).write(b)
        chunk = b.end()
        # one message index per channel that has messages in the chunk, in channel order
        chunk_start = self._offset
        index_offsets: dict[int, int] = {}
        message_index = b""
        for c in self._channels:
            mine = channels == c.id
            count = int(np.count_nonzero(mine)) if len(self._channels) > 1 else n
            if not count:
                continue
            index = np.empty(count, dtype=_INDEX_ENTRY)
            index["log"] = log_times if count == n else log_times[mine]
            index["offset"] = offsets if count == n else offsets[mine]
            body = index.tobytes()
            index_offsets[c.id] = chunk_start + len(chunk) + len(message_index)
            message_index += (
                int(Opcode.MESSAGE_INDEX).to_bytes(1, "little")
                + (6 + len(body)).to_bytes(8, "little")
                + c.id.to_bytes(2, "little")
                + len(body).to_bytes(4, "little")
                + body
            )
            self._counts[c.id] += count
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=chunk_start,
                chunk_length=len(chunk),
                message_index_offsets=index_offsets,
                message_index_length=len(message_index),
                compression="zstd",
                compressed_size=len(compressed),
                uncompressed_size=len(records),
            )
        )
        self._write(chunk + message_index)
        if self._messages == 0:
            self._start_time = start
        self._messages += n
        self._end_time = end

    def finish(self) -> None:
        """The open chunk, DataEnd, the summary (schema, channel, statistics, chunk and
        metadata indexes, each group with its summary offset) and the footer. Does not
        close the stream."""
        self.flush()
        b = RecordBuilder()
        DataEnd(data_section_crc=0).write(b)
        self._write(b.end())
        summary_start = self._offset
        s = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: Sequence[object]) -> None:
            if not records:  # an empty group is no group (Foxglove and mcap-cli agree)
                return
            begin = s.count
            for r in records:
                r.write(s)  # type: ignore[attr-defined]
            offsets.append(
                SummaryOffset(
                    group_opcode=opcode,
                    group_start=summary_start + begin,
                    group_length=s.count - begin,
                )
            )

        stats = Statistics(
            message_count=self._messages,
            schema_count=1,
            channel_count=len(self._channels),
            attachment_count=len(self._attachment_indexes),
            metadata_count=len(self._metadata_indexes),
            chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_time,
            message_end_time=self._end_time,
            channel_message_counts={k: v for k, v in self._counts.items() if v},
        )
        group(Opcode.SCHEMA, [self._schema])
        group(Opcode.CHANNEL, list(self._channels))
        group(Opcode.STATISTICS, [stats])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, self._attachment_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        offset_start = summary_start + s.count
        for o in offsets:
            o.write(s)
        summary = s.end()
        footer = (
            int(Opcode.FOOTER).to_bytes(1, "little")
            + (20).to_bytes(8, "little")
            + summary_start.to_bytes(8, "little")
            + offset_start.to_bytes(8, "little")
        )
        f = RecordBuilder()
        Footer(
            summary_start=summary_start,
            summary_offset_start=offset_start,
            summary_crc=zlib.crc32(footer, zlib.crc32(summary)),
        ).write(f)
        self._write(summary + f.end() + MAGIC)
        self._stream.flush()


__all__ = [
    "ZSTD_LEVEL",
    "ChunkWriter",
]
