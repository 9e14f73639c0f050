"""``corraoi recover``: rewrite a log whose writer died into a finished, indexed MCAP file.

A writer killed mid-run leaves a file (usually ``RUN.mcap.partial``) without summary or
footer: the corraoi reader and ``mcap.stream_reader`` read its complete chunks, but the
indexed readers (``mcap.reader.make_reader``, most MCAP tools) find nothing. ``recover``
copies the header, the run metadata, the schema, the channel and every message of the
complete chunks -- payloads byte for byte, chunked as the writer chunks them -- and
finishes the copy with the ``corraoi.end`` record, chunk indexes, summary and footer.

The copy is written to a temporary file beside the destination, read back with the
corraoi reader, and only then renamed into place, so an error leaves nothing behind and
an existing file is never replaced without ``overwrite``. ``recover RUN.mcap.partial -o
RUN.mcap`` is the usual call; the source is never modified.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

from corraoi.files.partial import PARTIAL_SUFFIX, PartialFile, partial_path

from .runs import require_slots

#: The name a recovered copy is written under while it is made, when ``.partial`` would be
#: the source itself (``recover RUN.mcap.partial -o RUN.mcap``).
RECOVER_SUFFIX = ".recovering"

if TYPE_CHECKING:
    from corraoi.recorder.slotlog.reader import RunLog

#: Chunks of the copy are closed by slot count like the writer's; this only caps a chunk.
_CHUNK_BYTES = 64 * 1024 * 1024


@dataclass(frozen=True)
class Recovered:
    """What :func:`recover` wrote."""

    source: Path
    path: Path
    slots: int
    horizon: int
    #: How the source ended: "truncated" (killed), "interrupted" or "complete".
    source_status: str
    #: How the copy reads back: "complete" or "interrupted" (finished, fewer slots).
    status: str
    #: Bytes at the end of the source that held no complete record (the torn tail).
    dropped_bytes: int
    #: What was damaged in the source, and where ("" when nothing was): the copy ends there.
    damage: str = ""

    def to_dict(self) -> dict[str, Any]:
        """What ``corraoi recover --json`` prints."""
        return {
            "source": str(self.source),
            "output": str(self.path),
            "slots": self.slots,
            "horizon": self.horizon,
            "source_status": self.source_status,
            "status": self.status,
            "dropped_bytes": self.dropped_bytes,
            "damage": self.damage or None,
        }


def default_output(source: str | os.PathLike[str]) -> Path:
    """``RUN.mcap.partial`` and ``RUN.mcap`` -> ``RUN.recovered.mcap`` beside them; any other
    name gets ``.recovered.mcap`` appended."""
    src = Path(source)
    name = src.name.removesuffix(".partial")
    base = name.removesuffix(".mcap")
    return src.with_name(f"{base}.recovered.mcap")


def recover(
    source: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    overwrite: bool = False,
) -> Recovered:
    """Rewrite the corraoi log ``source`` into a finished, indexed log at ``out``.

    Raises :class:`~corraoi.errors.LogError` when ``source`` is not a readable corraoi log
    (missing, not MCAP, another tool's, a newer format, a damaged chunk) and
    :class:`~corraoi.errors.OutputError` when ``out`` exists (unless ``overwrite``), is a
    directory, or is the source itself. Nothing is written on error.
    """
    from corraoi.errors import OutputError
    from corraoi.recorder.slotlog.reader import open_log

    src = Path(source)
    log = require_slots(open_log(src, salvage=True), "recover")
    dest = _check_dest(src, Path(out), overwrite=overwrite)
    # RUN.mcap.partial -> RUN.mcap: the copy cannot be written under the source's name
    suffix = RECOVER_SUFFIX if partial_path(dest).resolve() == src.resolve() else PARTIAL_SUFFIX
    # a copy left by a recover that was stopped is made again from the source: never in the way
    target = PartialFile(dest, overwrite=overwrite, what="recovered log", suffix=suffix,
                         replaceable=lambda _: True).create()  # fmt: skip
    tmp = target.partial
    try:
        with src.open("rb") as fin:
            consumed = _copy(log, fin, target.file)
        target.sync()
        if log.damage:
            consumed = log._data_end
        size = src.stat().st_size
        check = open_log(tmp)
        if check.n_slots != log.n_slots or not check.finished:
            from corraoi.errors import LogError

            raise LogError(f"{src}: the rewritten log does not read back ({check.summary})")
    except OSError as exc:
        target.discard()
        raise OutputError(f"{dest}: cannot write the recovered log: {_reason(exc)}") from None
    except BaseException:
        target.discard()
        raise
    target.publish(sync=False)
    return Recovered(
        source=src,
        path=dest,
        slots=log.n_slots,
        horizon=log.config.horizon,
        source_status=log.status,
        status=check.status,
        dropped_bytes=max(size - consumed, 0) if not log.finished else 0,
        damage=f"{src}: {log.damage}" if log.damage else "",
    )


def _copy(log: RunLog, fin: BinaryIO, fout: BinaryIO) -> int:
    """Copy the records of ``log`` (open as ``fin``) into a new MCAP writer on ``fout``.

    Returns the byte offset after the last complete record read from the source.
    """
    from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
    from mcap.writer import CompressionType, Writer

    from corraoi.engine.block import SourcesBlock
    from corraoi.errors import LogError
    from corraoi.recorder.slotlog.decode import decode_messages
    from corraoi.recorder.slotlog.encode import end_metadata as make_end
    from corraoi.recorder.slotlog.encode import sources_end_metadata
    from corraoi.recorder.vocab import (
        NS_PER_SLOT,
        mcap_index_types,
        slot_topic,
    )
    from corraoi.recorder.vocab import RUN_END_METADATA as END_METADATA
    from corraoi.recorder.vocab import SLOT_FLUSH_EVERY as FLUSH_EVERY
    from corraoi.recorder.walk import Walker

    src, cfg, n_slots = log.path, log.config, log.n_slots
    M = cfg.sources  # a run of several sources: a slot channel per source
    topics = {slot_topic(m, M): m for m in range(1, M + 1)}
    #: each slot channel's source (from 1), and the last payload of each source
    slot_channels: dict[int, int] = {}
    last_payloads: dict[int, bytes] = {}
    try:
        every = max(int(log.metadata.get("flush_every", FLUSH_EVERY)), 1)
    except ValueError:
        every = FLUSH_EVERY
    complete = _complete_length(fin, src)
    if log.damage:  # stop before the damaged record: what follows is not trusted
        complete = min(complete, log._data_end)
    fin.seek(0)
    writer = Writer(
        fout, chunk_size=_CHUNK_BYTES, compression=CompressionType.ZSTD,
        index_types=mcap_index_types(bool(log.attachments)),
    )  # fmt: skip
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    started = False
    written = 0
    for rec in Walker(fin, src, stop_at=complete).mcap_records():
        if rec is None:  # the data end: the summary is the writer's to make
            break
        if isinstance(rec, Header):
            writer.start(profile=rec.profile, library=rec.library)
            started = True
        elif isinstance(rec, Metadata):
            if rec.name != END_METADATA:
                writer.add_metadata(rec.name, dict(rec.metadata))
        elif isinstance(rec, Attachment):  # a plug-in's source, byte for byte
            writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type,
                                  rec.data)  # fmt: skip
        elif isinstance(rec, Schema):
            if rec.id not in schemas:
                schemas[rec.id] = writer.register_schema(
                    name=rec.name, encoding=rec.encoding, data=rec.data
                )
        elif isinstance(rec, Channel):
            if rec.id not in channels:
                channels[rec.id] = writer.register_channel(
                    topic=rec.topic,
                    message_encoding=rec.message_encoding,
                    schema_id=schemas.get(rec.schema_id, 0),
                    metadata=dict(rec.metadata),
                )
                if rec.topic in topics:
                    slot_channels[rec.id] = topics[rec.topic]
        elif isinstance(rec, Message):
            if rec.channel_id not in channels:
                continue
            is_slot = rec.channel_id in slot_channels
            t = rec.log_time // NS_PER_SLOT
            if is_slot and t > n_slots:
                continue
            writer.add_message(
                channels[rec.channel_id], rec.log_time, rec.data, rec.publish_time,
                rec.sequence,
            )  # fmt: skip
            if is_slot:
                m = slot_channels[rec.channel_id]
                written += m == M  # a slot is written with its last source's message
                last_payloads[m] = rec.data
                if t % every == 0 and m == M:
                    writer.flush()
    if not started:
        raise LogError(f"{src}: no MCAP header record")
    if written != n_slots:
        raise LogError(f"{src}: found {written} slot messages where the reader found {n_slots}")
    K, n = cfg.K, cfg.n_states
    lasts = [decode_messages([last_payloads[m]], K, n, where=str(src))
             for m in range(1, M + 1) if m in last_payloads]  # fmt: skip
    end: dict[str, Any]
    if M > 1:
        many = SourcesBlock(tuple(lasts)) if len(lasts) == M else None
        end = sources_end_metadata(slots=n_slots, horizon=cfg.horizon, last=many)
    else:
        end = make_end(slots=n_slots, horizon=cfg.horizon, last=lasts[0] if lasts else None)
    end["recovered_from"] = f"{src.name} ({log.status}, {n_slots} slots)"
    writer.add_metadata(END_METADATA, end)
    writer.finish()
    return complete


def _complete_length(f: BinaryIO, path: Path) -> int:
    """Bytes from the start of the file to the end of its last complete record (with the
    closing magic after a footer), as the MCAP walker finds them; damage ends the count
    where it starts."""
    from corraoi.errors import LogError
    from corraoi.recorder.walk import Walker

    f.seek(0)
    walker = Walker(f, path)
    try:
        for _ in walker.records(read_chunks=False):
            pass
    except LogError:
        pass
    return walker.position


def _check_dest(src: Path, dest: Path, *, overwrite: bool) -> Path:
    """Refuse the source itself as the destination (the rest is PartialFile's check)."""
    from corraoi.errors import OutputError

    if dest.exists() or dest.is_symlink():
        try:
            same = os.path.samefile(src, dest)
        except OSError:
            same = False
        if same:
            raise OutputError(f"{dest}: is the log being recovered; give another path with -o")
    return dest


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)
