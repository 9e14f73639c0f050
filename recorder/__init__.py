"""corraoi's recorder: sinks a simulation streams into, and the reader of its logs.

* :class:`McapSink` writes the MCAP slot log (``docs/log-format.md``);
* :func:`open_log` reads it back into the same SlotBlocks (:class:`RunLog`);
* :class:`RerunSink` sends the slots to a Rerun ``RecordingStream`` (file or viewer), with
  :func:`one_run_blueprint` as the default layout.

The Rerun parts are imported on first use, so reading logs does not import rerun.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from corraoi.errors import LogError, OutputError, ViewerError, WriteError
from recorder.slotlog.reader import RunLog, open_log
from recorder.slotlog.sink import McapSink

from .vocab import SLOT_FORMAT_VERSION as FORMAT_VERSION  # the slot log's, as always
from .vocab import SLOT_TOPIC as TOPIC

if TYPE_CHECKING:
    from recorder.rerun.layout import one_run_blueprint
    from recorder.rerun.names import new_recording
    from recorder.rerun.output import RrdOutput
    from recorder.rerun.sink import RerunSink

#: the Rerun parts, by the module that defines each (imported on first use)
_LAZY = {"RerunSink": "rerun.sink", "RrdOutput": "rerun.output", "new_recording": "rerun.names",
         "one_run_blueprint": "rerun.layout"}  # fmt: skip


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'recorder' has no attribute {name!r}")


__all__ = [
    "FORMAT_VERSION",
    "LogError",
    "McapSink",
    "OutputError",
    "RerunSink",
    "RrdOutput",
    "RunLog",
    "TOPIC",
    "ViewerError",
    "WriteError",
    "new_recording",
    "one_run_blueprint",
    "open_log",
]
