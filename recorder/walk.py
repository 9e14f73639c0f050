"""The one MCAP walker: every reader of corraoi's MCAP files walks their records here.

The slot-log reader (:mod:`corraoi.recorder.slotlog.reader`), the sweep-log reader, the sweep
sniffing of :mod:`corraoi.recorder.sweeplog.results` and ``corraoi recover``
(:mod:`corraoi.viewer.recover`) read through :class:`Walker`, as ``mcap``'s ``reader.py``
builds on its ``stream_reader.py``. Record bodies are parsed by ``mcap``'s record classes
(:mod:`mcap.records`) over its :class:`~mcap.data_stream.ReadDataStream`; a finished file's
chunk index is read by ``mcap.reader.SeekingReader``.

The rest is our own code for one reason: a reader must tell a file *cut short* (its writer
was killed: a torn last record, no footer; every complete chunk before is good) from a
*damaged* one (a bad CRC, sizes that do not add up, a record past the end of a file its
writer finished). ``mcap.stream_reader.StreamReader`` raises the same ``EndOfFile`` or
``struct.error`` for both, and ``mcap.reader.make_reader`` needs the summary a killed writer
never wrote. So the walker frames the top-level records itself and compares each length
with the file's size (a record that does not fit is a torn tail, unless the file ends with
the MCAP magic: then it is damage); checks a chunk's sizes before reading or decompressing
it (a damaged size must not make it allocate gigabytes), bounds its decompression, checks
its CRC and names an unknown compression (``mcap`` reads those bytes as uncompressed);
and bounds-checks every record inside a chunk (a cut record in a complete chunk is damage).
On the slot log's hot path, :func:`channel_payloads` takes the payloads as views without
building a ``Message`` per slot. Every problem is a :class:`~corraoi.errors.LogError`
naming the file and the byte offset.
"""

from __future__ import annotations

import os
import stat
import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Header, McapRecord, Message, Metadata, Schema

from corraoi.errors import LogError

from .vocab import MAGIC

#: The largest uncompressed chunk the walker accepts (writers close chunks at 64 MiB).
_MAX_CHUNK = 1 << 28
#: The most a chunk can expand when decompressed (zstd's limit is far below this).
_MAX_RATIO = 1 << 16
_RECORD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression len
_MSG_HEAD = struct.Struct("<HIQQ")  # channel, sequence, log_time, publish_time
_MSG_PEEK = struct.Struct("<BQH")  # opcode, length, and (for a message) its channel
_U64 = struct.Struct("<Q")
#: The records parsed with mcap's classes, top level or inside a chunk.
_PARSED: dict[int, tuple[str, Callable[[ReadDataStream], McapRecord]]] = {
    Opcode.HEADER: ("header", Header.read),
    Opcode.METADATA: ("metadata", Metadata.read),
    Opcode.ATTACHMENT: ("attachment", Attachment.read),
    Opcode.SCHEMA: ("schema", Schema.read),
    Opcode.CHANNEL: ("channel", Channel.read),
}
_IN_CHUNK = (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE)
_ALWAYS = (Opcode.HEADER, Opcode.METADATA, Opcode.ATTACHMENT)  # parsed on every walk


@dataclass
class ChunkData:
    """A chunk record: where it is, its time range, and its records when read."""

    offset: int
    start_time: int
    end_time: int
    records: bytes | None  # uncompressed records, when read


def open_mcap(p: Path) -> BinaryIO:
    """Open a log for reading; a FIFO, device or socket is refused at once (never read:
    a FIFO would block and a device may never end)."""
    try:
        fd = os.open(p, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except IsADirectoryError:
        raise LogError(f"{p}: is a directory, expected an MCAP log file") from None
    except OSError as exc:
        raise LogError(f"{p}: cannot read: {exc.strerror or exc}") from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        if stat.S_ISDIR(mode):
            raise LogError(f"{p}: is a directory, expected an MCAP log file")
        fifo, sock = stat.S_ISFIFO(mode), stat.S_ISSOCK(mode)
        kind = "a FIFO" if fifo else "a socket" if sock else "a device"
        raise LogError(f"{p}: is {kind}, not a regular file; expected an MCAP log file")
    return os.fdopen(fd, "rb")


class Walker:
    """Walks the top-level records of an MCAP file, stopping cleanly at a truncated tail.

    :meth:`records` yields ``(kind, item)``: "header", "metadata", "attachment" (its CRC
    checked), "chunk" (ChunkData),
    "data_end", "footer", and with ``data`` the schemas, channels and messages outside
    chunks (a file without messages has its schema and channel in the summary only);
    :meth:`mcap_records` yields mcap records with the chunks opened, as
    ``StreamReader.records`` does. ``truncated``: the file was cut short; ``position``:
    the byte after the last complete record."""

    def __init__(self, f: BinaryIO, path: Path, *, stop_at: int = 0) -> None:
        self.f = f
        self.path = path
        self.size = os.fstat(f.fileno()).st_size
        self.stop_at = stop_at  # 0: read to the end; else stop after this offset
        self.position = 0
        self.records_seen = 0
        self.truncated = False
        # A file that ends with the MCAP magic was finished by its writer: a record that
        # does not fit in it is damage, not a writer killed half-way.
        self.sealed = False
        if self.size >= 2 * len(MAGIC) + _RECORD.size:
            here = f.tell()
            f.seek(self.size - len(MAGIC))
            self.sealed = f.read(len(MAGIC)) == MAGIC
            f.seek(here)

    def _bad(self, what: str) -> LogError:
        return LogError(f"{self.path}: {what}")

    def records(
        self, *, read_chunks: bool, lazy_after_first: bool = False, data: bool = False
    ) -> Iterator[tuple[str, object]]:
        f = self.f
        head = f.read(len(MAGIC))
        if head != MAGIC:
            if MAGIC.startswith(head):
                raise self._bad("not an MCAP file (too short to hold the MCAP magic bytes)")
            raise self._bad("not an MCAP file (bad magic bytes)")
        pos = self.position = len(MAGIC)
        chunks = 0
        while True:
            if self.stop_at and pos >= self.stop_at:
                return
            head = f.read(_RECORD.size)
            if len(head) < _RECORD.size:
                if self.sealed:
                    raise self._bad(
                        f"damaged at byte {pos}: the file (finished, {self.size} bytes) ends "
                        "there without its footer record"
                    )
                self.truncated = True
                return
            opcode, length = _RECORD.unpack(head)
            body_at = pos + _RECORD.size
            end = body_at + length
            if end > self.size:
                if self.sealed:
                    raise self._bad(f"damaged at byte {pos}: a record (opcode 0x{opcode:02x}) "
                                    f"claims {length} bytes, past the end of the file "
                                    f"({self.size} bytes), though the file was finished")
                self.truncated = True  # the writer died in the middle of this record
                return
            if opcode == 0 or 0x0F < opcode < 0x80:
                raise self._bad(f"damaged at byte {pos}: unknown MCAP record opcode "
                                f"0x{opcode:02x}")  # fmt: skip
            if self.records_seen == 0 and opcode != Opcode.HEADER:
                raise self._bad("not an MCAP file (no header record after the magic bytes)")
            self.records_seen += 1
            if opcode == Opcode.CHUNK:
                want = read_chunks and not (lazy_after_first and chunks > 0)
                chunk = self.chunk(pos, length, read=want)
                chunks += 1
                self.position = end
                yield "chunk", chunk
            elif opcode in _ALWAYS or (data and (opcode in _PARSED or opcode == Opcode.MESSAGE)):
                record = _parse(opcode, f.read(length))
                if record is None:
                    raise self._bad(f"damaged MCAP record at byte {pos}")
                self.position = end
                yield _PARSED[opcode][0] if opcode in _PARSED else "message", record
            elif opcode == Opcode.DATA_END:
                f.seek(end)
                self.position = end
                yield "data_end", None
            elif opcode == Opcode.FOOTER:
                f.seek(end)
                self.position = min(end + len(MAGIC), self.size)
                if f.read(len(MAGIC)) != MAGIC:
                    self.truncated = True
                    return
                yield "footer", None
                return
            else:
                f.seek(end)
                self.position = end
            pos = end

    def mcap_records(self) -> Iterator[McapRecord | None]:
        """The records as mcap objects (Header, Metadata, Schema, Channel, Message; those of
        each chunk in turn; no indexes), None for the data end, then the summary's schemas
        and channels."""
        for kind, item in self.records(read_chunks=True, data=True):
            if kind == "chunk":
                assert isinstance(item, ChunkData) and item.records is not None
                yield from chunk_records(item.records, self.path, item.offset)
            elif kind == "data_end":
                yield None
            elif kind != "footer":
                assert isinstance(item, McapRecord)
                yield item

    def chunk_at(self, offset: int) -> ChunkData:
        """The chunk at byte ``offset`` (from a chunk index), read and checked."""
        self.f.seek(offset)
        opcode, length = _RECORD.unpack(self.f.read(_RECORD.size))
        if opcode != Opcode.CHUNK:
            raise self._bad(f"the chunk index points at byte {offset}, which holds no chunk")
        return self.chunk(offset, length, read=True)

    def chunk(self, pos: int, length: int, *, read: bool) -> ChunkData:
        """The chunk record at ``pos`` (the file is positioned after its opcode and length),
        its sizes checked; with ``read``, decompressed and its CRC checked."""
        f = self.f
        if length < _CHUNK_HEAD.size + 8:
            raise self._bad(f"chunk at byte {pos} is damaged (a record of {length} bytes is "
                            "too short for a chunk)")  # fmt: skip
        fixed = f.read(_CHUNK_HEAD.size)
        start, end_time, usize, crc, clen = _CHUNK_HEAD.unpack(fixed)
        if _CHUNK_HEAD.size + clen + 8 > length:
            raise self._bad(f"chunk at byte {pos} is damaged (its sizes do not add up)")
        compression = f.read(clen).decode("utf-8", "replace")
        (dlen,) = _U64.unpack(f.read(8))
        data_at = pos + _RECORD.size + _CHUNK_HEAD.size + clen + 8
        if data_at + dlen > pos + _RECORD.size + length:
            raise self._bad(f"chunk at byte {pos} is damaged (its sizes do not add up)")
        if usize > _MAX_CHUNK or (compression != "" and usize > _MAX_RATIO * dlen + 4096):
            raise self._bad(f"chunk at byte {pos} is damaged (it claims {usize} bytes "
                            f"uncompressed from {dlen} compressed; at most "
                            f"{min(_MAX_CHUNK, _MAX_RATIO * dlen + 4096)} are possible)")
        if not read:
            f.seek(pos + _RECORD.size + length)
            return ChunkData(pos, start, end_time, None)
        data = f.read(dlen)
        f.seek(pos + _RECORD.size + length)
        if compression == "zstd":
            try:
                records = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
            except zstandard.ZstdError as exc:
                raise self._bad(f"chunk at byte {pos} is damaged (zstd: {exc})") from None
        elif compression == "":
            records = data
        elif compression == "lz4":
            try:
                import lz4.frame
            except ImportError:
                raise self._bad(f"chunk at byte {pos} is lz4-compressed; install the lz4 "
                                "package") from None  # fmt: skip
            records = lz4.frame.decompress(data)
        else:
            raise self._bad(f"chunk at byte {pos}: unknown compression {compression!r}")
        if len(records) != usize:
            raise self._bad(f"chunk at byte {pos} is damaged (wrong uncompressed size)")
        if crc and zlib.crc32(records) != crc:
            raise self._bad(f"chunk at byte {pos} is damaged (CRC mismatch)")
        return ChunkData(pos, start, end_time, records)


def _parse(opcode: int, body: bytes) -> McapRecord | None:
    """One record body parsed by mcap's record class; None if it does not parse (damage)."""
    stream = ReadDataStream(BytesIO(body))
    if opcode == Opcode.ATTACHMENT and len(body) >= 4:  # mcap's reader skips this CRC
        crc = int.from_bytes(body[-4:], "little")
        if crc and zlib.crc32(body[:-4]) != crc:
            return None
    try:
        if opcode == Opcode.MESSAGE:
            return Message.read(stream, len(body))
        return _PARSED[opcode][1](stream)
    except Exception:  # noqa: BLE001 - any parse failure means a damaged record
        return None


def chunk_offsets(f: BinaryIO, walker: Walker, lo: int, hi: int) -> list[int]:
    """Byte offsets of the chunks whose message times overlap [lo, hi] (ns), in order:
    from the summary's chunk index (read by ``mcap``) when the file has one, else from
    each chunk's header (a file cut short)."""
    try:
        from mcap.reader import SeekingReader

        f.seek(0)
        summary = SeekingReader(f).get_summary()
    except Exception:  # noqa: BLE001 - no footer or summary: walk the chunk headers instead
        summary = None
    if summary is not None and summary.chunk_indexes:
        return sorted(
            c.chunk_start_offset
            for c in summary.chunk_indexes
            if c.message_end_time >= lo and c.message_start_time <= hi
        )
    f.seek(0)
    return [
        c.offset
        for kind, c in walker.records(read_chunks=False)
        if kind == "chunk" and isinstance(c, ChunkData) and c.end_time >= lo and c.start_time <= hi
    ]


def records_in(data: bytes, path: Path, offset: int) -> Iterator[tuple[int, int, int]]:
    """(opcode, body start, body end) of each record inside a chunk."""
    pos, end = 0, len(data)
    unpack = _RECORD.unpack_from
    while pos < end:
        if pos + _RECORD.size > end:
            raise LogError(f"{path}: chunk at byte {offset} is damaged (a record is cut)")
        opcode, length = unpack(data, pos)
        body = pos + _RECORD.size
        nxt = body + length
        if nxt > end:
            raise LogError(f"{path}: chunk at byte {offset} is damaged (a record is cut)")
        yield opcode, body, nxt
        pos = nxt


def chunk_records(
    data: bytes, path: Path, offset: int, kinds: tuple[int, ...] = _IN_CHUNK
) -> Iterator[McapRecord]:
    """The records inside a chunk whose opcodes are in ``kinds``, as mcap objects."""
    for opcode, body, end in records_in(data, path, offset):
        if opcode in kinds:
            record = _parse(opcode, data[body:end])
            if record is None:
                raise LogError(f"{path}: chunk at byte {offset} is damaged")
            yield record


def channel_payloads(data: bytes, channel_id: int, path: Path, offset: int) -> list[memoryview]:
    """The payloads of the messages of ``channel_id`` inside a chunk, in order.

    The hot loop of the slot reader: one ``unpack_from`` per record, payloads as views.
    """
    out: list[memoryview] = []
    view = memoryview(data)
    head = _MSG_PEEK.unpack_from
    pos, end = 0, len(data)
    skip = _RECORD.size + _MSG_HEAD.size
    append = out.append
    while pos < end:
        if pos + _MSG_PEEK.size > end:
            if pos + _RECORD.size <= end and data[pos] != Opcode.MESSAGE:
                (length,) = _U64.unpack_from(data, pos + 1)
                pos += _RECORD.size + length
                continue
            raise LogError(f"{path}: chunk at byte {offset} is damaged (a record is cut)")
        opcode, length, channel = head(data, pos)
        nxt = pos + _RECORD.size + length
        if nxt > end:
            raise LogError(f"{path}: chunk at byte {offset} is damaged (a record is cut)")
        if opcode == Opcode.MESSAGE and channel == channel_id:
            append(view[pos + skip : nxt])
        pos = nxt
    return out


def last_log_time(data: bytes, channel_id: int, path: Path, offset: int) -> int | None:
    """The log_time of the last message of ``channel_id`` in the chunk (None: none)."""
    last = None
    head = _MSG_HEAD.unpack_from
    for opcode, body, _ in records_in(data, path, offset):
        if opcode == Opcode.MESSAGE:
            channel, _, log_time, _ = head(data, body)
            if channel == channel_id:
                last = log_time
    return last


def find_channel(
    data: bytes, path: Path, offset: int, *, topic: str, encoding: str, schema: str
) -> int:
    """The id of the channel of ``topic`` (message ``encoding``, schema named ``schema``)
    declared in a chunk's records (0 if it is not there)."""
    schemas: dict[int, str] = {}
    for record in chunk_records(data, path, offset, (Opcode.SCHEMA, Opcode.CHANNEL)):
        if isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, Channel) and (record.topic, record.message_encoding,
                                              schemas.get(record.schema_id)) == (
            topic, encoding, schema):  # fmt: skip
            return int(record.id)
    return 0


__all__ = [
    "ChunkData",
    "Walker",
    "chunk_offsets",
    "channel_payloads",
    "chunk_records",
    "find_channel",
    "last_log_time",
    "open_mcap",
    "records_in",
]
