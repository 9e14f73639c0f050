"""The vocabulary of corraoi's MCAP files: every name and number of the slot log and the
sweep log, defined once.

Writers, readers, the walker (:mod:`corraoi.recorder.walk`), ``corraoi recover`` and the live
viewers import these; ``corraoi.recorder.slotlog.decode`` and ``corraoi.recorder.sweeplog.log``
re-export them under their older short names (``TOPIC``, ``FORMAT_VERSION``, ...), each for its
own format.
``docs/log-format.md`` is the human description. Nothing here imports corraoi's core.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mcap.writer import IndexType

# ---------------------------------------------------------------------------- MCAP

#: The bytes that open and close every MCAP file.
MAGIC = b"\x89MCAP0\r\n"
#: Metadata record of both formats: the versions, the backend and the plug-in sources that
#: made the file's numbers (corraoi.provenance.Provenance.metadata); each plug-in's source is
#: an attachment named after its file, media type PLUGIN_MEDIA_TYPE.
PROVENANCE_METADATA = "corraoi.provenance"
PLUGIN_MEDIA_TYPE = "text/x-python"
#: Both formats' messages are JSON, described by a JSON Schema.
MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"
#: log_time = publish_time = t * NS_PER_SLOT: one slot shows as one second in MCAP tools.
NS_PER_SLOT = 1_000_000_000
#: The largest slot number whose log_time fits MCAP's unsigned 64-bit nanoseconds.
MAX_SLOT = (2**64 - 1) // NS_PER_SLOT


def library_name(version: str) -> str:
    """The MCAP header's ``library`` field of a file written by corraoi ``version``."""
    return f"corraoi/{version}"


# ---------------------------------------------------------------------------- slot log

#: Name of the slot-log format, stored under ``format`` in the run metadata.
SLOT_FORMAT_NAME = "corraoi.slot-log"
#: The newest version of the slot-log format this code reads and writes: a run is written
#: as version 1 (built-in policy, i.i.d. channel), 2 (a plug-in policy or a Markov/trace
#: channel) or 3 (a loop logged by ``corraoi.Logger``: its messages may lack any field the
#: slot record says may be absent, its run may have no instance) or 4 (a run of several
#: sources: one channel per source, :func:`slot_topic`), ``RunConfig.format_version``.
SLOT_FORMAT_VERSION = 4
#: The first version whose logs may lack a column every block carries (``SlotBlock.absent``).
LACKING_FORMAT_VERSION = 3
SLOT_TOPIC = "/corraoi/slot"
SLOT_SCHEMA_NAME = "corraoi.SlotEvent"


def slot_topic(source: int, sources: int) -> str:
    """The topic of source ``source`` (from 1) of a run of ``sources`` sources: the slot
    topic for a single source, ``/corraoi/slot/<source>`` for each of several."""
    return SLOT_TOPIC if sources == 1 else f"{SLOT_TOPIC}/{source}"


#: Metadata record written when a slot log is opened: the run configuration.
RUN_METADATA = "corraoi.run"
#: Metadata record written when a slot log is finished: how the run ended.
RUN_END_METADATA = "corraoi.end"
#: A slot log's chunk is closed (and flushed to the OS) after every slot t with
#: t % SLOT_FLUSH_EVERY == 0.
SLOT_FLUSH_EVERY = 1000

# ---------------------------------------------------------------------------- sweep log

#: Name of the sweep-log format, stored under ``format`` in the sweep metadata.
SWEEP_FORMAT_NAME = "corraoi.sweep-log"
#: Version the sweep writer writes and the newest it reads. Version 2: a CI half-width
#: that is not defined (one run) is an absent key, where version 1 wrote null (type lists
#: such as ["number", "null"] are rejected by Foxglove's JSON-schema parser).
SWEEP_FORMAT_VERSION = 2
SWEEP_TOPIC = "/corraoi/sweep"
SWEEP_SCHEMA_NAME = "corraoi.SweepPoint"
#: Metadata record written when a sweep log is opened: the sweep configuration. It also
#: marks a sweep log apart from a run log.
SWEEP_METADATA = "corraoi.sweep"
#: Metadata record written when a sweep log is finished: how the sweep ended.
SWEEP_END_METADATA = "corraoi.sweep.end"
#: The open chunk of a sweep log is closed and handed to the OS once SWEEP_FLUSH_EVERY
#: messages wait in it, so a killed writer loses fewer than SWEEP_FLUSH_EVERY points.
SWEEP_FLUSH_EVERY = 32
#: Keys a sweep message may lack: a half-width is absent with a single run; the collisions
#: (mean over runs of a run's collisions up to t, summed over its sources, and its half-width)
#: only a cell of several sources has, and only a log of such a sweep declares them.
SWEEP_OPTIONAL_KEYS = ("regret_ci95", "estimator_ci95", "collisions_mean", "collisions_ci95")
#: The keys only a sweep with a cell of several sources declares in its schema.
SWEEP_SOURCES_KEYS = ("collisions_mean", "collisions_ci95")
#: Sweep message keys in the order the writer writes them.
SWEEP_MESSAGE_KEYS = (
    "policy",
    "t",
    "regret_mean",
    "regret_ci95",
    "estimator_mean",
    "estimator_ci95",
    "pull_share",
    "collisions_mean",
    "collisions_ci95",
)


def mcap_index_types(attachments: bool) -> IndexType:
    """The summary indexes every MCAP file we write carries: chunk, message and metadata
    indexes, and the attachment index in a file that holds ``attachments`` (plug-in
    sources): the mcap writer would otherwise end every file with an empty attachment-index
    group. mcap is imported here, not with the vocabulary (a sweep's results need none)."""
    from mcap.writer import IndexType

    index = IndexType.CHUNK | IndexType.MESSAGE | IndexType.METADATA
    return index | IndexType.ATTACHMENT if attachments else index


__all__ = [
    "MAGIC",
    "MAX_SLOT",
    "PLUGIN_MEDIA_TYPE",
    "PROVENANCE_METADATA",
    "MESSAGE_ENCODING",
    "NS_PER_SLOT",
    "RUN_END_METADATA",
    "RUN_METADATA",
    "SCHEMA_ENCODING",
    "SLOT_FLUSH_EVERY",
    "SLOT_FORMAT_NAME",
    "SLOT_FORMAT_VERSION",
    "LACKING_FORMAT_VERSION",
    "SLOT_SCHEMA_NAME",
    "SLOT_TOPIC",
    "SWEEP_END_METADATA",
    "SWEEP_FLUSH_EVERY",
    "SWEEP_FORMAT_NAME",
    "SWEEP_FORMAT_VERSION",
    "SWEEP_MESSAGE_KEYS",
    "SWEEP_METADATA",
    "SWEEP_OPTIONAL_KEYS",
    "SWEEP_SCHEMA_NAME",
    "SWEEP_SOURCES_KEYS",
    "SWEEP_TOPIC",
    "library_name",
    "mcap_index_types",
    "slot_topic",
]
