"""``corraoi record``: simulate runs and stream every slot to an MCAP log and a Rerun recording.

What to record and where is :mod:`corraoi.cli.record_plan`'s, running the runs and reporting
them :mod:`corraoi.cli.record_loop`'s; this module is the command: its options, the refusals
before anything runs, the viewers and the exit status.
The recorder (and rerun) are imported inside the command, so ``corraoi --help`` stays fast.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import click

from corraoi.errors import ConfigError, UsageError
from corraoi.text import safe_text

from .common import handle_errors, keep_pandas_out, warn
from .live import foxglove_choice, foxglove_options, viewer_choice, viewer_options
from .options import (
    backend_option,
    channel_option,
    code_options,
    from_only,
    horizon_option,
    instance_option,
    output_option,
    param_options,
    policy_option,
    seed_option,
    sources_option,
)
from .reading import progress
from .record_loop import report
from .record_plan import from_sweep_policies, say_where_from


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
@code_options
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
@click.option("--score/--no-score", default=None,
              help="Log what the policy maximised at every slot (score, forced) [default: "
                   "up to 64 arms].")  # fmt: skip
@sources_option
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
    score: bool | None,
    sources: int,
    as_json: bool,
    from_: str | None,
    run: str | None,
    cell: tuple[str, ...],
    kept_code: bool,
    allow_changed_code: bool,
) -> None:
    """Simulate runs and stream every slot to an MCAP log and a Rerun recording.

    Each slot is logged with the hidden state, the channel played, success, AoI, the
    oracle's AoI, the pathwise regret, the paper's estimator, mu_hat and pulls per arm, the
    candidate set, the AoI-aware override flag and why the channel was played (each arm's
    score, whether the arm was forced, the override's threshold; docs/log-format.md lists
    every field). Several policies run on the same seed,
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
    from corraoi.face.sessions import record_from_options

    if backend == "gpu":
        raise ConfigError(
            "--backend gpu: record writes every slot of a run, a CPU feature; the GPU backend "
            "runs sweeps (corraoi sweep --backend gpu), or record with --backend cpu"
        )
    if backend == "auto":
        warn("--backend auto: record runs on the CPU (per-slot logs are a CPU feature)")
    viewer = viewer_choice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port)
    live = foxglove_choice(foxglove, pace=pace)
    if no_rrd and rrd is not None:
        raise UsageError("--rrd and --no-rrd: choose one")
    policies: tuple[str, ...] | None = policy
    if from_ is not None:
        if sources != 1:
            raise UsageError(f"--sources {sources}: not with --from SWEEP (a sweep's run is "
                             "recorded with the sources it was run with)")  # fmt: skip
        policies = from_sweep_policies(policy)
    elif run is not None or cell or kept_code or allow_changed_code:
        raise UsageError(f"{from_only(run, cell, kept_code, allow_changed_code)}: only with "
                         "--from SWEEP")  # fmt: skip

    def fresh_line(p: Any) -> None:
        click.echo(
            f"up to date: {safe_text(p.mcap)}"
            + (f" and {safe_text(p.rrd)}" if p.rrd is not None else "")
            + (" hold" if p.rrd is not None else " holds")
            + " this run (same configuration, complete); use --force to record it again",
            err=as_json,
        )

    session = record_from_options(
        instance, policies, param, c=c, beta=beta, channel=channel, seed=seed, horizon=horizon,
        score=score, sources=sources, output=output, rrd=rrd, no_rrd=no_rrd, force=force,
        again=bool(force or viewer.asked or foxglove), sweep=from_,
        run=run if run is not None else "worst", cells=cell, kept_code=kept_code,
        allow_changed_code=allow_changed_code, hold=click.get_current_context().with_resource,
        viewer=viewer, live=live, live_option=_live_option(viewer, foxglove), warn=warn,
        on_planned=say_where_from if from_ is not None else None, on_fresh=fresh_line,
        progress=progress, before_rerun=keep_pandas_out,
    )  # fmt: skip
    if not session.plans:
        if as_json:
            click.echo(json.dumps({"runs": [], "up_to_date": [str(p.mcap) for p in session.fresh]}))
        return
    viewer_failed = session.viewer_failed
    viewer_problem = session.viewer_problem
    if viewer_problem:
        click.echo(f"corraoi: error: {safe_text(viewer_problem)}", err=True)
        viewer_failed = True
    report(session, as_json=as_json)
    for verdict in session.verdicts():  # a run recorded with changed code: the sweep's row?
        click.echo(safe_text(verdict), err=as_json)
    if session.stopped:
        last = session.results[-1]
        click.echo(
            f"corraoi: interrupted ({session.stopped}) after slot {last.slots} of "
            f"{last.plan.config.horizon}; the files hold every slot simulated so far",
            err=True,
        )
        viewer.stop()
        sys.exit(130)
    viewer.serve_until_stopped()
    if viewer_failed:
        sys.exit(1)


def _live_option(viewer: Any, foxglove: str | None) -> str | None:
    """The option that shows the runs live as they are recorded, if one was given."""
    if foxglove is not None:
        return "--foxglove"
    if viewer.asked:
        return "--spawn" if viewer.spawn else "--connect" if viewer.connect else "--serve-web"
    return None


__all__ = ["record"]
