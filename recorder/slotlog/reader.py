"""Read a corraoi MCAP log back into the SlotBlocks that were recorded (a run of several
sources: :class:`~corraoi.engine.block.SourcesBlock` s, one SlotBlock per source's channel).

``open_log(path)`` checks the file and returns a :class:`RunLog`; ``RunLog.blocks()``
streams the slots (memory bounded by one chunk plus one block). A log whose writer was
killed (no footer, or a ``.partial`` file) is read up to its last complete chunk and
reported as cut short.

The records are walked by :mod:`corraoi.recorder.walk`, the one MCAP walker, which tells a
truncated tail (recover) from a damaged chunk (refuse); this module reads the slots.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.records import Attachment, Header, Metadata

from corraoi._version import __version__
from corraoi.engine.block import RunConfig, SlotBlock, SourcesBlock
from corraoi.engine.slot_record import OPTIONAL, record_for
from corraoi.errors import CorraoiError, CorraoiWarning, LogError
from corraoi.files.locks import lock_holder
from corraoi.limits import MAX_HORIZON
from corraoi.recorder.vocab import (
    LACKING_FORMAT_VERSION,
    MESSAGE_ENCODING,
    NS_PER_SLOT,
    PROVENANCE_METADATA,
    RUN_END_METADATA,
    RUN_METADATA,
    SLOT_SCHEMA_NAME,
    SLOT_TOPIC,
    SWEEP_METADATA,
    slot_topic,
)
from corraoi.recorder.walk import (
    ChunkData,
    Walker,
    channel_payloads,
    chunk_offsets,
    find_channel,
    last_log_time,
    open_mcap,
)

from .decode import check_agrees, check_run_metadata, decode_messages, empty_block, not_a_run_log


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
    #: The ``corraoi.provenance`` metadata ({} in an older log; Provenance.read parses it)
    provenance: dict[str, str] = field(default_factory=dict)
    #: (name, media type, bytes) of each file the log carries: each plug-in's source
    attachments: list[tuple[str, str, bytes]] = field(default_factory=list)
    _channel_id: int = field(default=0, repr=False)
    #: the channel of each source of a run of several sources (source m's is [m - 1])
    _source_channels: tuple[int, ...] = field(default=(), repr=False)
    #: byte offset after the last complete chunk seen at open: blocks() stops there
    _data_end: int = field(default=0, repr=False)
    #: the unknown slot fields already named in a warning
    _unknown: list[str] = field(default_factory=list, repr=False)
    _absent: tuple[str, ...] | None = field(default=None, repr=False)

    def __repr__(self) -> str:
        return (f"RunLog({str(self.path)!r}, {self.config.label}, "
                f"{self.n_slots}/{self.config.horizon} slots, {self.status})")  # fmt: skip

    @property
    def label(self) -> str:
        return self.config.label

    @property
    def absent(self) -> tuple[str, ...]:
        """The fields a run of its sources may lack (corraoi.engine.slot_record.OPTIONAL,
        ``record_for``) that this log lacks, as its first chunk shows (a log written before a
        field existed lacks it)."""
        if self._absent is None:
            first = next(iter(self._chunk_blocks()), None)
            if isinstance(first, SourcesBlock):
                first = first.sources[0]
            have = first.fields() if first is not None else ()
            mine = {f.name for f in record_for(self.config.sources)}
            self._absent = tuple(f for f in OPTIONAL if f not in have and f in mine)
        return self._absent

    @property
    def horizon(self) -> int:
        return self.config.horizon

    @property
    def summary(self) -> str:
        """One line on how complete the log is."""
        n = self.n_slots
        # a log of a stream given no horizon (corraoi.Logger) has no "of T" to say
        bounded = self.config.horizon < MAX_HORIZON
        of = f" of {self.config.horizon}" if bounded else ""
        if self.status == "complete":
            return f"complete: {n}{of} slots" + ("" if bounded else " (no horizon given)")
        if self.status == "failed":
            return (f"failed: the run stopped on an error after slot {n}{of}: "
                    f"{self.end.get('error', '(no message)')}")  # fmt: skip
        if self.status == "damaged":
            return f"damaged: {self.damage}; read {n}{of} slots before the damage"
        if self.status == "interrupted":
            return (f"cut short: the run was stopped after slot {n}{of} "
                    "(the file was finished properly)")  # fmt: skip
        if self.writer is not None:
            who = f"process {self.writer}" if self.writer else "another process"
            return (
                f"being written right now by {who}: {n}{of} slots so far, up "
                "to the last complete chunk"
            )
        return (
            f"cut short: the writer did not finish the file (killed?); recovered "
            f"{n}{of} slots, up to the last complete chunk"
        )

    @property
    def sources(self) -> int:
        """The number of sources of the run (1: its blocks are SlotBlocks, else
        SourcesBlocks)."""
        return self.config.sources

    def blocks(self, block: int = 1000) -> Iterator[Any]:
        """The recorded slots in blocks of ``block`` slots (the last one may be shorter):
        SlotBlocks, or for a run of several sources SourcesBlocks."""
        if block < 1:
            raise ValueError(f"block must be >= 1, got {block}")
        pending: list[Any] = []
        have = 0
        for part in self._chunk_blocks():
            pending.append(part)
            have += len(part)
            while have >= block:
                whole = pending[0] if len(pending) == 1 else type(part).concat(pending)
                yield whole.slice(0, block)
                rest = whole.slice(block, len(whole))
                pending = [rest] if len(rest) else []
                have = len(rest)
        if have:
            yield pending[0] if len(pending) == 1 else type(pending[0]).concat(pending)

    def read_all(self) -> Any:
        """Every recorded slot in one block (memory grows with the log: prefer blocks()):
        a SlotBlock, or for a run of several sources a SourcesBlock."""
        parts = list(self.blocks(block=max(self.n_slots, 1)))
        if not parts:
            empty = empty_block(self.config.K)
            if self.sources > 1:
                return SourcesBlock(tuple(empty for _ in range(self.sources)))
            return empty
        return parts[0] if len(parts) == 1 else type(parts[0]).concat(parts)

    def _decoded(self, chunk: ChunkData) -> Any:
        """The slots of one chunk: a SlotBlock, or a SourcesBlock of a run of several
        sources (each source's from its channel)."""
        K, n = self.config.K, self.config.n_states
        if self.sources == 1:
            return self._noted(_decode(chunk, self._channel_id, self.path, K, n))
        parts = tuple(self._noted(_decode(chunk, c, self.path, K, n))
                      for c in self._source_channels)  # fmt: skip
        if len({len(p) for p in parts}) != 1 or not all(
            np.array_equal(p.t, parts[0].t) and np.array_equal(p.x, parts[0].x) for p in parts
        ):
            raise LogError(f"{self.path}: chunk at byte {chunk.offset}: the sources' slots "
                           "differ (expected every source at every slot, with one x)")  # fmt: skip
        return SourcesBlock(parts)

    def window(self, first: int, last: int) -> Iterator[Any]:
        """The slots ``first..last`` (inclusive, 1-based t), one block per chunk read.

        Chunks whose time range lies outside the window are skipped without being
        decompressed or decoded: their ranges come from the summary's chunk index when the
        file has one, else from each chunk's header (a file cut short).
        """
        first, last = max(int(first), 1), min(int(last), self.n_slots)
        if first > last:
            return
        lo, hi = first * NS_PER_SLOT, last * NS_PER_SLOT
        expected = first
        with open_mcap(self.path) as f:
            walker = Walker(f, self.path, stop_at=self._data_end)
            for offset in chunk_offsets(f, walker, lo, hi):
                chunk = walker.chunk_at(offset)
                part = self._decoded(chunk)
                keep = (part.t >= first) & (part.t <= last)
                if not keep.any():
                    continue
                idx = np.flatnonzero(keep)
                part = part.slice(int(idx[0]), int(idx[-1]) + 1)
                expected = _follows(part, expected, self.path, offset)
                yield part
        if expected != last + 1:
            raise LogError(f"{self.path}: slots {expected}..{last} are missing from the log")

    def _noted(self, part: SlotBlock) -> SlotBlock:
        """``part``, after one warning per log naming the fields a newer corraoi wrote that
        this one does not know (they are kept: ``SlotBlock.extra``, ``Run.slots``). Only a
        log of format version 3 (``corraoi.Logger``'s) may lack a column every block carries
        (``SlotBlock.absent``): in an older one that is damage."""
        if part.absent and self.format_version != LACKING_FORMAT_VERSION and len(part):
            raise LogError(
                f"{self.path}: slot {int(part.t[0])} lacks {', '.join(part.absent)}, a required "
                f"field of a log of format version {self.format_version} (only a log of "
                f"version {LACKING_FORMAT_VERSION}, corraoi.Logger's, may lack it)"
            )
        new = [f for f in part.extra if f not in self._unknown]
        if new:
            self._unknown.extend(new)
            warnings.warn(
                f"{self.path}: slot field{'s' if len(new) > 1 else ''} {', '.join(new)} "
                f"unknown to corraoi {__version__} (written by corraoi "
                f"{self.config.version}?): kept as read, not shown or compared",
                CorraoiWarning,
                stacklevel=3,
            )
        return part

    def _chunk_blocks(self) -> Iterator[Any]:
        expected = 1
        with open_mcap(self.path) as f:
            walker = Walker(f, self.path, stop_at=self._data_end)
            for kind, item in walker.records(read_chunks=True):
                if kind != "chunk":
                    continue
                assert isinstance(item, ChunkData)
                part = self._decoded(item)
                if not len(part):
                    continue
                _follows(part, expected, self.path, item.offset)
                if expected + len(part) - 1 > self.n_slots:
                    part = part.slice(0, self.n_slots - expected + 1)
                expected += len(part)
                if len(part):
                    yield part
                if expected > self.n_slots:
                    return


def open_log(path: str | os.PathLike[str], *, verify: bool = True, salvage: bool = False) -> RunLog:
    """Open a corraoi MCAP log, checking what it is and how complete it is.

    With ``verify`` (the default) every chunk is decompressed and its CRC checked now, so
    a damaged file is refused here rather than half-way through a replay. Raises
    :class:`~corraoi.errors.LogError` with a one-line message when the file cannot be used:
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
    with open_mcap(p) as f:
        size = os.fstat(f.fileno()).st_size
        if size == 0:
            raise LogError(f"{p}: empty file (0 bytes), not an MCAP log")
        walker = Walker(f, p)
        damage = ""
        expected = 1
        library = ""
        run_md: dict[str, str] | None = None
        end_md: dict[str, str] = {}
        prov_md: dict[str, str] = {}
        attachments: list[tuple[str, str, bytes]] = []
        channel_id = 0
        source_channels: tuple[int, ...] = ()
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
                    check_run_metadata(p, run_md, library)
                elif item.name == RUN_END_METADATA:
                    end_md = dict(item.metadata)
                elif item.name == PROVENANCE_METADATA:
                    prov_md = dict(item.metadata)
                elif item.name == SWEEP_METADATA:
                    sweep = True
            elif kind == "attachment":
                assert isinstance(item, Attachment)
                attachments.append((item.name, item.media_type, bytes(item.data)))
            elif kind == "chunk":
                assert isinstance(item, ChunkData)
                if run_md is None:
                    raise not_a_run_log(p, library, sweep)
                try:
                    if item.records is not None:
                        if not channel_id:
                            source_channels = _source_channels(item, p, run_md)
                            channel_id = source_channels[0] if source_channels else 0
                        t_ns = last_log_time(item.records, channel_id, p, item.offset)
                        last = (t_ns or 0) // NS_PER_SLOT
                        if salvage:
                            expected = _validate_chunk(item, run_md, source_channels, p,
                                                       expected)  # fmt: skip
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
                raise not_a_run_log(p, library, sweep)
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
            raise not_a_run_log(p, library, sweep)
        if n_slots and not channel_id and verify:
            raise LogError(f"{p}: no {SLOT_TOPIC} channel with schema {SLOT_SCHEMA_NAME}")
        if n_slots and verify and not all(source_channels):
            m = source_channels.index(0) + 1
            raise LogError(f"{p}: no {slot_topic(m, len(source_channels))} channel with schema "
                           f"{SLOT_SCHEMA_NAME} (the channel of source {m})")  # fmt: skip
    config = _config(p, run_md)
    check_agrees(p, run_md, config)
    if n_slots > config.horizon:
        raise LogError(f"{p}: {n_slots} slots recorded for a horizon of {config.horizon}")
    if damage:
        finished = False
        status = "damaged"
    elif not finished:
        status = "truncated"
    elif end_md.get("status") == "failed":
        status = "failed"
    elif n_slots < config.horizon and end_md.get("status") != "complete":
        status = "interrupted"  # (a Logger's log without a horizon is complete when closed)
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
        provenance=prov_md,
        attachments=attachments,
        _channel_id=channel_id or 1,
        _source_channels=source_channels
        if all(source_channels) and len(source_channels) > 1
        else tuple(range(1, config.sources + 1)),
        _data_end=data_end,
    )


# ---------------------------------------------------------------------------- internals


def _strip_path(exc: LogError, p: Path) -> str:
    text = str(exc)
    prefix = f"{p}: "
    return text[len(prefix) :] if text.startswith(prefix) else text


def _config(p: Path, run_md: dict[str, str]) -> RunConfig:
    """The run configuration a log's metadata holds (LogError, one line, when unusable)."""
    try:
        return RunConfig.from_dict(json.loads(run_md["config"]))
    except (CorraoiError, KeyError, TypeError, ValueError, AttributeError, RecursionError) as exc:
        raise LogError(f"{p}: the run configuration in the log is unusable: "
                       f"{' '.join(str(exc).split())[:200] or type(exc).__name__}") from None


def _source_channels(chunk: ChunkData, p: Path, run_md: dict[str, str]) -> tuple[int, ...]:
    """The channel of each source (one for a single source) as the first chunk declares
    them; 0 for a source whose channel it lacks."""
    assert chunk.records is not None
    try:
        M = _config(p, run_md).sources
    except LogError:
        M = 1  # (an unusable config is refused after the walk, with this message)
    return tuple(
        find_channel(chunk.records, p, chunk.offset, topic=slot_topic(m, M),
                     encoding=MESSAGE_ENCODING, schema=SLOT_SCHEMA_NAME)
        for m in range(1, M + 1)
    )  # fmt: skip


def _validate_chunk(
    chunk: ChunkData,
    run_md: dict[str, str] | None,
    channels: tuple[int, ...],
    p: Path,
    expected: int,
) -> int:
    """Decode and check one chunk's slots (salvage); returns the next slot expected."""
    assert chunk.records is not None and run_md is not None
    config = _config(p, run_md)
    next_slot = expected
    for c in channels:
        part = _decode(chunk, c, p, config.K, config.n_states)
        next_slot = _follows(part, expected, p, chunk.offset) if len(part) else expected
    return next_slot


def _decode(chunk: ChunkData, channel_id: int, p: Path, K: int, n: int | None) -> SlotBlock:
    """The slots of one chunk, decoded and validated (an empty block when it holds none)."""
    assert chunk.records is not None
    found = channel_payloads(chunk.records, channel_id, p, chunk.offset)
    return decode_messages(found, K, n, where=f"{p}: chunk at byte {chunk.offset}")


def _follows(part: SlotBlock | SourcesBlock, expected: int, p: Path, offset: int) -> int:
    """The slots of ``part`` must be ``expected``, ``expected + 1``, ...; the next one."""
    t = part.t
    if t[0] != expected or not np.array_equal(
        t, np.arange(expected, expected + len(t), dtype=np.int64)
    ):
        raise LogError(f"{p}: chunk at byte {offset}: slots are not consecutive (expected "
                       f"slot {expected}, got {int(t[0])}..{int(t[-1])})")  # fmt: skip
    return expected + len(t)
