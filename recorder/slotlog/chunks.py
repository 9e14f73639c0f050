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

import dataclasses
import queue
import threading
import weakref
import zlib
from collections.abc import Callable, Sequence
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
#: What :meth:`ChunkWriter.frame` takes before each message: room for its record header,
#: starting with a newline (a byte that no JSON text of ours holds: orjson escapes it), by
#: which the messages are found.
RECORD_ROOM = b"\n" + bytes(_MESSAGE_HEADER.itemsize - 1)
_INDEX_ENTRY = np.dtype([("log", "<u8"), ("offset", "<u8")])
#: zstd level of the chunks. Against mcap's default 3, on 200,000 slots of cucb (the
#: benchmarks/bench_record.py data): framing and compression 0.74-0.82 instead of
#: 0.83-0.93 us a slot, for files 6% larger (49.6 instead of 46.8 bytes a slot).
ZSTD_LEVEL = 1


@dataclasses.dataclass(frozen=True)
class Framed:
    """Messages framed as MCAP Message records, back to back in one buffer: record i is
    ``records[offsets[i]:offsets[i + 1]]``, at ``log_times[i]``, on channel
    ``channels[i]`` (None: every one on the writer's first channel). Sliced by message
    (``framed[a:b]``) without copying."""

    records: memoryview
    log_times: np.ndarray
    offsets: np.ndarray
    channels: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.log_times)

    def __getitem__(self, part: slice) -> Framed:
        begin, end, _ = part.indices(len(self))
        a, z = int(self.offsets[begin]), int(self.offsets[end])
        chans = None if self.channels is None else self.channels[begin:end]
        return Framed(self.records[a:z], self.log_times[begin:end],
                      self.offsets[begin : end + 1] - a, chans)  # fmt: skip


class ChunkWriter:
    """Writes ``stream`` as an MCAP file with one schema and one channel (id 1), or with
    ``more_channels`` several (a run of several sources: a channel per source, sharing the
    schema; each message then names its channel).

    The calls of ``mcap.writer.Writer`` it replaces: ``start()``, ``add_metadata()``,
    ``add_messages()`` (a batch of ``add_message``), ``flush()`` to close the open chunk,
    write it and hand it to the OS (not fsynced: a killed writer leaves every flushed
    chunk on disk), ``finish()``. Chunks end only at ``flush()``, never by size.
    ``frame()`` and ``add_framed()`` take the messages as one text with room for the
    record headers (what ``BlockEncoder.encode_framed`` writes): the same bytes as
    ``add_messages`` without a bytes object per message (0.4 us a slot less at K = 4).

    ``background``: a chunk that ``flush()`` closes is compressed and written by a thread
    of the writer's own while the caller goes on (zstd, the CRC and the write release the
    GIL), at most one chunk at a time; ``finish()`` waits for it, and ``stop()`` does for a
    writer given up. The bytes are the same. Measured on 2 cores (benchmarks/bench_record.py,
    cucb at K = 4): ``corraoi record``'s MCAP log alone 0.8x the wall time, with the
    ``.rrd`` 0.92x, for 6-20% more CPU time (the other core's caches do not hold the chunk).
    """

    def __init__(
        self,
        stream: BinaryIO,
        *,
        schema: Schema,
        channel: Channel,
        library: str,
        profile: str = "",
        zstd_level: int = ZSTD_LEVEL,
        more_channels: Sequence[Channel] = (),
        background: bool = False,
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
        # the open chunk: the messages added since the last flush, framed
        self._open: list[Framed] = []
        self._background = background
        self._worker: _Worker | None = None

    def _write(self, data: bytes) -> None:
        self._wait()  # the chunk being written comes first
        self._stream.write(data)
        self._offset += len(data)

    def _wait(self) -> None:
        """Wait until the chunk handed to the thread is written (its error, an ``OSError``
        such as a full disk, is raised here)."""
        if self._worker is not None:
            self._worker.wait()

    def stop(self) -> None:
        """Wait for the chunk being written and end the thread that writes them (``finish``
        does; a writer given up calls it before it closes the stream). Safe twice."""
        worker, self._worker = self._worker, None
        if worker is not None:
            worker.stop()

    def start(self) -> None:
        b = RecordBuilder()
        Header(profile=self._profile, library=self._library).write(b)
        self._write(MAGIC + b.end())

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._wait()  # its offset follows the chunk being written
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
        self._wait()
        b = RecordBuilder()
        Attachment(create_time=0, log_time=0, name=name, media_type=media_type,
                   data=data).write(b)  # fmt: skip
        record = b.end()
        self._attachment_indexes.append(
            AttachmentIndex(offset=self._offset, length=len(record), log_time=0, create_time=0,
                            data_size=len(data), name=name, media_type=media_type)  # fmt: skip
        )
        self._write(record)

    def _head(self, log_times: np.ndarray, sequences: np.ndarray, lengths: np.ndarray,
              channels: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """The record headers of messages of these times, sequences, byte lengths and
        channels (None: the first)."""
        head = np.empty(len(lengths), dtype=_MESSAGE_HEADER)
        head["op"] = Opcode.MESSAGE
        head["len"] = lengths + _MESSAGE_FIXED
        head["ch"] = self._channel.id if channels is None else channels
        head["seq"] = sequences
        head["log"] = log_times
        head["pub"] = log_times
        return head

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
        n = len(messages)
        if n != len(log_times) or n != len(sequences):
            raise ValueError("add_messages: times, sequences and messages differ in length")
        if n == 0:
            return
        log_times = np.asarray(log_times, dtype=np.uint64)
        lengths = np.fromiter(map(len, messages), dtype=np.uint64, count=n)
        if channels is not None:
            channels = np.asarray(channels, dtype=np.uint16)
        head = self._head(log_times, np.asarray(sequences, dtype=np.uint64), lengths, channels)
        size = _MESSAGE_HEADER.itemsize
        parts: list[bytes] = [b""] * (2 * n)
        parts[0::2] = head.view(f"V{size}").tolist()  # one bytes object per header
        parts[1::2] = messages
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(lengths + np.uint64(size), out=offsets[1:])
        self._open.append(Framed(memoryview(b"".join(parts)), log_times, offsets, channels))

    def frame(self, log_times: np.ndarray, sequences: np.ndarray,
              text: bytes | bytearray) -> Framed:  # fmt: skip
        """The messages of ``text`` as records: message i after the i-th
        :data:`RECORD_ROOM`, at ``log_times[i]`` (= publish time), ``sequences[i]``. The
        headers are written over the rooms: in ``text`` itself when it is a bytearray,
        else in a copy."""
        buf = np.frombuffer(text if isinstance(text, bytearray) else bytearray(text),
                            dtype=np.uint8)  # fmt: skip
        starts = np.flatnonzero(buf == RECORD_ROOM[0])
        n, size = len(starts), _MESSAGE_HEADER.itemsize
        if n != len(log_times) or n != len(sequences) or (n and starts[0] != 0):
            raise ValueError(f"frame: {n} messages in the text, {len(log_times)} times and "
                             f"{len(sequences)} sequences: expected as many, each after a "
                             "RECORD_ROOM")  # fmt: skip
        offsets = np.append(starts, len(buf))
        log_times = np.asarray(log_times, dtype=np.uint64)
        lengths = (np.diff(offsets) - size).astype(np.uint64)
        head = self._head(log_times, np.asarray(sequences, dtype=np.uint64), lengths)
        buf[starts[:, None] + np.arange(size)] = head.view(np.uint8).reshape(n, size)
        return Framed(buf.data, log_times, offsets)

    def add_framed(self, framed: Framed) -> None:
        """Add the messages of ``framed`` (:meth:`frame`) to the open chunk, in time order.
        Nothing is written until :meth:`flush` (or :meth:`finish`)."""
        if len(framed):
            self._open.append(framed)

    def flush(self) -> None:
        """Write the open chunk (if it holds a message) and hand everything to the OS, as
        ``mcap.writer.Writer.flush`` does. Not fsynced. A writer made with ``background``
        hands the chunk to its thread and returns; the chunk's error, if any, is raised by
        the next call that writes."""
        parts, self._open = self._open, []
        if parts and self._background:
            if self._worker is None:
                self._worker = _Worker(self)
            self._worker.submit(lambda: self._write_chunk(parts, flush=True))
            return
        self._wait()
        if parts:
            self._write_chunk(parts)
        self._stream.flush()

    def _write_chunk(self, parts: list[Framed], *, flush: bool = False) -> None:
        """Write the chunk of ``parts`` (and with ``flush``, hand the stream to the OS)."""
        n = sum(len(p) for p in parts)
        if n == 0:
            return
        prefix = b""
        if not self._chunk_indexes:  # the first chunk carries the schema and the channel
            b = RecordBuilder()
            self._schema.write(b)
            for c in self._channels:
                c.write(b)
            prefix = b.end()
        records = (parts[0].records if len(parts) == 1 and not prefix
                   else b"".join([prefix, *(p.records for p in parts)]))  # fmt: skip
        log_times = parts[0].log_times if len(parts) == 1 else np.concatenate(
            [p.log_times for p in parts])  # fmt: skip
        index = np.empty(n, dtype=_INDEX_ENTRY)
        index["log"] = log_times
        at, begin = len(prefix), 0
        for p in parts:  # each record's offset in the chunk
            index["offset"][begin : begin + len(p)] = p.offsets[:-1] + at
            at, begin = at + int(p.offsets[-1]), begin + len(p)

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
        chunk_start = self._offset
        # one message index per channel that has messages in the chunk, in channel order
        channels = None
        if len(self._channels) > 1:
            first = self._channel.id
            channels = np.concatenate([
                np.full(len(p), first, dtype=np.uint16) if p.channels is None else p.channels
                for p in parts
            ])  # fmt: skip
        index_offsets: dict[int, int] = {}
        message_index = b""
        for c in self._channels:
            mine = None if channels is None else channels == c.id
            count = n if mine is None else int(np.count_nonzero(mine))
            if not count:
                continue
            body = (index if mine is None else index[mine]).tobytes()
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
        self._stream.write(chunk + message_index)
        self._offset += len(chunk) + len(message_index)
        if self._messages == 0:
            self._start_time = start
        self._messages += n
        self._end_time = end
        if flush:
            self._stream.flush()

    def finish(self) -> None:
        """The open chunk, DataEnd, the summary (schema, channel, statistics, chunk and
        metadata indexes, each group with its summary offset) and the footer. Does not
        close the stream."""
        self.flush()
        self.stop()
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


class _Worker:
    """The thread that writes a ChunkWriter's chunks, one at a time, in the order handed
    over; the writer waits for one before it hands over the next (zstd, the CRC and the
    file write release the GIL: the next block is encoded meanwhile)."""

    def __init__(self, writer: ChunkWriter) -> None:
        self._jobs: queue.SimpleQueue[Callable[[], object] | None] = queue.SimpleQueue()
        self._done: queue.SimpleQueue[BaseException | None] = queue.SimpleQueue()
        self._busy = False
        self._thread = threading.Thread(target=_work, args=(self._jobs, self._done),
                                        name="corraoi-mcap-chunks", daemon=True)  # fmt: skip
        self._thread.start()
        # a writer dropped without finish() (an aborted log) ends its thread
        weakref.finalize(writer, self._jobs.put, None)

    def submit(self, job: Callable[[], object]) -> None:
        """Run ``job`` once the job before it is done (its error raised here)."""
        self.wait()
        self._jobs.put(job)
        self._busy = True

    def wait(self) -> None:
        """Wait for the job handed over last (a Ctrl-C meanwhile leaves it to wait for)."""
        if self._busy:
            error = self._done.get()
            self._busy = False
            if error is not None:
                raise error

    def stop(self) -> None:
        try:
            self.wait()
        finally:
            self._jobs.put(None)
            self._thread.join()


def _work(jobs: queue.SimpleQueue[Callable[[], object] | None],
          done: queue.SimpleQueue[BaseException | None]) -> None:  # fmt: skip
    while True:
        job = jobs.get()
        if job is None:
            return
        error: BaseException | None = None
        try:
            job()
        except BaseException as exc:  # handed to the writer's thread, raised there
            error = exc
        job = None  # the writer is not kept alive by its last chunk
        done.put(error)


__all__ = [
    "RECORD_ROOM",
    "ZSTD_LEVEL",
    "ChunkWriter",
    "Framed",
]
