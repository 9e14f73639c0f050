"""McapSink: streams slot blocks into an MCAP log, one JSON message per slot (a run of
several sources: one per slot and source, each source on its own channel).

The file is written as ``<path>.partial`` and renamed to ``<path>`` when it is finished,
so a file at ``<path>`` is always complete. Every :data:`~corraoi.recorder.vocab.SLOT_FLUSH_EVERY`
slots the current chunk is closed and handed to the operating system, so a writer killed
with SIGKILL loses at most that many slots (and the chunk before them, if it was still
being written in the background): the reader recovers every complete chunk of the
``.partial`` file and says the log was cut short.

The chunks are framed by :class:`corraoi.recorder.slotlog.chunks.ChunkWriter` (whole chunks built
with numpy; see there why), not by ``mcap.writer.Writer`` one message at a time.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from types import TracebackType
from typing import BinaryIO

import numpy as np
from mcap.records import Channel, Schema

from corraoi.engine.block import RunBlock, RunConfig, SlotBlock, SourcesBlock
from corraoi.engine.threads import cores
from corraoi.errors import ConfigError, CorraoiError, WriteError
from corraoi.files.partial import PartialFile, reason
from corraoi.provenance import Provenance
from corraoi.recorder.sink import Sink
from corraoi.recorder.vocab import (
    MAX_SLOT,
    MESSAGE_ENCODING,
    NS_PER_SLOT,
    PLUGIN_MEDIA_TYPE,
    PROVENANCE_METADATA,
    RUN_METADATA,
    SCHEMA_ENCODING,
    library_name,
    slot_topic,
)
from corraoi.recorder.vocab import RUN_END_METADATA as END_METADATA
from corraoi.recorder.vocab import SLOT_FLUSH_EVERY as FLUSH_EVERY
from corraoi.recorder.vocab import SLOT_SCHEMA_NAME as SCHEMA_NAME

from .chunks import RECORD_ROOM, ChunkWriter
from .encode import BlockEncoder, end_metadata, run_metadata, schema_bytes, sources_end_metadata


def same_run_partial(config: RunConfig) -> Callable[[Path], bool]:
    """Whether a ``.partial`` left by a writer that stopped may be written over by a log of
    ``config``: it is empty, or a corraoi slot log of the same run (its slots are what this
    writer writes again), so that a killed ``record`` never blocks the next attempt."""

    def same(part: Path) -> bool:
        from corraoi.errors import LogError

        from .reader import open_log

        try:
            if part.stat().st_size == 0:
                return True
            return bool(open_log(part, verify=False).config.to_dict() == config.to_dict())
        except (LogError, OSError, ValueError):
            return False

    return same


class McapSink(Sink[RunBlock]):
    """Write one run's slots to ``path`` (an MCAP file), block by block.

    ``with McapSink(path, config) as sink: sink.write(block) ...``. Leaving the ``with``
    normally or by KeyboardInterrupt finishes the file with the slots written so far and
    renames it into place; any other exception leaves the ``.partial`` file as it is (the
    reader recovers its complete chunks). Closing twice is safe.

    ``background``: each finished chunk is compressed and written by a thread while the
    next slots are encoded (:class:`ChunkWriter`), so a writer killed outright may also
    lose the chunk being written, ``flush_every`` slots more. None (the default): when
    this process may use more than one core. A log of slots that cannot be run again
    (``corraoi.Logger``) says False.
    """

    takes_sources = True  # a run of several sources too (Sink.takes_sources)

    def __init__(
        self,
        path: str | os.PathLike[str],
        config: RunConfig,
        *,
        overwrite: bool = False,
        flush_every: int = FLUSH_EVERY,
        fsync: bool = True,
        provenance: Provenance | None = None,
        background: bool | None = None,
    ) -> None:
        if flush_every < 1:
            raise ConfigError(f"flush_every must be >= 1, got {flush_every}")
        if config.horizon > MAX_SLOT:
            raise ConfigError(
                f"horizon {config.horizon} is too long for an MCAP log (at most {MAX_SLOT} "
                "slots, since log_time is t seconds in nanoseconds)"
            )
        # what made the numbers: versions, backend, each plug-in's source as it ran (the
        # plug-in resolved before any file is made: a refusal leaves nothing behind)
        self.provenance = provenance or Provenance.of([config.policy], backend=config.streams)
        self._out = PartialFile(path, overwrite=overwrite, what="MCAP log",
                                replaceable=same_run_partial(config))  # fmt: skip
        self.path: Path = self._out.path
        self.partial_path: Path = self._out.partial
        self.config = config
        self.overwrite = overwrite
        self.flush_every = int(flush_every)
        self.slots = 0
        self.closed = False
        self.finished = False
        self._fsync = fsync
        self._torn = False
        self._last: SlotBlock | SourcesBlock | None = None
        self._encoder = BlockEncoder(config.K)
        self._file: BinaryIO = self._out.create().file
        M = config.sources
        version = {"format_version": run_metadata(config)["format_version"]}
        channels = [
            Channel(id=m, topic=slot_topic(m, M), message_encoding=MESSAGE_ENCODING,
                    schema_id=1, metadata=version if M == 1 else {**version, "source": str(m)})
            for m in range(1, M + 1)
        ]  # fmt: skip
        try:
            self._writer = ChunkWriter(
                self._file,
                schema=Schema(
                    id=1, name=SCHEMA_NAME, encoding=SCHEMA_ENCODING, data=schema_bytes(config)
                ),
                channel=channels[0],
                more_channels=channels[1:],
                library=library_name(config.version),
                background=cores() > 1 if background is None else background,
            )
            self._writer.start()
            self._writer.add_metadata(RUN_METADATA, run_metadata(config, flush_every=flush_every))
            self._writer.add_metadata(PROVENANCE_METADATA, self.provenance.metadata())
            for src in self.provenance.sources:
                self._writer.add_attachment(src.name, PLUGIN_MEDIA_TYPE, src.data)
            self._file.flush()
        except OSError as exc:
            self._torn = True
            self._close_file()
            raise self._write_error(exc) from None

    # ------------------------------------------------------------------ writing

    def write(self, block: RunBlock) -> None:
        """Append the block's slots; they must follow the slots written so far. A run of
        several sources is written from :class:`SourcesBlock` s, one message per slot and
        source, the sources of a slot in order, each on its source's channel."""
        if self.closed or self._torn:
            raise ValueError(f"{self.path}: write() after close() or a failed write")
        n = len(block)
        if n == 0:
            return
        K, M = self.config.K, self.config.sources
        if M > 1 or isinstance(block, SourcesBlock):
            if not isinstance(block, SourcesBlock) or block.M != M:
                got = block.M if isinstance(block, SourcesBlock) else 1
                raise ValueError(f"block has {got} source(s), the run has {M}")
            self._write_sources(block)
            return
        if block.mu_hat.shape != (n, K):
            raise ValueError(f"block has {block.mu_hat.shape[1]} arms, the run has {K}")
        self._check_span(block.t)
        t = block.t.astype(np.uint64)
        times = t * np.uint64(NS_PER_SLOT)  # no overflow: the horizon is at most MAX_SLOT
        sequences = t & np.uint64(0xFFFFFFFF)  # MCAP sequence is 32-bit: t modulo 2**32
        # the messages framed as MCAP records at once, with no bytes object per message
        framed = self._writer.frame(times, sequences,
                                    self._encoder.encode_framed(block, RECORD_ROOM))  # fmt: skip
        # a chunk ends after every slot t with t % flush_every == 0, wherever the blocks
        # end: the file is the same for any block size
        ends = (np.flatnonzero(t % np.uint64(self.flush_every) == 0) + 1).tolist()
        add, flush = self._writer.add_framed, self._writer.flush
        self._torn = True  # until this block is fully handed to the writer
        try:
            begin = 0
            for end in ends:
                add(framed[begin:end])
                flush()
                begin = end
            if begin < n:  # the rest stays in the open chunk
                add(framed[begin:])
        except OSError as exc:
            raise self._write_error(exc) from None
        self._torn = False
        self.slots += n
        self._last = block

    def _check_span(self, t: np.ndarray) -> None:
        """The block's slots ``t`` follow those written, one by one, within the horizon."""
        n, first, last = len(t), int(t[0]), int(t[-1])
        if first != self.slots + 1 or last != self.slots + n:
            raise ValueError(
                f"block covers slots {first}..{last}, expected to start at "
                f"{self.slots + 1} with consecutive slots"
            )
        if self.slots + n > self.config.horizon:
            raise ValueError(f"block goes past the horizon {self.config.horizon}")

    def _write_sources(self, block: SourcesBlock) -> None:
        """The messages of a run of several sources: slot by slot, source 1..M within a
        slot (their log time the slot's), a chunk ending after each slot t with
        t % flush_every == 0, as a single source's."""
        n, M, K = len(block), block.M, self.config.K
        for part in block.sources:
            if part.mu_hat.shape != (n, K) or not np.array_equal(part.t, block.t):
                raise ValueError(f"a source's block has other slots or arms than the run's {K}")
        self._check_span(block.t)
        messages: list[bytes] = [b""] * (n * M)
        for m, part in enumerate(block.sources):
            messages[m::M] = self._encoder.encode(part)
        t = np.repeat(block.t.astype(np.uint64), M)
        times = t * np.uint64(NS_PER_SLOT)
        sequences = t & np.uint64(0xFFFFFFFF)
        channels = np.tile(np.arange(1, M + 1, dtype=np.uint16), n)
        ends = ((np.flatnonzero(block.t % self.flush_every == 0) + 1) * M).tolist()
        add, flush = self._writer.add_messages, self._writer.flush
        self._torn = True
        try:
            begin = 0
            for end in ends:
                add(times[begin:end], sequences[begin:end], messages[begin:end],
                    channels[begin:end])  # fmt: skip
                flush()
                begin = end
            if begin < n * M:
                add(times[begin:], sequences[begin:], messages[begin:], channels[begin:])
        except OSError as exc:
            raise self._write_error(exc) from None
        self._torn = False
        self.slots += n
        self._last = block

    # ------------------------------------------------------------------ closing

    def close(self, *, complete: bool | None = None) -> Path:
        """Finish the file (summary, footer), sync it and rename it into place.

        Returns the final path. Safe to call twice. If finishing fails (disk full, ...),
        the ``.partial`` file is left and :class:`WriteError` says so. ``complete``: the
        status to write when the writer knows better than the horizon (a ``corraoi.Logger``
        log without a horizon is complete when closed, interrupted on Ctrl-C).
        """
        if self.closed:
            return self.path if self.finished else self.partial_path
        if self._torn:  # a write was cut off half-way: keep what is surely whole
            return self.abort() or self.partial_path
        self._write_end(error=None, complete=complete)
        # synced by _write_end; renamed while still open: the lock is held until it is in place
        self._out.publish(sync=False)
        self.finished = True
        return self.path

    def fail(self, error: str) -> Path:
        """The run stopped on ``error``: finish the file with status ``failed`` and that error,
        and leave it at its ``.partial`` name (the final name is never written). A run that
        failed before its first slot leaves no file, as any failed run."""
        if self.closed:
            return self.partial_path
        if self._torn or self.slots == 0:
            return self.abort() or self.partial_path
        self._write_end(error=error)
        self._close_file()
        return self.partial_path

    def _write_end(self, *, error: str | None, complete: bool | None = None) -> None:
        """The last chunk, the ``corraoi.end`` record (status failed with ``error``), the
        summary and the footer, synced (the file stays open: its lock is held)."""
        self.closed = True
        try:
            self._writer.flush()
            last, horizon = self._last, self.config.horizon
            self._writer.add_metadata(
                END_METADATA,
                sources_end_metadata(slots=self.slots, horizon=horizon, last=last,
                                     error=error, complete=complete)
                if isinstance(last, SourcesBlock)
                else end_metadata(slots=self.slots, horizon=horizon, last=last,
                                  error=error, complete=complete),
            )  # fmt: skip
            self._writer.finish()
            self._file.flush()
            if self._fsync:
                os.fsync(self._file.fileno())
        except OSError as exc:
            self._close_file()
            raise self._write_error(exc) from None

    def abort(self) -> Path | None:
        """Stop without finishing: the ``.partial`` file stays (readable up to its last
        chunk), unless no slot was written and no write failed, in which case it is
        deleted (None). After a failed write (disk full) it always stays: the error
        message points to it."""
        if not self.closed:
            self.closed = True
            try:
                if not self._torn:
                    self._writer.flush()
                self._writer.stop()
            except OSError:
                pass
            if self.slots == 0 and not self._torn:
                self._out.discard()
            self._close_file()
        if self.slots == 0 and not self.partial_path.exists():
            return None
        return self.partial_path

    def _close_file(self) -> None:
        """Keep the ``.partial`` file as it is and release its lock (safe twice)."""
        writer = getattr(self, "_writer", None)
        if writer is not None:
            try:  # the chunk being written is written first
                writer.stop()
            except OSError:
                pass  # already cut off: the file is kept as it is
        self._out.leave()

    def _write_error(self, exc: OSError) -> WriteError:
        return WriteError(
            f"{self.partial_path}: cannot write the MCAP log: {reason(exc)} "
            f"(the unfinished log is left as {self.partial_path})"
        )

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        interrupted = exc_type is not None and issubclass(exc_type, (KeyboardInterrupt, SystemExit))
        if exc_type is None or (interrupted and not self._torn):
            self.close()
        elif isinstance(exc, CorraoiError) and not isinstance(exc, WriteError):
            self.fail(str(exc))  # the simulation failed (e.g. a plug-in's bad arm): say so
        else:
            self.abort()

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        return f"McapSink({str(self.path)!r}, {self.config.label}, {self.slots} slots, {state})"
