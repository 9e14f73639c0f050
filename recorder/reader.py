"""Read a corraoi MCAP log back into the SlotBlocks that were recorded.

``open_log(path)`` checks the file and returns a :class:`RunLog`; ``RunLog.blocks()``
streams the slots (memory bounded by one chunk plus one block). A log whose writer was
killed (no footer, or a ``.partial`` file) is read up to its last complete chunk and
reported as cut short.

The reader walks the file's records itself (with the ``mcap`` package's record classes
for the rare records) because it must tell a truncated tail (recover) from a damaged
chunk (refuse), which the ``mcap`` readers do not distinguish.
"""

from __future__ import annotations

import json
import os
import stat
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import BinaryIO

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Header, Metadata

from corraoi.block import FIELDS, RunConfig, SlotBlock
from corraoi.errors import CorraoiError

from .errors import LogError
from .format import (
    END_METADATA,
    FORMAT_NAME,
    FORMAT_VERSION,
    MESSAGE_ENCODING,
    NS_PER_SLOT,
    RUN_METADATA,
    SCHEMA_NAME,
    SWEEP_METADATA,
    TOPIC,
    decode_messages,
    empty_block,
)
from .paths import lock_holder
from .vocab import MAGIC

#: The largest uncompressed chunk the reader accepts (writers close chunks at 64 MiB).
_MAX_CHUNK = 1 << 28
#: The most a chunk can expand when decompressed (zstd's limit is far below this).
_MAX_RATIO = 1 << 16
_RECORD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression len
_MSG_HEAD = struct.Struct("<HIQQ")  # channel, sequence, log_time, publish_time
_MSG_PEEK = struct.Struct("<BQH")  # opcode, length, and (for a message) its channel
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")


@dataclass
class _Chunk:
    offset: int
    start_time: int
    end_time: int
    records: bytes | None  # uncompressed records, when read


@dataclass
class RunLog:
    """An opened corraoi log. ``blocks()`` and ``read_all()`` give the slots back."""

    path: Path
    config: RunConfig
    metadata: dict[str, str]
    format_version: int
    n_slots: int
    #: The writer did not finish: no footer, or fewer slots than the horizon.
    cut_short: bool
    #: The file has its footer (the writer closed it, possibly after an interrupt).
    finished: bool
    #: "complete", "interrupted" (finished early, e.g. Ctrl-C) or "truncated" (killed).
    status: str
    #: The ``corraoi.end`` metadata of a finished file ({} otherwise).
    end: dict[str, str] = field(default_factory=dict)
    library: str = ""
    n_chunks: int = 0
    #: With ``open_log(salvage=True)``: what was wrong where reading stopped ("" if nothing).
    damage: str = ""
    #: PID of the process writing the file right now (it holds the writer's lock), if any.
    writer: int | None = None
    _channel_id: int = field(default=0, repr=False)
    #: byte offset after the last complete chunk seen at open: blocks() stops there
    _data_end: int = field(default=0, repr=False)

    def __repr__(self) -> str:
        return (
            f"RunLog({str(self.path)!r}, {self.config.label}, "
            f"{self.n_slots}/{self.config.horizon} slots, {self.status})"
        )

    @property
    def label(self) -> str:
        return self.config.label

    @property
    def horizon(self) -> int:
        return self.config.horizon

    @property
    def summary(self) -> str:
        """One line on how complete the log is."""
        T = self.config.horizon
        if self.status == "complete":
            return f"complete: {self.n_slots} of {T} slots"
        if self.status == "failed":
            return (
                f"failed: the run stopped on an error after slot {self.n_slots} of {T}: "
                f"{self.end.get('error', '(no message)')}"
            )
        if self.status == "damaged":
            return f"damaged: {self.damage}; read {self.n_slots} of {T} slots before the damage"
        if self.status == "interrupted":
            return (
                f"cut short: the run was stopped after slot {self.n_slots} of {T} "
                "(the file was finished properly)"
            )
        if self.writer is not None:
            who = f"process {self.writer}" if self.writer else "another process"
            return (
                f"being written right now by {who}: {self.n_slots} of {T} slots so far, up "
                "to the last complete chunk"
            )
        return (
            f"cut short: the writer did not finish the file (killed?); recovered "
            f"{self.n_slots} of {T} slots, up to the last complete chunk"
        )

    def blocks(self, block: int = 1000) -> Iterator[SlotBlock]:
        """The recorded slots in blocks of ``block`` slots (the last one may be shorter)."""
        if block < 1:
            raise ValueError(f"block must be >= 1, got {block}")
        pending: list[SlotBlock] = []
        have = 0
        for part in self._chunk_blocks():
            pending.append(part)
            have += len(part)
            while have >= block:
                whole = pending[0] if len(pending) == 1 else SlotBlock.concat(pending)
                yield _slice(whole, 0, block)
                rest = _slice(whole, block, len(whole))
                pending = [rest] if len(rest) else []
                have = len(rest)
        if have:
            yield pending[0] if len(pending) == 1 else SlotBlock.concat(pending)

    def read_all(self) -> SlotBlock:
        """Every recorded slot in one block (memory grows with the log: prefer blocks())."""
        parts = list(self.blocks(block=max(self.n_slots, 1)))
        if not parts:
            return empty_block(self.config.instance.K)
        return parts[0] if len(parts) == 1 else SlotBlock.concat(parts)

    def window(self, first: int, last: int) -> Iterator[SlotBlock]:
        """The slots ``first..last`` (inclusive, 1-based t), one block per chunk read.

        Chunks whose time range lies outside the window are skipped without being
        decompressed or decoded: their ranges come from the summary's chunk index when the
        file has one, else from each chunk's header (a file cut short).
        """
        first, last = max(int(first), 1), min(int(last), self.n_slots)
        if first > last:
            return
        K, n = self.config.instance.K, self.config.instance.n_states
        lo, hi = first * NS_PER_SLOT, last * NS_PER_SLOT
        expected = first
        with _open(self.path) as f:
            walker = _Walker(f, self.path, stop_at=self._data_end)
            for offset in _chunk_offsets(f, walker, lo, hi):
                f.seek(offset)
                opcode, length = _RECORD.unpack(f.read(_RECORD.size))
                if opcode != Opcode.CHUNK:
                    raise LogError(f"{self.path}: the chunk index points at byte {offset}, "
                                   "which holds no chunk")
                chunk = walker._chunk(offset, length, read=True)
                assert chunk.records is not None
                payloads = _payloads(chunk.records, self._channel_id, self.path, offset)
                where = f"{self.path}: chunk at byte {offset}"
                part = decode_messages(payloads, K, n, where=where)
                keep = (part.t >= first) & (part.t <= last)
                if not keep.any():
                    continue
                idx = np.flatnonzero(keep)
                part = _slice(part, int(idx[0]), int(idx[-1]) + 1)
                t = part.t
                if t[0] != expected or not np.array_equal(
                    t, np.arange(expected, expected + len(t), dtype=np.int64)
                ):
                    raise LogError(
                        f"{where}: slots are not consecutive (expected slot {expected}, "
                        f"got {int(t[0])}..{int(t[-1])})"
                    )
                expected += len(part)
                yield part
        if expected != last + 1:
            raise LogError(f"{self.path}: slots {expected}..{last} are missing from the log")

    def _chunk_blocks(self) -> Iterator[SlotBlock]:
        K, n = self.config.instance.K, self.config.instance.n_states
        expected = 1
        with _open(self.path) as f:
            walker = _Walker(f, self.path, stop_at=self._data_end)
            for kind, item in walker.records(read_chunks=True):
                if kind != "chunk":
                    continue
                assert isinstance(item, _Chunk) and item.records is not None
                payloads = _payloads(item.records, self._channel_id, self.path, item.offset)
                if not payloads:
                    continue
                where = f"{self.path}: chunk at byte {item.offset}"
                part = decode_messages(payloads, K, n, where=where)
                t = part.t
                if t[0] != expected or not np.array_equal(
                    t, np.arange(expected, expected + len(t), dtype=np.int64)
                ):
                    raise LogError(
                        f"{where}: slots are not consecutive (expected slot {expected}, "
                        f"got {int(t[0])}..{int(t[-1])})"
                    )
                if expected + len(part) - 1 > self.n_slots:
                    part = _slice(part, 0, self.n_slots - expected + 1)
                expected += len(part)
                if len(part):
                    yield part
                if expected > self.n_slots:
                    return


def open_log(path: str | os.PathLike[str], *, verify: bool = True, salvage: bool = False) -> RunLog:
    """Open a corraoi MCAP log, checking what it is and how complete it is.

    With ``verify`` (the default) every chunk is decompressed and its CRC checked now, so
    a damaged file is refused here rather than half-way through a replay. Raises
    :class:`~recorder.errors.LogError` with a one-line message when the file cannot be used:
    a finished file with a record that does not fit, a bad CRC, a bad size or an invalid
    slot is *damaged* (file, byte offset, what is wrong), which is told apart from a file
    whose writer was killed (*cut short*: no footer, a torn last record).

    With ``salvage`` every chunk is decoded and validated, and the first damage ends the
    log instead of raising: the RunLog holds the slots before it, ``status`` is
    "damaged" and ``damage`` says what and where (``corraoi recover`` uses this).
    """
    p = Path(path)
    if not p.exists() and not p.is_symlink():
        part = p.with_name(p.name + ".partial")
        if part.exists():
            raise LogError(
                f"{p}: no such file, but {part} is there (a writer that did not finish, or "
                f"one still writing): read it with `corraoi info {part}`, finish it with "
                f"`corraoi recover {part}`"
            )
        raise LogError(f"{p}: no such file")
    if p.is_dir():
        raise LogError(f"{p}: is a directory, expected an MCAP log file")
    with _open(p) as f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            raise LogError(f"{p}: empty file (0 bytes), not an MCAP log")
        walker = _Walker(f, p)
        damage = ""
        expected = 1
        library = ""
        run_md: dict[str, str] | None = None
        end_md: dict[str, str] = {}
        channel_id = 0
        n_chunks = 0
        n_slots = 0
        data_end = 0
        finished = False
        sweep = False  # a sweep log's metadata was seen
        records = walker.records(read_chunks=True, lazy_after_first=not (verify or salvage))
        while True:
            try:
                kind, item = next(records)
            except StopIteration:
                break
            except LogError as exc:
                if not salvage or run_md is None or not n_chunks:
                    raise
                damage = _strip_path(exc, p)
                break
            if kind == "header":
                assert isinstance(item, Header)
                library = item.library
            elif kind == "metadata":
                assert isinstance(item, Metadata)
                if item.name == RUN_METADATA and run_md is None:
                    run_md = dict(item.metadata)
                    _check_run_metadata(p, run_md, library)
                elif item.name == END_METADATA:
                    end_md = dict(item.metadata)
                elif item.name == SWEEP_METADATA:
                    sweep = True
            elif kind == "chunk":
                assert isinstance(item, _Chunk)
                if run_md is None:
                    raise _not_ours(p, library, sweep)
                try:
                    if item.records is not None:
                        if not channel_id:
                            channel_id = _find_channel(item.records, p, item.offset)
                        last = _last_slot(item.records, channel_id, p, item.offset)
                        if salvage:
                            expected = _validate_chunk(item, run_md, channel_id, p, expected)
                    else:  # not verified: trust the chunk header (our chunks hold only slots)
                        last = item.end_time // NS_PER_SLOT
                except LogError as exc:
                    if not salvage or not n_chunks:
                        raise
                    damage = _strip_path(exc, p)
                    break
                if last:
                    n_slots = max(n_slots, last)
                n_chunks += 1
                data_end = walker.position
            elif kind == "footer":
                finished = True
            elif kind == "data_end" and run_md is None:
                raise _not_ours(p, library, sweep)
        if run_md is None:
            if walker.records_seen == 0:
                raise LogError(
                    f"{p}: an MCAP file cut off before its first record; nothing to read"
                )
            if walker.records_seen <= 1 and library.startswith("corraoi/"):
                raise LogError(
                    f"{p}: the writer stopped before it wrote the run configuration; "
                    "nothing to read"
                )
            raise _not_ours(p, library, sweep)
        if n_slots and not channel_id and verify:
            raise LogError(f"{p}: no {TOPIC} channel with schema {SCHEMA_NAME}")
    try:
        config = RunConfig.from_dict(json.loads(run_md["config"]))
    except (CorraoiError, KeyError, TypeError, ValueError) as exc:
        raise LogError(f"{p}: the run configuration in the log is unusable: {exc}") from None
    _check_agrees(p, run_md, config)
    if n_slots > config.horizon:
        raise LogError(f"{p}: {n_slots} slots recorded for a horizon of {config.horizon}")
    if damage:
        finished = False
        status = "damaged"
    elif not finished:
        status = "truncated"
    elif end_md.get("status") == "failed":
        status = "failed"
    elif n_slots < config.horizon:
        status = "interrupted"
    else:
        status = "complete"
    if finished and end_md.get("slots") not in (None, str(n_slots)):
        raise LogError(
            f"{p}: the file says it holds {end_md['slots']} slots but {n_slots} were found"
        )
    return RunLog(
        path=p,
        config=config,
        metadata=run_md,
        format_version=int(run_md["format_version"]),
        n_slots=n_slots,
        cut_short=status != "complete",
        finished=finished,
        status=status,
        end=end_md,
        library=library,
        n_chunks=n_chunks,
        damage=damage,
        writer=None if finished else lock_holder(p),
        _channel_id=channel_id or 1,
        _data_end=data_end,
    )


# ---------------------------------------------------------------------------- internals


def _open(p: Path) -> BinaryIO:
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
        kind = (
            "a FIFO" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else ("a device")
        )
        raise LogError(f"{p}: is {kind}, not a regular file; expected an MCAP log file")
    return os.fdopen(fd, "rb")


def _check_agrees(p: Path, md: dict[str, str], config: RunConfig) -> None:
    """The flat fields of the run metadata must say what its ``config`` says: MCAP has no
    checksum over metadata, so a flipped digit in either shows up as a disagreement."""
    facts = {
        "seed": str(config.seed),
        "horizon": str(config.horizon),
        "arms": str(config.instance.K),
        "states": str(config.instance.n_states),
        "policy": config.policy.name,
        "instance": config.instance.name,
    }
    for key, value in facts.items():
        if key in md and md[key] != value:
            raise LogError(
                f"{p}: damaged run metadata: {key} is {md[key]!r} in its own field but "
                f"{value!r} in the configuration; expected both to agree"
            )


def _strip_path(exc: LogError, p: Path) -> str:
    text = str(exc)
    prefix = f"{p}: "
    return text[len(prefix) :] if text.startswith(prefix) else text


def _validate_chunk(
    chunk: _Chunk,
    run_md: dict[str, str] | None,
    channel_id: int,
    p: Path,
    expected: int,
) -> int:
    """Decode and check one chunk's slots (salvage); returns the next slot expected."""
    assert chunk.records is not None and run_md is not None
    try:
        config = RunConfig.from_dict(json.loads(run_md["config"]))
    except (CorraoiError, KeyError, TypeError, ValueError) as exc:
        raise LogError(f"{p}: the run configuration in the log is unusable: {exc}") from None
    payloads = _payloads(chunk.records, channel_id, p, chunk.offset)
    if not payloads:
        return expected
    where = f"{p}: chunk at byte {chunk.offset}"
    part = decode_messages(payloads, config.instance.K, config.instance.n_states, where=where)
    t = part.t
    if t[0] != expected or not np.array_equal(
        t, np.arange(expected, expected + len(t), dtype=np.int64)
    ):
        raise LogError(f"{where}: slots are not consecutive (expected slot {expected}, got "
                       f"{int(t[0])}..{int(t[-1])})")  # fmt: skip
    return expected + len(t)


def _not_ours(p: Path, library: str, sweep: bool = False) -> LogError:
    if sweep:
        return LogError(
            f"{p}: a corraoi sweep log (aggregated curves), not the log of one run; "
            "draw it with `corraoi figure`"
        )
    who = f" (written by {library!r})" if library else ""
    return LogError(f"{p}: an MCAP file but not a corraoi log{who}: no {RUN_METADATA} metadata")


def _check_run_metadata(p: Path, md: dict[str, str], library: str) -> None:
    if md.get("format") != FORMAT_NAME or "config" not in md:
        raise _not_ours(p, library)
    try:
        version = int(md.get("format_version", ""))
    except ValueError:
        raise LogError(
            f"{p}: format_version {md.get('format_version')!r} is not an integer"
        ) from None
    if version > FORMAT_VERSION:
        raise LogError(
            f"{p}: written in log format version {version}, newer than the version "
            f"{FORMAT_VERSION} this corraoi reads; upgrade corraoi to read it"
        )
    if version < 1:
        raise LogError(f"{p}: unknown log format version {version}")


class _Walker:
    """Walks the top-level records of an MCAP file, stopping cleanly at a truncated tail."""

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
        self, *, read_chunks: bool, lazy_after_first: bool = False
    ) -> Iterator[tuple[str, object]]:
        f = self.f
        head = f.read(len(MAGIC))
        if head != MAGIC:
            if MAGIC.startswith(head):
                raise self._bad("not an MCAP file (too short to hold the MCAP magic bytes)")
            raise self._bad("not an MCAP file (bad magic bytes)")
        pos = len(MAGIC)
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
                    raise self._bad(
                        f"damaged at byte {pos}: a record (opcode 0x{opcode:02x}) claims "
                        f"{length} bytes, past the end of the file ({self.size} bytes), "
                        "though the file was finished"
                    )
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
                chunk = self._chunk(pos, length, read=want)
                chunks += 1
                self.position = end
                yield "chunk", chunk
            elif opcode in (Opcode.HEADER, Opcode.METADATA):
                body = f.read(length)
                stream = ReadDataStream(BytesIO(body))
                try:
                    record: object = (
                        Header.read(stream) if opcode == Opcode.HEADER else Metadata.read(stream)
                    )
                except Exception:  # noqa: BLE001 - any parse failure means a damaged record
                    raise self._bad(f"damaged MCAP record at byte {pos}") from None
                self.position = end
                yield ("header" if opcode == Opcode.HEADER else "metadata"), record
            elif opcode == Opcode.DATA_END:
                f.seek(end)
                self.position = end
                yield "data_end", None
            elif opcode == Opcode.FOOTER:
                f.seek(end)
                self.position = end
                if f.read(len(MAGIC)) != MAGIC:
                    self.truncated = True
                    return
                yield "footer", None
                return
            else:
                f.seek(end)
                self.position = end
            pos = end

    def _chunk(self, pos: int, length: int, *, read: bool) -> _Chunk:
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
            raise self._bad(
                f"chunk at byte {pos} is damaged (it claims {usize} bytes uncompressed from "
                f"{dlen} compressed; at most {min(_MAX_CHUNK, _MAX_RATIO * dlen + 4096)} "
                "are possible)"
            )
        if not read:
            f.seek(pos + _RECORD.size + length)
            return _Chunk(pos, start, end_time, None)
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
                raise self._bad(
                    f"chunk at byte {pos} is lz4-compressed; install the lz4 package"
                ) from None
            records = lz4.frame.decompress(data)
        else:
            raise self._bad(f"chunk at byte {pos}: unknown compression {compression!r}")
        if len(records) != usize:
            raise self._bad(f"chunk at byte {pos} is damaged (wrong uncompressed size)")
        if crc and zlib.crc32(records) != crc:
            raise self._bad(f"chunk at byte {pos} is damaged (CRC mismatch)")
        return _Chunk(pos, start, end_time, records)


def _chunk_offsets(f: BinaryIO, walker: _Walker, lo: int, hi: int) -> list[int]:
    """Byte offsets of the chunks whose message times overlap [lo, hi] (ns), in order."""
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
        if kind == "chunk" and isinstance(c, _Chunk) and c.end_time >= lo and c.start_time <= hi
    ]


def _records_in(data: bytes, path: Path, offset: int) -> Iterator[tuple[int, int, int]]:
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


def _payloads(data: bytes, channel_id: int, path: Path, offset: int) -> list[memoryview]:
    """The payloads of the messages of ``channel_id`` inside a chunk, in order.

    The hot loop of the reader: one ``unpack_from`` per record, payloads as views.
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


def _last_slot(data: bytes, channel_id: int, path: Path, offset: int) -> int:
    """The log_time-derived slot of the last message of ``channel_id`` in the chunk (0: none)."""
    last = 0
    head = _MSG_HEAD.unpack_from
    for opcode, body, _ in _records_in(data, path, offset):
        if opcode == Opcode.MESSAGE:
            channel, _, log_time, _ = head(data, body)
            if channel == channel_id:
                last = log_time // NS_PER_SLOT
    return last


def _string(data: bytes, at: int) -> tuple[str, int]:
    (n,) = _U32.unpack_from(data, at)
    at += 4
    return data[at : at + n].decode("utf-8", "replace"), at + n


def _find_channel(data: bytes, path: Path, offset: int) -> int:
    """The id of the slot channel declared in the first chunk (0 if it is not there)."""
    schemas: dict[int, str] = {}
    for opcode, body, _ in _records_in(data, path, offset):
        try:
            if opcode == Opcode.SCHEMA:
                (sid,) = _U16.unpack_from(data, body)
                name, _ = _string(data, body + 2)
                schemas[sid] = name
            elif opcode == Opcode.CHANNEL:
                cid, sid = struct.unpack_from("<HH", data, body)
                topic, at = _string(data, body + 4)
                encoding, _ = _string(data, at)
                if (
                    topic == TOPIC
                    and encoding == MESSAGE_ENCODING
                    and schemas.get(sid) == SCHEMA_NAME
                ):
                    return int(cid)
        except struct.error:
            raise LogError(f"{path}: chunk at byte {offset} is damaged") from None
    return 0


def _slice(b: SlotBlock, start: int, stop: int) -> SlotBlock:
    return SlotBlock(**{f: b.column(f)[start:stop] for f in FIELDS})
