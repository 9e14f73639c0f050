"""Recording runs: a run's slots streamed to its MCAP log, its Rerun recording and any
further sink -- what :func:`corraoi.record` does, and ``corraoi record`` for each of its runs.

* :func:`record_run`: one run (a ``RunConfig``) into its files, one loop over its sinks;
* :class:`Plan`, :func:`plan_files`, :func:`up_to_date`, :func:`refuse`: which files a run
  goes to (path templates filled in), whether they already hold it, and the refusals made
  before anything runs;
* :func:`record_plans`: several plans one after another (their kernels compiled together
  first), each run's figures measured (:class:`Recorded`);
* :func:`record`: the Python face's one call, returning a :class:`~corraoi.face.runs.Run`.

The core gives the slots (``corraoi.face.slots.slots_of``); the sinks are the recorder's.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from corraoi import arguments
from corraoi.errors import (
    ConfigError,
    OutputError,
    PolicyError,
    PolicyRuntimeError,
    SweepMismatch,
    UsageError,
    WriteError,
)
from corraoi.provenance import Provenance
from corraoi.recorder.sink import RunRecording, Sink
from corraoi.recorder.slotlog.sink import McapSink

if TYPE_CHECKING:
    from corraoi.engine.block import RunBlock, RunConfig, SlotBlock
    from corraoi.engine.summary import RunSummary
    from corraoi.experiments.drill import Drill
    from corraoi.model.instance import Instance
    from corraoi.recorder.rerun.worker import RerunWorker

    from .live import FoxgloveChoice
    from .resolve import PolicyLike
    from .runs import Run

#: Where a run's log goes unless told: ``runs/<label>.mcap`` (a run of a sweep: its name).
DEFAULT_OUT = "runs/{label}.mcap"
FROM_OUT = "runs/{from}.mcap"
#: What a path template may hold, each filled with a safe file name.
PLACEHOLDERS = ("{label}", "{policy}", "{instance}", "{seed}", "{run}", "{from}")


@dataclass
class RecordOutcome:
    """What :func:`record_run` wrote: the log (final name, or ``.partial`` when the run
    stopped on an error), the Rerun recording if any, the slots, and a viewer's problem."""

    mcap: Path
    rrd: Path | None
    slots: int
    viewer_problem: str | None = None


def record_run(
    config: RunConfig,
    mcap: str | os.PathLike[str],
    *,
    rrd: str | os.PathLike[str] | None = None,
    viewer_url: str | None = None,
    overwrite: bool = False,
    on_block: Callable[[RunBlock], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    rerun: RerunWorker | None = None,
    sinks: Sequence[Sink[SlotBlock]] = (),
    expect: Sequence[tuple[int, float]] = (),
    notes: Sequence[str] = (),
) -> RecordOutcome:
    """Simulate one run (a ``RunConfig``) and stream every slot to the MCAP log ``mcap`` and,
    with ``rrd`` or ``viewer_url``, to a Rerun recording (what ``corraoi record`` does for
    each policy). ``should_stop()`` is asked after every block: the files are then finished
    with the slots so far (status interrupted). A failed run (a plug-in's bad arm) leaves its
    log at the ``.partial`` name, marked failed, and raises. Ctrl-C finishes both files.
    ``rerun``, a :class:`corraoi.recorder.rerun.worker.RerunWorker`, writes the Rerun recording in
    its process (the same file), else it is written in this one. ``sinks``: further
    :class:`~corraoi.recorder.sink.Sink` s (a Foxglove live server's, your own) that take every
    block after those two, closed with the run, or aborted when it fails (a run of several
    sources refuses those that do not take its blocks: ``Sink.takes_sources``).

    ``expect``: (slot, regret) pairs the run must give (a sweep's row, ``record --from``);
    the first difference stops it with :class:`corraoi.experiments.drill.SweepMismatch`, the log
    finished as failed with that line. ``notes`` go into the log's provenance."""
    from .slots import slots_of

    single = [s for s in sinks if not s.takes_sources]
    if config.sources > 1 and single:
        raise ConfigError(
            f"{config.label}: a run of {config.sources} sources goes to sinks that take its "
            f"blocks of several sources only; {type(single[0]).__name__} takes a single "
            "source's (expected a Sink with takes_sources = True)"
        )
    if expect:  # a drill-down's check (the module is not imported by a plain record)
        from corraoi.experiments.drill import row_mismatch
    slots = 0
    provenance = Provenance.of([config.policy], backend=config.streams, notes=notes)
    recording: RunRecording | None = None
    if rrd is not None or viewer_url is not None:
        where = None if rrd is None else Path(rrd)
        if rerun is not None:
            recording = rerun.open(config, rrd_path=where, viewer_url=viewer_url,
                                   overwrite=overwrite)  # fmt: skip
        else:
            from corraoi.recorder.rerun.sink import LocalRecording

            recording = LocalRecording(config, rrd_path=where, viewer_url=viewer_url,
                                       overwrite=overwrite)  # fmt: skip
    log: McapSink | None = None
    try:
        # every sink closes with the run, or aborts when it fails (each as its class says);
        # the recording is left last, so that the MCAP log is finished whatever it says
        with ExitStack() as stack:
            if recording is not None:
                stack.enter_context(recording)
            log = stack.enter_context(McapSink(mcap, config, overwrite=overwrite,
                                               provenance=provenance))  # fmt: skip
            every: list[Sink[RunBlock]] = [log]
            if recording is not None:
                every.append(recording)
            others = [stack.enter_context(s) for s in sinks]
            for block in slots_of(config):  # the engine's, or a GPU sweep's own run
                for sink in every:
                    sink.write(block)
                for other in others:  # (each takes a run of several sources, if it is one)
                    other.write(block)  # type: ignore[arg-type]
                slots = int(block.t[-1])
                # a run of several sources: its regret summed over them, as the sweep's row
                mismatch = row_mismatch(expect, block) if expect else None
                if mismatch is not None:  # after the block is in the log: it shows it
                    raise SweepMismatch(f"{config.label}: {mismatch}; the log is left as "
                                        f"{log.partial_path}, marked failed")  # fmt: skip
                if on_block is not None:
                    on_block(block)
                if should_stop is not None and should_stop():
                    break
    except WriteError as exc:
        if recording is not None and exc is recording.error and log is not None and log.finished:
            raise WriteError(f"{exc} (the MCAP log {log.path} is complete)") from None
        raise
    assert log is not None
    rrd_path = recording.result if recording is not None else None
    problem = recording.problem if recording is not None else None
    return RecordOutcome(log.path if log.finished else log.partial_path, rrd_path, slots, problem)


def record_drill(drill: Drill, mcap: str | os.PathLike[str], **kwargs: Any) -> RecordOutcome:
    """:func:`record_run` of a run chosen from a sweep (a
    :class:`corraoi.experiments.drill.Drill`): it
    must give the sweep's regret again, and its log carries the drill's notes."""
    return record_run(drill.config, mcap, expect=drill.expect, notes=drill.notes, **kwargs)


# ---------------------------------------------------------------------------- plans


@dataclass
class Plan:
    """One run to record: its configuration (a ``RunConfig``) and its files."""

    config: RunConfig
    mcap: Path
    rrd: Path | None
    #: where it came from (a corraoi.experiments.drill.Drill, --from): what it must give again
    drill: Drill | None = None


def _expand(template: str, config: RunConfig, drill: Drill | None = None) -> Path:
    """The path ``template`` names for ``config``. The names filled in are data (from an
    instance file or a plug-in): each goes through ``safe_name``, so none can add a folder,
    climb out of one (``../``) or carry control codes into the file name."""
    from corraoi.text import safe_name

    values = {
        "{label}": config.label,
        "{policy}": config.policy.name,
        "{instance}": config.instance_name,
        "{seed}": str(config.seed),
        "{run}": str(drill.run) if drill is not None else str(config.seed),
        "{from}": drill.name if drill is not None else config.label,
    }
    out = template
    for key, value in values.items():
        out = out.replace(key, safe_name(value))
    return Path(out)


def _rrd_beside(mcap: Path) -> Path:
    return mcap.with_suffix(".rrd") if mcap.suffix == ".mcap" else Path(f"{mcap}.rrd")


def plan_files(
    configs: Sequence[RunConfig],
    out: str | os.PathLike[str] | None = None,
    rrd: str | os.PathLike[str] | None = None,
    no_rrd: bool = False,
    drills: Sequence[Drill] | None = None,
) -> list[Plan]:
    """The files of each run: ``out`` (default ``runs/{label}.mcap``, a run of a sweep
    ``runs/{from}.mcap``) and ``rrd`` (default: beside the log, none with ``no_rrd``), their
    templates filled in; one line for a path that names one file for several runs, or a
    path used twice."""
    several = len(configs) > 1
    texts = {"-o/--output": None if out is None else os.fspath(out),
             "--rrd": None if rrd is None else os.fspath(rrd)}  # fmt: skip
    for option, value in texts.items():
        if value is not None and several and not any(p in value for p in PLACEHOLDERS):
            raise UsageError(
                f"{option} {value}: names one file but {len(configs)} "
                f"{'runs' if drills else 'policies'} are recorded; put {{label}} or "
                f"{'{from}' if drills else '{policy}'} in it (e.g. -o "
                f"'runs/{'{from}' if drills else '{label}'}.mcap')"
            )
        if value is not None and value.strip() == "":
            raise UsageError(f"{option}: empty path")
    plans = []
    for i, config in enumerate(configs):
        drill = drills[i] if drills else None
        mcap = _expand(texts["-o/--output"] or (FROM_OUT if drill else DEFAULT_OUT), config, drill)
        rrd_text = texts["--rrd"]
        path = None if no_rrd else (_expand(rrd_text, config, drill) if rrd_text
                                    else _rrd_beside(mcap))  # fmt: skip
        plans.append(Plan(config, mcap, path, drill))
    seen: dict[str, str] = {}
    for plan in plans:
        for kind, p in (("MCAP log", plan.mcap), ("Rerun recording", plan.rrd)):
            if p is None:
                continue
            key = os.path.abspath(p)
            if key in seen:
                raise UsageError(f"{p}: used twice (as {seen[key]} and as {kind})")
            seen[key] = kind
    return plans


def up_to_date(plan: Plan) -> bool:
    """The plan's files exist, and its MCAP log is complete and holds the run asked for
    (:func:`stale`): recording again would write the same bytes."""
    return stale(plan) is None


def stale(plan: Plan) -> str | None:
    """Why the plan's files do not hold the run asked for, in words (None when they do).

    Read from what the log already holds, no simulation: its status, its configuration
    (instance, policy and parameters, the sha256 of the policy's code, channel, seed,
    horizon, backend, corraoi's version) and its provenance (the engine sources' hash, each
    plug-in source's sha256), each compared with the run asked for, as the code is now: a
    policy edited and defined again in this session is other code."""
    from corraoi.errors import LogError
    from corraoi.provenance import kernel_sources_hash, short, sources_of
    from corraoi.recorder.slotlog.reader import open_log

    if not plan.mcap.is_file():
        return "no log"
    if plan.rrd is not None and not plan.rrd.is_file():
        return f"no Rerun recording {plan.rrd}"
    try:
        log = open_log(plan.mcap, verify=False)
    except LogError:
        return "not a readable slot log"
    if log.status != "complete":
        return f"a run that is not complete (its status is {log.status})"
    had, want = log.config.to_dict(), plan.config.to_dict()
    if had != want:
        return f"another run ({_first_difference(had, want)})"
    then = log.provenance.get("kernel_sources")
    now = kernel_sources_hash()  # versions()'s, without asking the packages theirs
    if then != now:
        made = (f"engine sources {short(then)}" if then else
                "no hash of its engine sources")  # fmt: skip
        return (f"this run as another corraoi made it ({made}, this corraoi's are "
                f"{short(now)}: its numbers may differ)")  # fmt: skip
    logged = sorted(p["sha256"] for p in Provenance.read(log.provenance)["plugins"])
    ran = sorted(s.sha256 for s in sources_of(plan.config.policy))
    if logged != ran:
        return "another run (the policy's plug-in sources differ from its log's)"
    return None


def _first_difference(had: dict[str, Any], want: dict[str, Any]) -> str:
    """The first setting that differs between a log's configuration and the one asked."""
    from corraoi.provenance import short

    def plugin(d: dict[str, Any]) -> dict[str, Any]:
        return d.get("policy", {}).get("plugin") or {}

    old, new = plugin(had), plugin(want)
    if had.get("policy", {}).get("name") == want.get("policy", {}).get("name") and (
        old.get("sha256", "") != new.get("sha256", "")
    ):
        then = short(old["sha256"]) if old.get("sha256") else "no hash"
        return (f"the policy's code is {short(new.get('sha256', ''))} now, the log's ran "
                f"{then}")  # fmt: skip
    names = {"policy": "policy or its parameters", "version": "corraoi version"}
    for key in ("policy", "instance", "channel", "seed", "horizon", "streams", "version"):
        if had.get(key) != want.get(key):
            if key in ("seed", "horizon", "version"):
                return f"its {key} is {had.get(key)}, here {want.get(key)}"
            return f"its {names.get(key, key)} differs"
    return "a different configuration"


def refuse(plans: Sequence[Plan], *, force: bool, hint: str = "--force") -> None:
    """Refuse, before anything runs, a plan whose files cannot be written: a log that holds
    another run (without ``force``: the line says why), a file another process is writing,
    a folder, a sweep folder's own file. A ``.partial`` a killed attempt at the same run
    left is taken over."""
    from corraoi.files.partial import check_target
    from corraoi.recorder.sink import made_again
    from corraoi.recorder.slotlog.sink import same_run_partial

    for plan in plans:
        if not force and plan.mcap.is_file():
            why = stale(plan) or "this run, complete"
            if why.startswith("no Rerun recording"):
                why = f"this run, but there is {why}"
            raise OutputError(f"{plan.mcap}: already exists and holds {why}; use {hint} to "
                              "overwrite it")  # fmt: skip
        check_target(plan.mcap, overwrite=force, what="MCAP log",
                     replaceable=same_run_partial(plan.config))  # fmt: skip
        if plan.rrd is not None:
            check_target(plan.rrd, overwrite=force, what="Rerun recording",
                         replaceable=made_again)  # fmt: skip


# ---------------------------------------------------------------------------- recording plans


@dataclass(frozen=True)
class Outlets:
    """Where every run of one recording goes besides its files, decided once: a Rerun
    viewer's URL, whether files may be overwritten, a live Foxglove server (``.sink(config,
    stopping)`` gives each run's sink) and a forked Rerun writer
    (:class:`corraoi.recorder.rerun.worker.RerunWorker`)."""

    viewer_url: str | None = None
    overwrite: bool = False
    live: FoxgloveChoice | None = None
    rerun: RerunWorker | None = None
    sinks: tuple[Sink[SlotBlock], ...] = ()


@dataclass
class Recorded:
    """One plan recorded: the slots, the final figures, the files and the wall time (of which
    ``compile_s`` compiled the kernel, on first use only)."""

    plan: Plan
    slots: int = 0
    wall: float = 0.0
    regret: int | None = None
    estimator: float | None = None
    pulls: list[int] = field(default_factory=list)
    mcap: Path | None = None
    rrd: Path | None = None
    compile_s: float = 0.0
    viewer_problem: str | None = None
    #: the run's summary, measured as the blocks went by
    summary: RunSummary | None = None


def prepare_kernels(plans: Sequence[Plan]) -> None:
    """Several policy families to record for the first time: compile their record kernels
    at once, one worker process per core, before the first run starts (a run of several
    sources: the record kernel of many sources)."""
    from corraoi.engine import kernel_pool

    kernel_pool.prepare_for(((p.config.policy.resolve(), p.config.sources > 1) for p in plans
                             if p.config.streams == "cpu"),  # a GPU sweep's run: its kernel
                            record=True)  # fmt: skip


def record_plans(
    plans: Sequence[Plan],
    outlets: Outlets = Outlets(),
    *,
    on_block: Callable[[Plan, RunBlock], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> list[Recorded]:
    """Record every plan in turn (module docstring). ``on_block(plan, block)`` after each
    block; ``should_stop()`` ends the current run at its next block, its files finished with
    the slots so far, and records no further plan."""
    from corraoi.engine.threads import set_workers

    # One run has nothing to spread over threads, and idle numba workers compete with
    # Rerun's encoder threads for the cores: 2-3x slower on a 2-core machine.
    set_workers(1)
    prepare_kernels(plans)
    done: list[Recorded] = []
    for plan in plans:
        result = Recorded(plan)
        done.append(result)
        _record_one(plan, result, outlets, on_block, should_stop)
        if should_stop is not None and should_stop():
            break
    return done


def _record_one(
    plan: Plan,
    result: Recorded,
    outlets: Outlets,
    on_block: Callable[[Plan, RunBlock], None] | None,
    should_stop: Callable[[], bool] | None,
) -> None:
    from corraoi.engine import kernels
    from corraoi.engine.block import SourcesBlock
    from corraoi.engine.summary import SummaryAccumulator
    from corraoi.files.partial import partial_path

    config = plan.config
    summary = SummaryAccumulator(config)
    stopping = should_stop if should_stop is not None else (lambda: False)
    # with --pace, the Foxglove sink's write is what slows the run
    fox = outlets.live.sink(config, stopping) if outlets.live is not None else None

    def each(block: RunBlock) -> None:
        summary.update(block)
        result.slots = int(block.t[-1])
        if isinstance(block, SourcesBlock):  # several sources: the run's regret, the sum
            result.regret = sum(int(s.regret[-1]) for s in block.sources)
            result.pulls = [int(v) for v in sum(s.pulls[-1] for s in block.sources)]
        else:
            result.regret = int(block.regret[-1])
            result.estimator = float(block.estimator[-1])
            result.pulls = [int(v) for v in block.pulls[-1]]
        if on_block is not None:
            on_block(plan, block)

    start = time.perf_counter()
    compiled_before = kernels.compile_seconds  # compiling is not the run: left out of slots/s
    try:
        outcome = record_run(
            config, plan.mcap, rrd=plan.rrd, viewer_url=outlets.viewer_url,
            overwrite=outlets.overwrite, on_block=each, should_stop=should_stop,
            rerun=outlets.rerun, sinks=[*outlets.sinks, *([fox] if fox is not None else [])],
            expect=plan.drill.expect if plan.drill is not None else (),
            notes=plan.drill.notes if plan.drill is not None else (),
        )  # fmt: skip
    except PolicyRuntimeError as exc:
        where = partial_path(plan.mcap)
        left = (f"; the log is left as {where}, marked failed" if where.exists()
                else f"; no log written ({plan.mcap} would have held no slot)")
        raise type(exc)(f"{exc}{left}") from None
    finally:
        result.wall = time.perf_counter() - start
        result.compile_s = kernels.compile_seconds - compiled_before
    result.mcap, result.rrd = outcome.mcap, outcome.rrd
    result.viewer_problem = outcome.viewer_problem
    result.summary = summary.result()


# ---------------------------------------------------------------------------- the face


#: What every sink has (:class:`corraoi.recorder.sink.Sink`): written to, closed, and a
#: context manager.
SINK_METHODS = ("write", "close", "__enter__", "__exit__")


def record(
    policy: PolicyLike,
    instance: str | os.PathLike[str] | Instance = "I1",
    *,
    seed: int = 0,
    horizon: int = 10_000,
    params: Mapping[str, float] | Mapping[str, Mapping[str, float]] | None = None,
    channel: str | None = None,
    path: str | os.PathLike[str] | None = None,
    rrd: str | os.PathLike[str] | bool | None = None,
    force: bool = False,
    viewer: str | None = None,
    sinks: Sequence[Sink[SlotBlock]] = (),
    on_block: Callable[[RunBlock], None] | None = None,
    should_stop: Callable[[], bool] | None = None,
    score: bool | None = None,
    sources: int = 1,
) -> Run:
    """Simulate one run and record every slot, as ``corraoi record`` does with the same
    arguments (the same bytes in the log); returns the recorded :class:`corraoi.Run`.

    ``policy``: a name (``"cucb"``), a ``FILE.py:Class`` or ``module:Class`` word, a
    ``corraoi.Policy`` or ``corraoi.CompiledPolicy`` subclass (defined anywhere: it is
    registered under its ``name``) or an instance of one (its parameters set as attributes).
    ``instance``: a built-in name, an instance file or a :class:`corraoi.Instance`.
    ``seed``: the run's seed (its hidden path depends on the instance and the seed only, so
    runs of different policies with one seed are paired); ``horizon``: its slots.
    ``params``: ``{name: value}``. ``channel``: ``iid``, ``markov`` or ``trace:PATH``.

    ``path``: the slot log (default ``runs/{label}.mcap``; ``{label}``, ``{policy}``,
    ``{instance}`` and ``{seed}`` are filled in); ``rrd``: the Rerun recording (default beside
    the log; ``False`` for none). A complete log of the same run already there is returned as
    it is (nothing runs) unless ``force``; a file that holds another run is refused
    (:class:`~corraoi.errors.OutputError`) unless ``force``.

    ``viewer``: the URL of a running Rerun viewer that also gets every slot; ``sinks``:
    further :class:`~corraoi.recorder.sink.Sink` s (a Foxglove live server's, your own);
    ``on_block(block)`` after every block of slots; ``should_stop()`` ends the run at its
    next block, the files finished with the slots so far (Ctrl-C does the same).
    ``score``: log what the policy maximised at every slot (``score``, ``forced``; by
    default up to 64 arms). ``sources``: the number of sources M sharing the channels
    (1..K; a run of several sources logs each source's slots and its collisions,
    docs/model.md "Many sources").

    Raises :class:`~corraoi.errors.PolicyError`, :class:`~corraoi.errors.InstanceError`,
    :class:`~corraoi.errors.ConfigError` (bad input, before anything runs),
    :class:`~corraoi.errors.OutputError` (a path that must not be written),
    :class:`~corraoi.errors.PolicyRuntimeError` (the policy failed: the log is left at its
    ``.partial`` name, marked failed) and :class:`~corraoi.errors.WriteError`.
    """
    from corraoi.engine.block import RunConfig
    from corraoi.limits import check_horizon, check_seed

    from . import resolve
    from .runs import Run

    if isinstance(policy, (list, tuple)):  # the arguments checked before anything is done
        raise arguments.wrong_type(PolicyError, "policy", policy, f"one policy "
                                   f"({resolve.POLICY_LIKE}); corraoi.sweep takes several")
    seed, horizon = check_seed(seed, floats=True), check_horizon(horizon, floats=True)
    resolve.channel_word(channel)
    arguments.optional(arguments.path, path, name="path")
    arguments.path_or_flag(rrd, name="rrd", what="the Rerun recording's path")
    arguments.flag(force, name="force")
    arguments.optional(arguments.flag, score, name="score")
    arguments.optional(arguments.text, viewer, name="viewer",
                       expected="a running Rerun viewer's URL (rerun+http://HOST:PORT/proxy)")
    arguments.objects(sinks, name="sinks", has=SINK_METHODS, what="a corraoi.recorder.sink.Sink")
    arguments.optional(arguments.callback, on_block, name="on_block")
    arguments.optional(arguments.callback, should_stop, name="should_stop")
    inst = resolve.instance(instance)
    sources = arguments.integer(sources, name="sources", lo=1, hi=inst.K, kind=ConfigError,
                                floats=False,
                                why=f"at most the {inst.K} arms of instance {inst.name}")
    (spec,) = resolve.policies(policy, params)
    chan = resolve.channel(channel, inst)
    chan.check(inst, horizon)
    config = RunConfig(inst, spec, int(seed), int(horizon), channel=chan, score=score,
                       sources=sources)  # fmt: skip
    if rrd is True:
        rrd = None
    (plan,) = plan_files([config], path, None if rrd is False else rrd, no_rrd=rrd is False)
    if not force and viewer is None and not sinks and up_to_date(plan):
        return Run(plan.mcap, rrd=plan.rrd)
    refuse([plan], force=force, hint="force=True")
    if plan.rrd is not None or viewer is not None:
        from corraoi.extras import require_package

        # one line before anything is written, not an import error after the log began
        require_package("rerun", "corraoi.record's Rerun recording (rrd=False: none)")
    outlets = Outlets(viewer_url=viewer, overwrite=force, sinks=tuple(sinks))
    each = None if on_block is None else (lambda _plan, block: on_block(block))
    (done,) = record_plans([plan], outlets, on_block=each, should_stop=should_stop)
    if done.viewer_problem is not None:
        import warnings

        from corraoi.errors import CorraoiWarning

        warnings.warn(done.viewer_problem, CorraoiWarning, stacklevel=2)
    assert done.mcap is not None
    return Run(done.mcap, rrd=done.rrd, summary=done.summary)


__all__ = [
    "DEFAULT_OUT",
    "SINK_METHODS",
    "FROM_OUT",
    "Outlets",
    "Plan",
    "RecordOutcome",
    "Recorded",
    "plan_files",
    "prepare_kernels",
    "record",
    "record_drill",
    "record_plans",
    "record_run",
    "refuse",
    "stale",
    "up_to_date",
]
