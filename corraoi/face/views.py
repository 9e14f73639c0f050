"""Recorded runs side by side and slot by slot, from Python: :func:`compare` and :func:`diff`
over :class:`~corraoi.face.runs.Run` objects or log paths (the viewer's functions, which
``corraoi compare`` and ``corraoi diff`` call too). Nothing is simulated."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from corraoi import arguments
from corraoi.errors import UsageError
from recorder.slotlog.reader import RunLog

from .runs import Run, diff_arguments, log_of

if TYPE_CHECKING:
    from viewer.compare import Comparison
    from viewer.diff_report import DiffReport
    from viewer.recover import Recovered



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
    Returns a :class:`viewer.Comparison` (``.table()``, ``.to_dict()``, ``.path``); raises
    :class:`~corraoi.errors.LogError` for a log that cannot be read,
    :class:`~corraoi.errors.OutputError` for an ``rrd`` that must not be written."""
    from viewer.compare import compare as compare_logs

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
    does; returns a :class:`viewer.DiffReport` (``.identical``, ``report["arm"].first_slot``,
    ``.message()``).
    ``fields`` restricts the comparison (default every logged field); ``atol`` is the
    tolerance of the float fields. Raises :class:`~corraoi.errors.LogError` for a log that
    cannot be read."""
    from viewer.diffs import diff as diff_logs

    chosen, atol = diff_arguments(fields, atol)  # before any log is opened
    return diff_logs(log_of(a, "a"), log_of(b, "b"), fields=chosen, atol=atol)


def diff_files(a: str | os.PathLike[str], b: str | os.PathLike[str], *,
               fields: Sequence[str] | None = None, atol: float = 0.0) -> DiffReport:  # fmt: skip
    """``corraoi diff``: :func:`diff` of two logs' paths as the command line gives them,
    ``fields`` in its words (names or comma lists, ``--fields x,arm``). Raises
    :class:`~corraoi.errors.UsageError` for an unknown field, :class:`~corraoi.errors.LogError`
    for a log that cannot be read."""
    from viewer.diffs import diff as diff_logs

    return diff_logs(a, b, fields=fields or None, atol=atol)


class Info:
    """What :func:`info` finds: ``.to_dict()`` (``corraoi info --json``) and ``.text()``
    (the table ``corraoi info`` prints)."""

    def __init__(self, data: dict[str, Any], *, sweep: bool) -> None:
        self.data, self.sweep = data, sweep

    def to_dict(self) -> dict[str, Any]:
        return self.data

    def text(self) -> str:
        from viewer.info import info_text, sweep_info_text

        return sweep_info_text(self.data) if self.sweep else info_text(self.data)


def info(path: str | os.PathLike[str]) -> Info:
    """What a slot log or a sweep folder holds, as ``corraoi info`` shows it: a log's
    configuration, slots, how it ended and its summary figures (a log cut short too); a sweep
    folder's (or one group's folder's) grid, status and runs worth watching. Returns an
    :class:`Info`; raises :class:`~corraoi.errors.LogError` for what is not a readable log
    or sweep folder."""
    p = Path(arguments.path(path, name="path", kind=UsageError,
                            what="the path of a slot log or a sweep folder"))  # fmt: skip
    if p.is_dir() and any((d / "manifest.json").is_file() for d in (p, p.parent)):
        from viewer.info import sweep_info

        return Info(sweep_info(p), sweep=True)
    from viewer.info import log_info

    return Info(log_info(p), sweep=False)


def recover(
    log: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    *,
    force: bool = False,
) -> Recovered:
    """Rewrite the log ``log`` whose writer died into a finished, indexed log at ``out``
    (default ``RUN.recovered.mcap`` beside it), as ``corraoi recover`` does; ``log`` itself is
    not modified. Returns a :class:`viewer.recover.Recovered` (``.slots``, ``.status``,
    ``.damage``, ``.to_dict()``); raises :class:`~corraoi.errors.LogError` for a log that
    cannot be read, :class:`~corraoi.errors.OutputError` for an ``out`` that exists (unless
    ``force``) or is ``log`` itself."""
    from viewer.recover import default_output
    from viewer.recover import recover as recover_log

    arguments.path(log, name="log", kind=UsageError, what="a slot log's path")
    arguments.optional(arguments.path, out, name="out", what="the recovered log's path")
    arguments.flag(force, name="force")
    return recover_log(log, out if out is not None else default_output(log), overwrite=force)


__all__ = ["Info", "compare", "diff", "diff_files", "info", "recover"]
