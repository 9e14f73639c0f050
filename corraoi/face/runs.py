""":class:`Run`: one recorded run, what :func:`corraoi.record` returns and :func:`corraoi.load`
gives for a slot log. The recorder's :class:`~corraoi.recorder.slotlog.frames.RunData` (``.slots``,
``.config``, ``.to_arrow()``) with what a person asks of a run next: its summary, a diff
against another, the viewer, and a table in Jupyter."""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from corraoi import arguments
from corraoi.errors import UsageError
from corraoi.recorder.slotlog.frames import RunData
from corraoi.recorder.slotlog.reader import RunLog

if TYPE_CHECKING:
    from corraoi.engine.summary import RunSummary
    from corraoi.viewer.diff_report import DiffReport

    from .viewing import Shown



class Run(RunData):
    """One recorded run (a slot log, and its Rerun recording when there is one).

    * ``.path`` / ``.mcap``: the slot log; ``.rrd``: the Rerun recording (None without one);
    * ``.config``: the run's settings; ``.slots``: one row per slot (pandas, the ``analysis``
      extra); ``.blocks()``, ``.to_arrow()``;
    * ``.summary``: final pathwise regret, the paper's estimator, pulls per arm, the share of
      slots on the best arm, AoI-aware overrides and the slot from which it stayed on the best
      arm (:class:`corraoi.engine.summary.RunSummary`; arms 0-based, ``.to_dict()`` numbers
      them from 1);
    * ``.diff(other)``: a :class:`corraoi.viewer.DiffReport`.

    ``slots=(first, last)`` restricts the tables to those slots (1-based, inclusive).
    """

    def __init__(
        self,
        path: str | os.PathLike[str] | RunLog,
        *,
        slots: tuple[int, int] | None = None,
        rrd: str | os.PathLike[str] | None = None,
        summary: RunSummary | None = None,
    ) -> None:
        if not isinstance(path, RunLog):  # the arguments checked before the log is opened
            arguments.path(path, name="path", kind=UsageError, what="a slot log's path")
        slots = arguments.optional(arguments.window, slots, name="slots")
        arguments.optional(arguments.path, rrd, name="rrd", kind=UsageError,
                           what="a Rerun recording's path")  # fmt: skip
        super().__init__(path, slots=slots)
        if rrd is not None:
            self.rrd: Path | None = Path(rrd)
        else:
            beside = rrd_beside(self.path)
            self.rrd = beside if beside.is_file() else None
        if summary is not None and slots is None:
            self.__dict__["summary"] = summary  # measured while it was recorded

    def __fspath__(self) -> str:
        """The slot log's path: a Run goes wherever a log's path does."""
        return str(self.path)

    @property
    def mcap(self) -> Path:
        """The slot log (its ``.partial`` name when the run did not finish)."""
        return self.path

    @property
    def label(self) -> str:
        return self.log.config.label

    @property
    def complete(self) -> bool:
        """Every slot of the horizon recorded and the log finished."""
        return self.log.status == "complete"

    @cached_property
    def summary(self) -> RunSummary:
        """The run's figures from its logged slots (the window's, with ``slots=``)."""
        from corraoi.engine.summary import summarize_blocks

        return summarize_blocks(self.log.config, self.blocks())

    def diff(self, other: Run | str | os.PathLike[str], fields: Sequence[str] | None = None,
             *, atol: float = 0.0) -> DiffReport:  # fmt: skip
        """Slot by slot against ``other`` (a Run or a log's path): the first divergence per
        field (``fields``, default all), as :func:`corraoi.diff`."""
        from corraoi.viewer.diffs import diff

        chosen, atol = diff_arguments(fields, atol)
        return diff(self.log, log_of(other, "other"), fields=chosen, atol=atol)

    def recording(self) -> Path:
        """The run's Rerun recording: its ``.rrd``, else one replayed from the log to the
        place beside it (as ``corraoi replay`` does; nothing is simulated). Raises
        :class:`~corraoi.errors.LogError` for a recording that is missing or not one."""
        from .viewing import checked_rrd

        if self.rrd is not None:
            return checked_rrd(self.rrd)
        from corraoi.viewer.replay import replay

        done = replay(self.log, rrd_path=rrd_beside(self.path))
        assert done.path is not None
        self.rrd = done.path
        return done.path

    def show(self, **options: Any) -> Shown:
        """This run in the Rerun viewer, from :meth:`recording`: :func:`corraoi.show` with
        the same ``options`` (in Jupyter a widget, elsewhere a web viewer on 127.0.0.1)."""
        from .viewing import open_viewer

        return open_viewer(lambda: [self.recording()], **options)

    def __repr__(self) -> str:
        where = f", slots {self.window[0]}..{self.window[1]}" if self.window else ""
        return f"Run({str(self.path)!r}, {self.label}{where}, {self.log.status})"

    def _repr_html_(self) -> str:
        cfg = self.log.config
        s = self.summary
        arms = cfg.arm_names
        pulls = ", ".join(f"{a}: {n}" for a, n in zip(arms, s.pulls, strict=True))
        params = ", ".join(f"{k}={v:g}" for k, v in cfg.policy.params.items())
        rows = [
            ("run", cfg.label),
            ("policy", cfg.policy.name + (f" ({params})" if params else "")),
            ("instance", f"{cfg.instance_name} (K = {cfg.K})"),
            ("seed, horizon", f"{cfg.seed}, {cfg.horizon:,}"),
            ("slots", f"{s.slots:,} ({self.log.status})"),
            ("AoI regret (pathwise)", "" if s.regret is None else f"{s.regret:,}"),
            ("paper's estimator", "" if s.estimator is None else f"{s.estimator:,.1f}"),
            ("pulls per arm", pulls),
            ("share on the best arm", "" if s.best_share is None else f"{s.best_share:.3f}"),
            ("slot log", str(self.path)),
            ("Rerun recording", str(self.rrd) if self.rrd else "none"),
        ]
        body = "".join(f"<tr><th style='text-align:left'>{html.escape(k)}</th>"
                       f"<td style='text-align:left'>{html.escape(str(v))}</td></tr>"
                       for k, v in rows)  # fmt: skip
        return f"<table>{body}</table>"


def rrd_beside(log: Path) -> Path:
    """Where a slot log's Rerun recording lies: ``run.mcap`` (or ``run.mcap.partial``) ->
    ``run.rrd``."""
    return log.with_name(log.name.removesuffix(".partial")).with_suffix(".rrd")


def as_run(value: Run | str | os.PathLike[str], what: str = "run") -> Run:
    """A Run from a Run or a slot log's path (UsageError for anything else)."""
    if isinstance(value, Run):
        return value
    if isinstance(value, (str, os.PathLike)):
        return Run(arguments.path(value, name=what, kind=UsageError, what="a slot log's path"))
    raise arguments.wrong_type(UsageError, what, value, "a corraoi.Run or a slot log's path")


def log_of(value: Run | RunLog | str | os.PathLike[str], what: str = "run") -> RunLog:
    """The slot log of a Run, a ``RunLog`` or a log's path (:func:`as_run`'s UsageError for
    anything else)."""
    return value if isinstance(value, RunLog) else as_run(value, what).log


def diff_arguments(fields: object, atol: object) -> tuple[list[str] | None, float]:
    """``fields`` and ``atol`` of :func:`corraoi.diff` and :meth:`Run.diff`, checked: one
    field's name (a ``str`` is one name, or a comma list, never its letters) or a list of
    them, None for all; ``atol`` a finite number >= 0."""
    from corraoi.viewer.diffs import DIFF_FIELDS, parse_fields

    chosen = arguments.optional(arguments.names, fields, name="fields", empty=True,
                                what="fields")  # fmt: skip
    for i, item in enumerate(chosen or ()):
        try:
            parse_fields([item])
        except UsageError:
            where = "fields" if isinstance(fields, str) else f"fields[{i}]"
            raise arguments.wrong_value(UsageError, where, item,
                                        f"fields of {', '.join(DIFF_FIELDS)}") from None
    atol = arguments.number(atol, name="atol", lo=0.0)
    return (None if chosen is None else list(chosen)), atol


__all__ = ["Run", "as_run", "diff_arguments", "log_of", "rrd_beside"]
