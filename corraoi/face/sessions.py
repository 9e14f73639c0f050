"""``corraoi record``'s session, in the face: the runs it records (given, or chosen from a
sweep with ``--from``), the files each goes to and the refusals before anything runs, then
every run in turn with a progress callback, the first SIGINT/SIGTERM/SIGHUP finishing the
files at the next block, into its files, a live viewer and a Foxglove server.

The command line parses, calls these, and prints what they return."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager, ExitStack
from dataclasses import dataclass, field
from types import FrameType
from typing import TYPE_CHECKING, Any

from corraoi.errors import OutputError

if TYPE_CHECKING:
    from corraoi.engine.block import RunBlock, RunConfig
    from corraoi.experiments.drill import Drill

    from .live import FoxgloveChoice, ViewerChoice
    from .recording import Plan, Recorded
    from .views import ProgressBar


def run_configs(instance: str | os.PathLike[str], policies: Sequence[str], params: Sequence[str],
                *, c: float | None, beta: float | None, channel: str | None, seed: int,
                horizon: int, score: bool | None,
                warn: Callable[[str], None] | None = None,
                sources: int = 1) -> list[RunConfig]:  # fmt: skip
    """The runs ``corraoi record`` is given: the instance, the policies (words, with the
    command line's ``--param NAME=VALUE`` words, ``c`` and ``beta``) on one seed, horizon,
    channel and number of sources (``--sources``, 1..K), as ``RunConfig`` values. Raises
    :class:`~corraoi.errors.InstanceError`, :class:`~corraoi.errors.PolicyError` or
    :class:`~corraoi.errors.ConfigError`."""
    from corraoi import arguments
    from corraoi.engine.block import RunConfig
    from corraoi.errors import ConfigError
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policies, parse_param_assignments

    from .resolve import channel as resolve_channel

    inst = load_instance(instance)
    arguments.integer(sources, name="--sources", lo=1, hi=inst.K, kind=ConfigError,
                      why=f"at most the {inst.K} arms of instance {inst.name}")  # fmt: skip
    specs = make_policies(policies, parse_param_assignments(params), c=c, beta=beta, warn=warn)
    chan = resolve_channel(channel, inst)
    chan.check(inst, horizon)
    return [RunConfig(inst, spec, seed, horizon, channel=chan, score=score, sources=sources)
            for spec in specs]  # fmt: skip


def runs_from_sweep(
    folder: str,
    run: str,
    cells: Sequence[str],
    policies: Sequence[str] | None,
    params: Sequence[str],
    *,
    c: float | None,
    beta: float | None,
    kept_code: bool = False,
    allow_changed_code: bool = False,
    hold: Callable[[AbstractContextManager[Any]], Any],
    warn: Callable[[str], None] | None = None,
) -> list[Drill]:
    """The runs ``--from folder`` names (``run`` of each cell, ``cells`` only), as drills
    (``.config``, ``.folder``, ``.cell``, ``.run``, ``.choice``). ``policies``: the words of
    ``--policy`` when it was given (the sweep's labels select its cells, any other word adds a
    policy on the same runs); ``hold`` keeps the kept copies of the sweep's plug-ins in use
    while the command runs. Raises :class:`~corraoi.errors.UsageError` for parameters given
    without a policy, and the sweep's own refusals."""
    from corraoi.errors import UsageError
    from corraoi.experiments.drill import choose, kept_code_scope, split_policy_words
    from corraoi.policies import make_policies, parse_param_assignments

    from .resolve import TRACE_READERS

    if policies is None and (params or c is not None or beta is not None):
        raise UsageError(
            "--c/--beta/--param and --from: the sweep fixes its policies' "
            "parameters (with --policy they set those of a policy added)"
        )
    # the labels the sweep's table prints select its cells; any other word is a policy
    labels, words = split_policy_words(folder, policies) if policies is not None else ([], [])
    specs = (make_policies(words, parse_param_assignments(params), c=c, beta=beta, warn=warn)
             if words else [])  # fmt: skip
    # the kept copies are handed over while this command runs (its runs are recorded later)
    hold(kept_code_scope(folder, kept_code))
    return choose(folder, run, cells=cells, policies=specs, swept_labels=labels, warn=warn,
                  kept_code=kept_code, allow_changed_code=allow_changed_code,
                  trace_readers=TRACE_READERS)  # fmt: skip


def plan_runs(
    configs: Sequence[RunConfig],
    output: str | None,
    rrd: str | None,
    no_rrd: bool,
    drills: Sequence[Drill] | None,
    *,
    force: bool,
    live_option: str | None,
    again: bool,
    on_planned: Callable[[list[Plan]], None] | None = None,
    on_fresh: Callable[[Plan], None] | None = None,
) -> tuple[list[Plan], list[Plan]]:
    """The files of each run (``output`` and ``rrd`` templates, ``no_rrd``) and what is to be
    recorded: a run whose files hold it already, complete, is left out (``on_fresh``) unless
    ``again`` (``force``, or a live view); a live view (``live_option``) of such a run is
    refused without ``force``, and so is a file of another run. ``on_planned`` hears the plans
    once they stand. Returns the plans to record and those left out; raises
    :class:`~corraoi.errors.OutputError` before anything runs."""
    from .recording import plan_files, refuse, up_to_date

    plans = plan_files(list(configs), output, rrd, no_rrd, drills)
    if on_planned is not None:
        on_planned(plans)  # once the plan stands: a refusal above stays one line
    if live_option is not None and not force:  # a live view records again: say so, truly
        done = next((p for p in plans if up_to_date(p)), None)
        if done is not None:
            from corraoi.text import safe_text

            log = safe_text(done.mcap)
            raise OutputError(f"{log}: already holds this run (same configuration, complete); "
                              f"{live_option} shows a run as it is recorded, which would write "
                              f"it again: use --force to record it again, or `corraoi replay "
                              f"{log} {live_option}` to show this log")  # fmt: skip
    fresh = [p for p in plans if up_to_date(p)] if not again else []
    plans = [p for p in plans if p not in fresh]  # recording them again would change nothing
    for p in fresh:
        if on_fresh is not None:
            on_fresh(p)
    if plans:
        refuse(plans, force=force)  # before simulating anything
    return plans, fresh


class Stop:
    """SIGINT/SIGTERM/SIGHUP while recording: the first asks the loop to stop at the next block
    (the files are then finished with every slot simulated so far); a second one raises
    KeyboardInterrupt at once."""

    def __init__(self) -> None:
        self.signal: str | None = None
        self._old: dict[int, Any] = {}

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signal is not None:
            raise KeyboardInterrupt
        self.signal = signal.Signals(signum).name

    def __enter__(self) -> Stop:
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread: keep the defaults
                pass
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()


@dataclass
class Session:
    """What :func:`record_runs` recorded: each run's result (``.plan``, ``.slots``,
    ``.regret``, ``.mcap``, ``.rrd``, ...), the signal that stopped it (None when every run
    finished), a live viewer's problem, and whether a viewer or Foxglove server failed."""

    results: list[Recorded] = field(default_factory=list)
    stopped: str | None = None
    viewer_problem: str | None = None
    viewer_failed: bool = False
    #: the runs planned to be recorded, and those left out as up to date (:func:`record`)
    plans: list[Plan] = field(default_factory=list)
    fresh: list[Plan] = field(default_factory=list)

    def verdicts(self) -> list[str]:
        """Per run recorded from a sweep with changed code: whether it still gives the sweep's
        row (one line each)."""
        out: list[str] = []
        if not any(r.plan.drill for r in self.results):
            return out  # no run from a sweep: its module is not imported
        from corraoi.experiments.drill import row_verdict

        for r in self.results:
            verdict = row_verdict(r.plan.drill, r.slots, r.regret) if r.plan.drill else None
            if verdict is not None:
                out.append(verdict)
        return out

    def view_command(self) -> str | None:
        """The shell command that opens the Rerun recordings written (None without one)."""
        from .live import open_command

        rrds = [str(r.rrd) for r in self.results if r.rrd is not None]
        return open_command(rrds) if rrds else None


def record_runs(
    plans: Sequence[Plan],
    *,
    viewer: ViewerChoice | None = None,
    live: FoxgloveChoice | None = None,
    force: bool = False,
    progress: ProgressBar | None = None,
    before_rerun: Callable[[], None] | None = None,
) -> Session:
    """Record every plan in turn (:func:`corraoi.face.recording.record_plans`) into its
    files, the ``viewer`` and the Foxglove server ``live`` (one that cannot be reached is one
    error line through its ``say``; the files are still written), with ``progress(total,
    label)`` as the bar; the first SIGINT/SIGTERM/SIGHUP finishes the files at the next block.
    ``before_rerun()`` runs in the process that imports Rerun, before it does. Returns a
    :class:`Session`."""
    from .recording import Outlets, record_plans

    worker = None
    asked = viewer is not None and viewer.asked
    if any(p.rrd for p in plans):
        os.environ.setdefault("RUST_LOG", "off")  # Rerun's own log lines: we report problems
        if not asked:
            # the .rrd files are written by a process that imports Rerun now, while this
            # one imports numba and loads the kernel (recorder/rerun/worker.py says why)
            from corraoi.recorder.rerun.worker import RerunWorker

            worker = RerunWorker.start(before_import=before_rerun)
    # A viewer that cannot be reached is one error line; the files are still written.
    viewer_url = viewer.start(tolerant=True) if viewer is not None else None
    # a port in use: one error line; the files are still written
    if live is not None:
        live.start([p.config for p in plans], tolerant=True)
    failed = (viewer is not None and viewer.problem is not None) or (
        live is not None and live.problem is not None
    )
    outlets = Outlets(viewer_url=viewer_url, overwrite=force, live=live, rerun=worker)
    try:
        if (
            worker is None
            and before_rerun is not None
            and (viewer_url is not None or any(p.rrd is not None for p in plans))
        ):
            before_rerun()  # Rerun's logging goes through pyarrow, in this process
        total = sum(p.config.horizon for p in plans)
        with Stop() as stop, _bar(progress, total) as bar:

            def on_block(plan: Plan, block: RunBlock) -> None:
                if bar is not None:
                    bar.update(len(block), note=f"{plan.config.label} slot {int(block.t[-1])}")

            results = record_plans(plans, outlets, on_block=on_block,
                                   should_stop=lambda: stop.signal is not None)  # fmt: skip
    except BaseException:
        if viewer is not None:
            viewer.stop()
        raise
    finally:
        if live is not None:
            live.stop()
        if worker is not None:
            worker.stop()
    problem = next((r.viewer_problem for r in results if r.viewer_problem), None)
    return Session(results, stop.signal, problem, failed)


def record_from_options(
    instance: str | os.PathLike[str],
    policies: Sequence[str] | None,
    params: Sequence[str],
    *,
    c: float | None,
    beta: float | None,
    channel: str | None,
    seed: int,
    horizon: int,
    score: bool | None,
    output: str | None,
    rrd: str | None,
    no_rrd: bool,
    force: bool,
    again: bool,
    sources: int = 1,
    sweep: str | None = None,
    run: str = "worst",
    cells: Sequence[str] = (),
    kept_code: bool = False,
    allow_changed_code: bool = False,
    hold: Callable[[AbstractContextManager[Any]], Any] | None = None,
    viewer: ViewerChoice | None = None,
    live: FoxgloveChoice | None = None,
    live_option: str | None = None,
    warn: Callable[[str], None] | None = None,
    on_planned: Callable[[list[Plan]], None] | None = None,
    on_fresh: Callable[[Plan], None] | None = None,
    progress: ProgressBar | None = None,
    before_rerun: Callable[[], None] | None = None,
) -> Session:
    """``corraoi record`` from its parsed options: the runs (:func:`run_configs`, or with
    ``sweep`` the folder's runs, :func:`runs_from_sweep`, ``policies`` None when ``--policy``
    was not given), their files (:func:`plan_runs`: ``on_planned``, ``on_fresh``), then every
    run not up to date recorded (:func:`record_runs`: ``progress``, the first signal finishing
    the files). Returns the :class:`Session` (``.plans`` empty: nothing was to be recorded)."""
    with ExitStack() as stack:  # the kept code in use while the runs record (hold: longer)
        if sweep is not None:
            drills = runs_from_sweep(sweep, run, cells, policies, params, c=c, beta=beta,
                                     kept_code=kept_code, allow_changed_code=allow_changed_code,
                                     hold=hold or stack.enter_context, warn=warn)  # fmt: skip
            configs = [d.config for d in drills]
        else:
            drills = None
            configs = run_configs(instance, policies or (), params, c=c, beta=beta,
                                  channel=channel, seed=seed, horizon=horizon, score=score,
                                  warn=warn, sources=sources)  # fmt: skip
        plans, fresh = plan_runs(configs, output, rrd, no_rrd, drills, force=force,
                                 live_option=live_option, again=again, on_planned=on_planned,
                                 on_fresh=on_fresh)  # fmt: skip
        if live is not None:
            live.several = len(configs) > 1  # one topic per run: /corraoi/slot/<label>
        if not plans:
            return Session(fresh=fresh)
        if any(p.rrd for p in plans) or (viewer is not None and viewer.asked):
            from corraoi.extras import require_package

            # said here, not as a traceback of the process that would write the .rrd
            require_package("rerun", "corraoi record's Rerun recording (--no-rrd: none)")
        session = record_runs(plans, viewer=viewer, live=live, force=force, progress=progress,
                              before_rerun=before_rerun)  # fmt: skip
    session.plans, session.fresh = list(plans), fresh
    return session


def _bar(progress: ProgressBar | None, total: int) -> AbstractContextManager[Any]:
    from contextlib import nullcontext

    return nullcontext() if progress is None else progress(total, "record")


__all__ = ["Session", "Stop", "plan_runs", "record_from_options", "record_runs", "run_configs",
           "runs_from_sweep"]  # fmt: skip
