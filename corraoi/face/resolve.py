"""Words resolved with every reader the house has: what the top floor hands the layers below
so that they never name the recorder (``readers=`` of a trace channel)."""

from __future__ import annotations

from collections.abc import Mapping

from corraoi.model.channels import Channel, TraceReader, parse_channel
from corraoi.model.instance import Instance
from recorder.slotlog.trace import states_of_log

#: Readers of trace files that are not text, by suffix: a corraoi slot log.
TRACE_READERS: Mapping[str, TraceReader] = {".mcap": states_of_log}


def channel(spec: str | None, instance: Instance) -> Channel:
    """``--channel`` value for ``instance``: ``iid``, ``markov``, ``trace:PATH`` (a text file of
    1-based states or a corraoi slot log), or None for the instance's default."""
    return parse_channel(spec, instance, readers=TRACE_READERS)


__all__ = ["TRACE_READERS", "channel"]
