"""``corraoi replay``: re-render one log into Rerun, through the sink ``corraoi record`` uses.

The log is read back into the SlotBlocks that were recorded and handed, block by block,
to the very :class:`corraoi.recorder.rerun.sink.RerunSink` that ``record`` streams into, with the
same label, recording id and default blueprint (:class:`corraoi.recorder.rerun.output.RrdOutput`).
So the replayed ``.rrd`` of a finished log equals the live one under ``rerun rrd
compare``. Nothing is simulated.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .readahead import read_ahead
from .runs import LogLike, as_log, require_slots

#: Slots per block handed to the sink: the engine's block, as ``corraoi record`` uses.
BLOCK = 1000


@dataclass(frozen=True)
class Replayed:
    """What :func:`replay` sent."""

    label: str
    slots: int
    horizon: int
    status: str
    cut_short: bool
    description: str
    path: Path | None


def replay(
    log: LogLike,
    *,
    rrd_path: str | os.PathLike[str] | None = None,
    viewer_url: str | None = None,
    overwrite: bool = False,
    block: int = BLOCK,
    on_block: Callable[[int], None] | None = None,
    verify: bool | None = None,
) -> Replayed:
    """Send every recorded slot of ``log`` to an ``.rrd`` file and/or a viewer (gRPC URL).

    ``on_block(n)`` is called after each block of ``n`` slots (for a progress bar). Raises
    :class:`~corraoi.errors.LogError` for an unreadable log -- then no file is left --,
    :class:`~corraoi.errors.OutputError` for an output that must not be written, and
    :class:`~corraoi.errors.ViewerError` when the viewer cannot be reached.

    ``verify`` (a path given as ``log``): check every chunk before sending anything. By
    default only when sending to a viewer, which cannot take data back; a file is
    discarded instead if a damaged chunk turns up on the way.
    """
    from corraoi.recorder.rerun.layout import one_run_blueprint, sources_blueprint
    from corraoi.recorder.rerun.output import RrdOutput
    from corraoi.recorder.rerun.sink import run_sink

    run = require_slots(
        as_log(log, verify=viewer_url is not None if verify is None else verify), "replay"
    )
    config = run.config
    # the "why this arm" view when the log has scores (a log written before them has none)
    blueprint = (
        sources_blueprint(config.label, config)
        if config.sources > 1
        else one_run_blueprint(config.label, config, why="score" not in run.absent)
    )
    out = RrdOutput(
        config, rrd_path=rrd_path, viewer_url=viewer_url, overwrite=overwrite,
        discard_on_abort=True, blueprint=blueprint,
    )  # fmt: skip
    try:
        sink = run_sink(out.recording, out.label, config)
        for b in read_ahead(run.blocks(block)):
            sink.write(b)
            if on_block is not None:
                on_block(len(b))
        sink.close()
    except BaseException:  # a damaged chunk, Ctrl-C, ...: no half-written .rrd is left
        out.abort()
        raise
    path = out.close()
    return Replayed(
        label=out.label,
        slots=run.n_slots,
        horizon=config.horizon,
        status=run.status,
        cut_short=run.cut_short,
        description=run.summary,
        path=path,
    )
