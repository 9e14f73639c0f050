"""One recorded run: a run's slots streamed to its MCAP log and, if asked, a Rerun recording
(what ``corraoi record`` does for each policy, ``compare --from`` and ``SweepData.record`` too).

The core gives the slots (``corraoi.face.slots.slots_of``); the sinks are the recorder's.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from corraoi.errors import SweepMismatch, ViewerError, WriteError
from corraoi.experiments.drill import row_mismatch
from corraoi.provenance import Provenance
from recorder.sink import Sink
from recorder.slotlog.sink import McapSink

from .slots import slots_of


@dataclass
class RecordOutcome:
    """What :func:`record_run` wrote: the log (final name, or ``.partial`` when the run
    stopped on an error), the Rerun recording if any, the slots, and a viewer's problem."""

    mcap: Path
    rrd: Path | None
    slots: int
    viewer_problem: str | None = None


def record_run(
    config: Any,
    mcap: str | os.PathLike[str],
    *,
    rrd: str | os.PathLike[str] | None = None,
    viewer_url: str | None = None,
    overwrite: bool = False,
    on_block: Callable[[Any], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    rerun: Any = None,
    sinks: Sequence[Sink] = (),
    expect: Sequence[tuple[int, float]] = (),
    notes: Sequence[str] = (),
) -> RecordOutcome:
    """Simulate one run (a ``RunConfig``) and stream every slot to the MCAP log ``mcap`` and,
    with ``rrd`` or ``viewer_url``, to a Rerun recording (what ``corraoi record`` does for
    each policy). ``should_stop()`` is asked after every block: the files are then finished
    with the slots so far (status interrupted). A failed run (a plug-in's bad arm) leaves its
    log at the ``.partial`` name, marked failed, and raises. Ctrl-C finishes both files.
    ``rerun``, a :class:`recorder.rerun.worker.RerunWorker`, writes the Rerun recording in
    its process (the same file), else it is written in this one. ``sinks``: further
    :class:`~recorder.sink.Sink` s (a Foxglove live server's, your own) that take every
    block after those two, closed with the run, or aborted when it fails.

    ``expect``: (slot, regret) pairs the run must give (a sweep's row, ``record --from``);
    the first difference stops it with :class:`corraoi.experiments.drill.SweepMismatch`, the log
    finished as failed with that line. ``notes`` go into the log's provenance."""
    problem: str | None = None
    rrd_error: WriteError | None = None
    slots = 0
    rrd_path: Path | None = None
    provenance = Provenance.of([config.policy], backend=config.streams, notes=notes)
    with McapSink(mcap, config, overwrite=overwrite, provenance=provenance) as log, \
            ExitStack() as more:  # fmt: skip
        extra = [more.enter_context(s) for s in sinks]  # each closed, or aborted, with the run
        output: Any = None
        sink: Any = None  # in this process: the RerunSink in front of ``output``
        if rrd is not None or viewer_url is not None:
            where = None if rrd is None else Path(rrd)
            if rerun is not None:
                output = rerun.open(config, rrd_path=where, viewer_url=viewer_url,
                                    overwrite=overwrite)  # fmt: skip
            else:
                from recorder.rerun.output import RrdOutput
                from recorder.rerun.sink import RerunSink

                output = RrdOutput(config, rrd_path=where, viewer_url=viewer_url,
                                   overwrite=overwrite)  # fmt: skip
                sink = RerunSink(output.recording, config.label, config)
        try:
            for block in slots_of(config):  # the engine's, or a GPU sweep's own run
                log.write(block)
                if sink is not None:
                    sink.write(block)
                elif output is not None:
                    output.write(block)
                for other in extra:
                    other.write(block)
                slots = int(block.t[-1])
                mismatch = row_mismatch(expect, block) if expect else None
                if mismatch is not None:  # after the block is in the log: it shows it
                    raise SweepMismatch(f"{config.label}: {mismatch}; the log is left as "
                                        f"{log.partial_path}, marked failed")  # fmt: skip
                if on_block is not None:
                    on_block(block)
                if should_stop is not None and should_stop():
                    break
        except BaseException as exc:
            if output is not None:
                if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                    try:
                        if sink is not None:
                            sink.close()  # send the slots it still holds (up to a batch)
                        output.close()
                    except (ViewerError, WriteError):
                        pass
                else:
                    try:  # the run's own error is the one to report, not the abort's
                        output.abort(discard=slots == 0)
                    except (ViewerError, WriteError):
                        pass
            raise
        if output is not None:
            if sink is not None:
                sink.close()
            try:
                rrd_path = output.close()
            except ViewerError as exc:
                rrd_path = output.path
                problem = str(exc)
            except WriteError as exc:  # the MCAP log is still finished properly
                rrd_error = exc
    if rrd_error is not None:
        if log.finished:
            raise WriteError(f"{rrd_error} (the MCAP log {log.path} is complete)")
        raise rrd_error
    return RecordOutcome(log.path if log.finished else log.partial_path, rrd_path, slots, problem)


def record_drill(drill: Any, mcap: str | os.PathLike[str], **kwargs: Any) -> RecordOutcome:
    """:func:`record_run` of a run chosen from a sweep (a
    :class:`corraoi.experiments.drill.Drill`): it
    must give the sweep's regret again, and its log carries the drill's notes."""
    return record_run(drill.config, mcap, expect=drill.expect, notes=drill.notes, **kwargs)
