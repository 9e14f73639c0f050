"""Recorded runs side by side and slot by slot, from Python: :func:`compare` and :func:`diff`
over :class:`~corraoi.face.runs.Run` objects or log paths (the viewer's functions, which
``corraoi compare`` and ``corraoi diff`` call too). Nothing is simulated."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from corraoi import arguments
from corraoi.errors import UsageError
from corraoi.recorder.slotlog.reader import RunLog

from .runs import Run, diff_arguments, log_of

if TYPE_CHECKING:
    from corraoi.viewer.compare import Comparison
    from corraoi.viewer.diff_report import DiffReport
    from corraoi.viewer.recover import Recovered
    from corraoi.viewer.replay import Replayed

    from .live import FoxgloveChoice, ViewerChoice

#: A progress bar for ``total`` steps named ``label``: a context manager with ``.update(n)``
#: (:class:`corraoi.progress.Progress` is one).
ProgressBar = Callable[[int, str], Any]



def compare(
    runs: Sequence[Run | str | os.PathLike[str]],
    *,
    rrd: str | os.PathLike[str] | None = None,
    viewer: str | None = None,
    force: bool = False,
) -> Comparison:
    """Put recorded runs side by side, as ``corraoi compare`` does: one Rerun recording with a
    column per run and every run's regret overlaid, into ``rrd`` (a file) and/or ``viewer``
    (a running viewer's URL); with neither, only the summary figures are gathered; ``force``
    replaces an existing ``rrd``. ``runs``: :class:`corraoi.Run` objects or slot logs' paths.
    Returns a :class:`corraoi.viewer.compare.Comparison` (``.table()``, ``.to_dict()``, ``.path``);
    raises :class:`~corraoi.errors.LogError` for a log that cannot be read,
    :class:`~corraoi.errors.OutputError` for an ``rrd`` that must not be written."""
    from corraoi.viewer.compare import compare as compare_logs

    if isinstance(runs, (str, os.PathLike)) or not isinstance(runs, Sequence):
        raise arguments.wrong_type(UsageError, "runs", runs, "a list of corraoi.Run or slot "
                                   "logs' paths")  # fmt: skip
    if not runs:
        raise arguments.wrong_value(UsageError, "runs", runs, "at least one run", "empty")
    arguments.optional(arguments.path, rrd, name="rrd", what="the Rerun recording's path")
    arguments.optional(arguments.text, viewer, name="viewer",
                       expected="a running Rerun viewer's URL (rerun+http://HOST:PORT/proxy)")
    arguments.flag(force, name="force")
    for i, r in enumerate(runs):
        if not isinstance(r, (Run, RunLog)):
            arguments.path(r, name=f"runs[{i}]", kind=UsageError,
                           what="a corraoi.Run or a slot log's path")  # fmt: skip
    logs = [log_of(r, f"runs[{i}]") for i, r in enumerate(runs)]
    return compare_logs(logs, rrd_path=rrd, viewer_url=viewer, overwrite=force)


def diff(
    a: Run | str | os.PathLike[str],
    b: Run | str | os.PathLike[str],
    fields: Sequence[str] | None = None,
    *,
    atol: float = 0.0,
) -> DiffReport:
    """Where two recorded runs ``a`` and ``b`` diverge, slot by slot, as ``corraoi diff``
    does; returns a :class:`corraoi.viewer.DiffReport` (``.identical``,
    ``report["arm"].first_slot``, ``.message()``).
    ``fields`` restricts the comparison (default every logged field); ``atol`` is the
    tolerance of the float fields. Raises :class:`~corraoi.errors.LogError` for a log that
    cannot be read."""
    from corraoi.viewer.diffs import diff as diff_logs

    chosen, atol = diff_arguments(fields, atol)  # before any log is opened
    return diff_logs(log_of(a, "a"), log_of(b, "b"), fields=chosen, atol=atol)


def diff_files(a: str | os.PathLike[str], b: str | os.PathLike[str], *,
               fields: Sequence[str] | None = None, atol: float = 0.0) -> DiffReport:  # fmt: skip
    """``corraoi diff``: :func:`diff` of two logs' paths as the command line gives them,
    ``fields`` in its words (names or comma lists, ``--fields x,arm``). Raises
    :class:`~corraoi.errors.UsageError` for an unknown field, :class:`~corraoi.errors.LogError`
    for a log that cannot be read."""
    from corraoi.viewer.diffs import diff as diff_logs

    return diff_logs(a, b, fields=fields or None, atol=atol)


class Info:
    """What :func:`info` finds: ``.to_dict()`` (``corraoi info --json``) and ``.text()``
    (the table ``corraoi info`` prints)."""

    def __init__(self, data: dict[str, Any], *, sweep: bool) -> None:
        self.data, self.sweep = data, sweep

    def to_dict(self) -> dict[str, Any]:
        return self.data

    def text(self) -> str:
        from corraoi.viewer.info import info_text, sweep_info_text

        return sweep_info_text(self.data) if self.sweep else info_text(self.data)


def info(path: str | os.PathLike[str]) -> Info:
    """What the slot log or sweep folder at ``path`` holds, as ``corraoi info`` shows it: a log's
    configuration, slots, how it ended and its summary figures (a log cut short too); a sweep
    folder's (or one group's folder's) grid, status and runs worth watching. Returns an
    :class:`Info`; raises :class:`~corraoi.errors.LogError` for what is not a readable log
    or sweep folder."""
    p = Path(arguments.path(path, name="path", kind=UsageError,
                            what="the path of a slot log or a sweep folder"))  # fmt: skip
    if p.is_dir() and any((d / "manifest.json").is_file() for d in (p, p.parent)):
        from corraoi.viewer.info import sweep_info

        return Info(sweep_info(p), sweep=True)
    from corraoi.viewer.info import log_info

    return Info(log_info(p), sweep=False)


def recover(
    log: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    *,
    force: bool = False,
) -> Recovered:
    """Rewrite the log ``log`` whose writer died into a finished, indexed log at ``out``
    (default ``RUN.recovered.mcap`` beside it), as ``corraoi recover`` does; ``log`` itself is
    not modified. Returns a :class:`corraoi.viewer.recover.Recovered` (``.slots``, ``.status``,
    ``.damage``, ``.to_dict()``); raises :class:`~corraoi.errors.LogError` for a log that
    cannot be read, :class:`~corraoi.errors.OutputError` for an ``out`` that exists (unless
    ``force``) or is ``log`` itself."""
    from corraoi.viewer.recover import default_output
    from corraoi.viewer.recover import recover as recover_log

    arguments.path(log, name="log", kind=UsageError, what="a slot log's path")
    arguments.optional(arguments.path, out, name="out", what="the recovered log's path")
    arguments.flag(force, name="force")
    return recover_log(log, out if out is not None else default_output(log), overwrite=force)


def _writable_rrd(rrd: Path | None, inputs: Sequence[Path], force: bool) -> None:
    """An ``.rrd`` about to be written: not one of the logs read, and writable (one line if
    not, before anything is written)."""
    if rrd is not None:
        from corraoi.files.partial import check_target

        not_an_input(rrd, inputs)
        check_target(rrd, overwrite=force, what="Rerun recording")


@contextmanager
def _viewer_started(viewer: ViewerChoice | None) -> Iterator[str | None]:
    """The viewer asked for, started: its URL (None without one); stopped if the work fails."""
    url = viewer.start() if viewer is not None and viewer.asked else None
    try:
        yield url
    except BaseException:
        if viewer is not None:
            viewer.stop()
        raise


@contextmanager
def _bar(progress: ProgressBar | None, total: int, label: str) -> Iterator[Any]:
    if progress is None:
        yield None
        return
    with progress(total, label) as bar:
        yield bar


def not_an_input(out: Path, inputs: Sequence[str | os.PathLike[str]]) -> None:
    """Refuse an output path that is one of the logs being read (even with ``force``)."""
    for log in inputs:
        try:
            same = out.exists() and os.path.exists(log) and os.path.samefile(out, log)
        except OSError:
            same = False
        if same:
            raise UsageError(f"{out}: is one of the logs being read; give another output path")


def default_rrd(log: Path) -> Path:
    """``run.mcap`` -> ``run.rrd`` (``run.mcap.partial`` -> ``run.rrd`` as well); another name
    gets ``.rrd`` appended."""
    name = log.name.removesuffix(".partial")
    base = log.with_name(name)
    return base.with_suffix(".rrd") if base.suffix == ".mcap" else log.with_name(name + ".rrd")


def replay_log(
    log: Path,
    rrd: Path | None,
    *,
    viewer: ViewerChoice | None = None,
    force: bool = False,
    progress: ProgressBar | None = None,
    warn: Callable[[str], None] | None = None,
) -> tuple[Replayed, str | None]:
    """``corraoi replay``: the slots of ``log`` re-rendered into the Rerun recording ``rrd``
    (default ``RUN.rrd`` beside the log unless a viewer is chosen) and/or the ``viewer``,
    through the sink ``record`` uses. Every chunk is checked before a viewer is started; a log
    cut short replays up to its last slot, said through ``warn``. Returns what was replayed and
    the viewer's URL (None without one). Raises :class:`~corraoi.errors.LogError` for a log
    that cannot be read, :class:`~corraoi.errors.OutputError` for an ``rrd`` that must not be
    written, :class:`~corraoi.errors.ViewerError` for a viewer that cannot be reached."""
    from corraoi.recorder.slotlog.reader import open_log
    from corraoi.viewer.replay import replay as replay_slots
    from corraoi.viewer.runs import require_slots

    asked = viewer is not None and viewer.asked
    # bad input: one line, nothing written. Every chunk is checked up front before sending to
    # a viewer; a file is discarded if a damaged chunk turns up on the way.
    run = require_slots(open_log(log, verify=asked), "replay")
    if rrd is None and not asked:
        rrd = default_rrd(log)
    _writable_rrd(rrd, [log], force)
    if run.cut_short and warn is not None:
        warn(f"{run.path}: {run.summary}; replaying slots 1..{run.n_slots}")
    with _viewer_started(viewer) as url, _bar(progress, run.n_slots, "replay") as bar:
        done = replay_slots(run, rrd_path=rrd, viewer_url=url, overwrite=force,
                            on_block=None if bar is None else bar.update)  # fmt: skip
    return done, url


def replay_foxglove(log: Path, live: FoxgloveChoice, *, start: int = 1,
                    progress: ProgressBar | None = None) -> tuple[Any, int, str]:  # fmt: skip
    """``corraoi replay --foxglove``: the slots of ``log`` from ``start`` on served over the
    Foxglove server ``live`` chose, which stops afterwards. Returns the log read, the last slot
    sent and the server's URL. Raises :class:`~corraoi.errors.LogError` for a log that cannot
    be read, :class:`~corraoi.errors.UsageError` for a ``start`` past its last slot."""
    from corraoi.recorder.live.foxglove import stream_log
    from corraoi.recorder.slotlog.reader import open_log
    from corraoi.viewer.runs import require_slots

    run = require_slots(open_log(log, verify=True), "replay")
    if not 1 <= start <= run.n_slots:
        raise UsageError(f"--start {start}: {log} holds slots 1..{run.n_slots}, "
                         "expected a slot there")  # fmt: skip
    server = live.start([run.config])
    assert server is not None  # --foxglove was given, and a server that cannot start raises
    try:
        with _bar(progress, run.n_slots - start + 1, "replay") as bar:
            last = stream_log(server, run, start=start,
                              on_block=None if bar is None else bar.update,
                              sink=live.sink(run.config, lambda: False))  # fmt: skip
    finally:
        live.stop()
    return run, last, server.url


def replay(
    run: Run | str | os.PathLike[str],
    rrd: str | os.PathLike[str] | None = None,
    *,
    force: bool = False,
) -> Replayed:
    """Re-render the recorded ``run`` (a :class:`corraoi.Run` or a slot log's path) into the
    Rerun recording ``rrd`` (default ``RUN.rrd`` beside the log), as ``corraoi replay`` does:
    through the sink ``record`` uses, nothing recomputed; a log cut short replays up to its
    last slot. ``force`` replaces an existing ``rrd``. Returns what was replayed (``.path``,
    ``.slots``, ``.horizon``, ``.status``); raises :class:`~corraoi.errors.LogError` for a log
    that cannot be read, :class:`~corraoi.errors.OutputError` for an ``rrd`` that must not be
    written."""
    arguments.path(run, name="run", kind=UsageError, what="a corraoi.Run or a slot log's path")
    arguments.optional(arguments.path, rrd, name="rrd", what="the Rerun recording's path")
    arguments.flag(force, name="force")
    done, _ = replay_log(Path(run), None if rrd is None else Path(rrd), force=force)
    return done


def compare_logs(
    logs: Sequence[Path],
    rrd: Path | None,
    *,
    viewer: ViewerChoice | None = None,
    write: bool = True,
    force: bool = False,
    progress: ProgressBar | None = None,
    warn: Callable[[str], None] | None = None,
) -> tuple[Comparison, str | None]:
    """``corraoi compare``: :func:`compare` of slot logs' paths into ``rrd`` (default
    ``compare.rrd`` when ``write`` and no viewer is chosen) and/or the ``viewer``, with a
    progress bar; what makes the runs hard to compare is said through ``warn``. Returns the
    comparison and the viewer's URL (None without one). Raises
    :class:`~corraoi.errors.LogError` for a log that cannot be read,
    :class:`~corraoi.errors.OutputError` for an ``rrd`` that must not be written."""
    from corraoi.viewer.compare import compare as compare_runs
    from corraoi.viewer.compare import prepare

    asked = viewer is not None and viewer.asked
    runs, warnings = prepare(logs)  # bad input: one line, nothing written
    if rrd is None and not asked and write:
        rrd = Path("compare.rrd")
    _writable_rrd(rrd, logs, force)
    for w in warnings:
        if warn is not None:
            warn(w)
    total = sum(r.log.n_slots for r in runs)
    with _viewer_started(viewer) as url, _bar(progress, total, "compare") as bar:
        result = compare_runs([r.log for r in runs], rrd_path=rrd, viewer_url=url,
                              overwrite=force,
                              on_block=None if bar is None else bar.update)  # fmt: skip
    return result, url


__all__ = [
    "Info", "ProgressBar", "compare", "compare_logs", "default_rrd", "diff", "diff_files", "info",
    "not_an_input", "recover", "replay", "replay_foxglove", "replay_log",
]  # fmt: skip
