"""``corraoi record``: simulate runs and stream every slot to an MCAP log and a Rerun recording.

The recorder (and rerun) are imported inside the command, so ``corraoi --help`` stays fast.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

import click

from ..errors import ConfigError, UsageError
from ..text import safe_text
from .common import handle_errors, keep_pandas_out, warn
from .live import FoxgloveChoice, ViewerChoice, foxglove_options, viewer_options
from .options import (
    backend_option,
    channel_option,
    horizon_option,
    instance_option,
    output_option,
    param_options,
    policy_option,
    seed_option,
)

DEFAULT_OUT = "runs/{label}.mcap"
_PLACEHOLDERS = ("{label}", "{policy}", "{instance}", "{seed}", "{run}", "{from}")
#: The default name of a run recorded from a sweep (--from): where it came from.
FROM_OUT = "runs/{from}.mcap"


@dataclass
class _Plan:
    config: Any  # RunConfig
    mcap: Path
    rrd: Path | None


@dataclass
class _Result:
    plan: _Plan
    slots: int = 0
    wall: float = 0.0
    regret: int | None = None
    estimator: float | None = None
    pulls: list[int] = field(default_factory=list)
    mcap: Path | None = None
    rrd: Path | None = None
    #: seconds of the wall time spent compiling the kernels (first use only)
    compile_s: float = 0.0


class _Stop:
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

    def __enter__(self) -> _Stop:
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


def _expand(template: str, config: Any, drill: Any = None) -> Path:
    """The path ``template`` names for ``config``. The names filled in are data (from an
    instance file or a plug-in): each goes through ``safe_name``, so none can add a folder,
    climb out of one (``../``) or carry control codes into the file name."""
    from ..text import safe_name

    values = {
        "{label}": config.label,
        "{policy}": config.policy.name,
        "{instance}": config.instance.name,
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


def _plans(
    configs: list[Any], out: str | None, rrd: str | None, no_rrd: bool, drills: Any = None
) -> list[_Plan]:
    several = len(configs) > 1
    for option, value in (("-o/--output", out), ("--rrd", rrd)):
        if value is not None and several and not any(p in value for p in _PLACEHOLDERS):
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
        mcap = _expand(out or (FROM_OUT if drill else DEFAULT_OUT), config, drill)
        path = None if no_rrd else (_expand(rrd, config, drill) if rrd else _rrd_beside(mcap))
        plans.append(_Plan(config, mcap, path))
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


@click.command("record")
@instance_option
@policy_option(default=("cucb",))
@horizon_option(10_000)
@seed_option
@param_options
@channel_option
@output_option(
    metavar="PATH",
    path=False,
    help="MCAP log to write [default: runs/{label}.mcap; with --from, runs/{from}.mcap]. "
    "{label}, {policy}, {instance}, {seed}, {run} and {from} (the sweep folder, instance, "
    "label and run) are filled in (needed with several runs), each made a safe file name.",
)
@click.option("--from", "from_", metavar="SWEEP", default=None,
              help="Record runs of the sweep folder SWEEP (a `sweep -o` or `reproduce -o` "
                   "folder): instance, policy, parameters, channel, horizon and seed come "
                   "from it; --run says which.")  # fmt: skip
@click.option("--run", "run", metavar="N|worst|best|median|widest-gap", default=None,
              help="With --from: run index N (seed = the sweep's seed + N) or a named run of "
                   "each cell (final regret largest, smallest, median); widest-gap records "
                   "both policies of the widest paired gap [default: worst].")  # fmt: skip
@click.option("--cell", "cell", metavar="LABEL", multiple=True,
              help="With --from: only these cells (a label such as cucb or cucb(c=2), an "
                   "instance name, or INSTANCE/LABEL); repeat for several.")  # fmt: skip
@click.option(
    "--rrd",
    metavar="PATH",
    default=None,
    help="Rerun recording to write [default: the MCAP path with .rrd].",
)
@click.option("--no-rrd", is_flag=True, help="Write no Rerun recording (the MCAP log only).")
@click.option("--force", "-f", is_flag=True, help="Overwrite existing files.")
@viewer_options
@foxglove_options
@backend_option("Per-slot logs are a CPU feature: cpu (and auto) record on the CPU; gpu is "
                "refused (the GPU backend is for sweeps, docs/gpu.md) [default: cpu].")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
@handle_errors
def record(
    instance: str,
    policy: tuple[str, ...],
    horizon: int,
    seed: int,
    c: float | None,
    beta: float | None,
    param: tuple[str, ...],
    channel: str | None,
    output: str | None,
    rrd: str | None,
    no_rrd: bool,
    force: bool,
    spawn: bool,
    connect: str | None,
    serve_web: bool,
    web_port: int,
    foxglove: str | None,
    pace: float | None,
    backend: str | None,
    as_json: bool,
    from_: str | None,
    run: str | None,
    cell: tuple[str, ...],
) -> None:
    """Simulate runs and stream every slot to an MCAP log and a Rerun recording.

    Each slot is logged with the hidden state, the channel played, success, AoI, the
    oracle's AoI, the pathwise regret, the paper's estimator, mu_hat and pulls per arm, the
    candidate set and the AoI-aware override flag. Several policies run on the same seed,
    so their hidden paths are the same (paired runs); each gets its own pair of files.
    Ctrl-C (or SIGTERM) stops at the next block and leaves both files finished with the
    slots simulated so far (exit status 130).

    \b
    Examples:
      corraoi record --policy cucb
      corraoi record -p ucb,cucb -T 100000 --seed 3
      corraoi record -p cts --connect          # into a viewer started with `rerun`
      corraoi record -p cucb --foxglove --pace 200   # live in Foxglove
      corraoi record --from sweeps/I2 --run worst -p cts   # a sweep's worst run
    """  # noqa: D301
    from ..block import RunConfig
    from ..channels import parse_channel

    if backend == "gpu":
        raise ConfigError(
            "--backend gpu: record writes every slot of a run, a CPU feature; the GPU backend "
            "runs sweeps (corraoi sweep --backend gpu), or record with --backend cpu"
        )
    if backend == "auto":
        warn("--backend auto: record runs on the CPU (per-slot logs are a CPU feature)")
    from ..instance import load_instance
    from ..policies import make_policies, parse_param_assignments

    viewer = ViewerChoice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port)
    live = FoxgloveChoice(foxglove, pace=pace)
    if no_rrd and rrd is not None:
        raise UsageError("--rrd and --no-rrd: choose one")
    drills = None
    if from_ is not None:
        which = run if run is not None else "worst"
        drills = _from_sweep(from_, which, cell, policy, param, c=c, beta=beta)
        configs = [d.config for d in drills]
    else:
        if run is not None or cell:
            raise UsageError(f"{'--run' if run is not None else '--cell'}: only with --from SWEEP")
        inst = load_instance(instance)
        specs = make_policies(policy, parse_param_assignments(param), c=c, beta=beta)
        chan = parse_channel(channel, inst)
        chan.check(inst, horizon)
        configs = [RunConfig(inst, spec, seed, horizon, channel=chan) for spec in specs]
    plans = _plans(configs, output, rrd, no_rrd, drills)
    if drills:
        _say_where_from(drills)  # once the plan stands: a refusal above stays one line
    live.several = len(configs) > 1  # one topic per run: /corraoi/slot/<label>

    from recorder.errors import OutputError
    from recorder.paths import check_output

    fresh = [p for p in plans if _up_to_date(p)] if not (force or viewer.asked or foxglove) else []
    plans = [p for p in plans if p not in fresh]  # recording them again would change nothing
    for p in fresh:
        click.echo(
            f"up to date: {safe_text(p.mcap)}"
            + (f" and {safe_text(p.rrd)}" if p.rrd is not None else "")
            + (" hold" if p.rrd is not None else " holds")
            + " this run (same configuration, complete); use --force to record it again",
            err=as_json,
        )
    if not plans:
        if as_json:
            click.echo(json.dumps({"runs": [], "up_to_date": [str(p.mcap) for p in fresh]}))
        return
    for plan in plans:  # refuse before simulating anything
        if not force and plan.mcap.is_file():
            raise OutputError(
                f"{plan.mcap}: already exists and holds another run (a different "
                "configuration, or not complete); use --force to overwrite it"
            )
        check_output(plan.mcap, overwrite=force, what="MCAP log")
        if plan.rrd is not None:
            check_output(plan.rrd, overwrite=force, what="Rerun recording")

    worker = None
    if any(p.rrd for p in plans):
        os.environ.setdefault("RUST_LOG", "off")  # Rerun's own log lines: we report problems
        if not viewer.asked:
            # the .rrd files are written by a process that imports Rerun now, while this
            # one imports numba and loads the kernel (recorder/rerun_worker.py says why)
            from recorder.rerun_worker import RerunWorker

            worker = RerunWorker.start(before_import=keep_pandas_out)
    # A viewer that cannot be reached is one error line; the files are still written.
    viewer_url = viewer.start(tolerant=True)
    # a port in use: one error line; the files are still written
    live.start([p.config for p in plans], tolerant=True)
    viewer_failed = viewer.problem is not None or live.problem is not None
    try:
        results, stopped, viewer_problem = _record_all(plans, viewer_url, force, live=live,
                                                       rerun=worker)  # fmt: skip
    except BaseException:
        viewer.stop()
        raise
    finally:
        live.stop()
        if worker is not None:
            worker.stop()
    if viewer_problem:
        click.echo(f"corraoi: error: {safe_text(viewer_problem)}", err=True)
        viewer_failed = True
    _report(results, as_json=as_json)
    if stopped:
        last = results[-1]
        click.echo(
            f"corraoi: interrupted ({stopped}) after slot {last.slots} of "
            f"{last.plan.config.horizon}; the files hold every slot simulated so far",
            err=True,
        )
        viewer.stop()
        sys.exit(130)
    viewer.serve_until_stopped()
    if viewer_failed:
        sys.exit(1)


def _from_sweep(
    folder: str,
    run: str,
    cells: tuple[str, ...],
    policy: tuple[str, ...],
    param: tuple[str, ...],
    *,
    c: float | None,
    beta: float | None,
) -> list[Any]:
    """The runs ``--from`` names (corraoi.drill); what the sweep fixed cannot be given too."""
    from click.core import ParameterSource

    from ..drill import choose
    from ..policies import make_policies, parse_param_assignments

    ctx = click.get_current_context()
    fixed = [("instance", "--instance"), ("horizon", "--horizon"), ("seed", "--seed"),
             ("channel", "--channel")]  # fmt: skip
    for name, option in fixed:
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None):
            raise UsageError(f"{option} and --from: the sweep fixes the {name} of its runs; "
                             "leave out " + option)  # fmt: skip
    given = ctx.get_parameter_source("policy") not in (ParameterSource.DEFAULT, None)
    if not given and (param or c is not None or beta is not None):
        raise UsageError("--c/--beta/--param and --from: the sweep fixes its policies' "
                         "parameters (with --policy they set those of a policy added)")
    specs = (make_policies(policy, parse_param_assignments(param), c=c, beta=beta)
             if given else [])  # fmt: skip
    return choose(folder, run, cells=cells, policies=specs, warn=warn)


def _say_where_from(drills: list[Any]) -> None:
    for d in drills:
        what = "" if d.cell is not None else ", added"
        label = d.cell if d.cell is not None else d.config.policy.label
        click.echo(f"from {safe_text(d.folder)}: {safe_text(d.config.instance.name)} "
                   f"{safe_text(label)}, run {d.run} (seed {d.config.seed}, {d.choice}{what})",
                   err=True)  # fmt: skip


def _up_to_date(plan: _Plan) -> bool:
    """The plan's files exist, and its MCAP log is complete with the same configuration
    (the version of corraoi included): recording again would write the same bytes."""
    from recorder.errors import LogError
    from recorder.reader import open_log

    if not plan.mcap.is_file() or (plan.rrd is not None and not plan.rrd.is_file()):
        return False
    try:
        log = open_log(plan.mcap, verify=False)
    except LogError:
        return False
    return log.status == "complete" and log.config.to_dict() == plan.config.to_dict()


def _record_all(
    plans: list[_Plan], viewer_url: str | None, force: bool, *, live: Any = None,
    rerun: Any = None,
) -> tuple[list[_Result], str | None, str | None]:
    """Run every plan in turn; returns (results, signal that stopped us, viewer problem)."""
    from ..engine import set_workers
    from ..progress import Progress

    # One run has nothing to spread over threads, and idle numba workers compete with
    # Rerun's encoder threads for the cores: 2-3x slower on a 2-core machine.
    set_workers(1)
    if rerun is None and (viewer_url is not None or any(p.rrd is not None for p in plans)):
        keep_pandas_out()  # Rerun's logging goes through pyarrow
    _prepare_kernels(plans)
    results: list[_Result] = []
    viewer_problem: str | None = None
    total = sum(p.config.horizon for p in plans)
    with _Stop() as stop, Progress(total, "record") as bar:
        for plan in plans:
            result = _Result(plan)
            results.append(result)
            problem = _record_one(plan, result, viewer_url, force, stop, bar, live=live,
                                  rerun=rerun)  # fmt: skip
            viewer_problem = viewer_problem or problem
            if stop.signal:
                return results, stop.signal, viewer_problem
    return results, None, viewer_problem


def _prepare_kernels(plans: list[_Plan]) -> None:
    """Several policy families to record for the first time: compile their record kernels
    at once, one worker process per core, before the first run starts."""
    from .. import kernels
    from ..policies.api import CompiledPolicy

    classes = {}
    for plan in plans:
        if plan.config.streams != "cpu":  # a GPU sweep's run: the GPU kernel decides it
            continue
        cls = plan.config.policy.resolve()
        if isinstance(cls, type) and issubclass(cls, CompiledPolicy):
            classes[cls.name] = cls
    kernels.prepare(classes.values(), record=True)


def _record_one(
    plan: _Plan,
    result: _Result,
    viewer_url: str | None,
    force: bool,
    stop: _Stop,
    bar: Any,
    *,
    live: Any = None,
    rerun: Any = None,
) -> str | None:
    """Record one run into its files; returns a problem with the viewer, if any."""
    from .. import kernels
    from ..pyengine import PolicyRuntimeError

    start = time.perf_counter()
    compiled_before = kernels.compile_seconds  # compiling is not the run: left out of slots/s
    try:
        return _record_into(plan, result, viewer_url, force, stop, bar, start, compiled_before,
                            live=live, rerun=rerun)  # fmt: skip
    except PolicyRuntimeError as exc:
        from recorder.paths import partial_path

        where = partial_path(plan.mcap)
        left = (f"; the log is left as {where}, marked failed" if where.exists()
                else f"; no log written ({plan.mcap} would have held no slot)")
        raise PolicyRuntimeError(f"{exc}{left}") from None


def _record_into(
    plan: _Plan,
    result: _Result,
    viewer_url: str | None,
    force: bool,
    stop: _Stop,
    bar: Any,
    start: float,
    compiled_before: float,
    *,
    live: Any = None,
    rerun: Any = None,
) -> str | None:
    from .. import kernels
    from ..experiments import record_run

    config = plan.config

    fox = live.sink(config, lambda: stop.signal is not None) if live is not None else None

    def on_block(block: Any) -> None:
        if fox is not None:
            fox.write(block)  # with --pace, this is what slows the run
        result.slots = int(block.t[-1])
        result.regret = int(block.regret[-1])
        result.estimator = float(block.estimator[-1])
        result.pulls = [int(v) for v in block.pulls[-1]]
        bar.update(len(block), note=f"{config.label} slot {result.slots}")

    try:
        outcome = record_run(
            config, plan.mcap, rrd=plan.rrd, viewer_url=viewer_url, overwrite=force,
            on_block=on_block, should_stop=lambda: stop.signal is not None, rerun=rerun,
        )  # fmt: skip
    finally:
        result.wall = time.perf_counter() - start
        result.compile_s = kernels.compile_seconds - compiled_before
    result.mcap, result.rrd = outcome.mcap, outcome.rrd
    return outcome.viewer_problem


def _report(results: list[_Result], *, as_json: bool) -> None:
    from recorder.live import view_command

    rrds = [str(r.rrd) for r in results if r.rrd is not None]
    command = view_command(rrds) if rrds else None
    if as_json:
        out = {
            "runs": [
                {
                    "label": r.plan.config.label,
                    "policy": r.plan.config.policy.name,
                    "params": r.plan.config.policy.params,
                    "instance": r.plan.config.instance.name,
                    "seed": r.plan.config.seed,
                    "horizon": r.plan.config.horizon,
                    "slots": r.slots,
                    "complete": r.slots == r.plan.config.horizon,
                    "regret": r.regret,
                    "estimator": r.estimator,
                    "pulls": r.pulls,
                    "mcap": str(r.mcap) if r.mcap else None,
                    "rrd": str(r.rrd) if r.rrd else None,
                    "wall_s": round(r.wall, 4),
                    "compile_s": round(r.compile_s, 4),
                }
                for r in results
            ],
            "view": command,
        }
        click.echo(json.dumps(out, indent=2))
        return
    for r in results:
        c = r.plan.config
        params = ", ".join(f"{k}={v:g}" for k, v in c.policy.params.items())
        run_s = r.wall - r.compile_s
        rate = r.slots / run_s if run_s > 0 else 0.0
        compiled = f", after {r.compile_s:.1f} s compiling" if r.compile_s else ""
        done = "" if r.slots == c.horizon else " (interrupted)"
        click.echo(
            f"{safe_text(c.policy.name)}{f' ({params})' if params else ''} on "
            f"{safe_text(c.instance.name)}, seed "
            f"{c.seed}: {r.slots} of {c.horizon} slots{done} in {r.wall:.2f} s "
            f"({rate:,.0f} slots/s{compiled})"
        )
        if r.regret is not None and r.estimator is not None:
            click.echo(
                f"  AoI regret at slot {r.slots}: {r.regret} (pathwise), "
                f"{r.estimator:.1f} (paper's estimator sum aoi - t/mu*)"
            )
            pulls = "  ".join(f"{k + 1}: {n}" for k, n in enumerate(r.pulls))
            click.echo(f"  pulls per arm: {pulls}")
        click.echo(f"  MCAP log:        {safe_text(r.mcap)}")
        if r.rrd is not None:
            click.echo(f"  Rerun recording: {safe_text(r.rrd)}")
    if command:
        click.echo(f"open in the Rerun viewer:  {safe_text(command)}")


__all__ = ["record"]
