"""``corraoi replay | compare | diff | info | recover``: commands that read logs only.

Nothing here simulates: the logs hold every slot. ``viewer``, ``recorder`` and ``rerun``
are imported inside the command functions, so ``corraoi --help`` stays fast.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from ..errors import UsageError
from ..text import safe_text
from .common import errors_exit, handle_errors, keep_pandas_out, say, warn
from .live import FoxgloveChoice, ViewerChoice, foxglove_options, viewer_options
from .options import output_option

F = TypeVar("F", bound=Callable[..., Any])

_LOG = click.Path(dir_okay=True, path_type=Path)  # existence is checked by the reader


def _default_rrd(log: Path) -> Path:
    """``run.mcap`` -> ``run.rrd`` (``run.mcap.partial`` -> ``run.rrd`` as well)."""
    name = log.name.removesuffix(".partial")
    base = log.with_name(name)
    return base.with_suffix(".rrd") if base.suffix == ".mcap" else log.with_name(name + ".rrd")


def _not_an_input(out: Path, inputs: tuple[Path, ...] | list[Path]) -> None:
    """Refuse an output path that is one of the logs being read (even with --force)."""
    for log in inputs:
        try:
            same = out.exists() and log.exists() and os.path.samefile(out, log)
        except OSError:
            same = False
        if same:
            raise UsageError(f"{out}: is one of the logs being read; give another output path")


def _progress(total: int, label: str) -> Any:
    from ..progress import Progress

    return Progress(total, label)


# ---------------------------------------------------------------------------- replay


@click.command("replay")
@click.argument("log", type=_LOG, metavar="RUN.mcap")
@output_option(metavar="OUT.rrd", aliases=("--rrd", "--out"),
               help="Rerun recording to write [default: RUN.rrd beside the log, unless a viewer "
               "option is given].")  # fmt: skip
@viewer_options
@foxglove_options
@click.option("--start", type=click.IntRange(min=1), default=1, metavar="SLOT",
              help="With --foxglove: the first slot to send [default: 1].")  # fmt: skip
@click.option("--force", "-f", is_flag=True, help="Overwrite an existing .rrd.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON object.")
@handle_errors
def replay(
    log: Path,
    output: Path | None,
    spawn: bool,
    connect: str | None,
    serve_web: bool,
    web_port: int,
    foxglove: str | None,
    pace: float | None,
    start: int,
    force: bool,
    as_json: bool,
) -> None:
    """Re-render one recorded run into Rerun, without recomputing anything.

    The log's slots go through the very Rerun sink that `corraoi record` uses, so the
    replayed .rrd of a finished log equals the live one (`rerun rrd compare` exits 0). A
    log that was cut short (a writer killed, or RUN.mcap.partial) replays up to its last
    complete slot, and says which.

    \b
    Examples:
      corraoi replay runs/cucb-I1-s0.mcap -o replay.rrd
      corraoi replay runs/cucb-I1-s0.mcap --serve-web      # then open the printed URL
      corraoi replay runs/cucb-I1-s0.mcap --foxglove --pace 100 --start 5000
    """
    from recorder.reader import open_log
    from viewer.replay import replay as do_replay
    from viewer.runs import require_slots

    keep_pandas_out()

    rrd = output
    viewer = ViewerChoice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port)
    if foxglove is not None or pace is not None or start != 1:
        if foxglove is None:
            raise UsageError("--pace and --start: only with --foxglove")
        if output is not None or viewer.asked:
            raise UsageError("--foxglove: replays to Foxglove only; leave out -o and the "
                             "Rerun viewer options")  # fmt: skip
        _replay_foxglove(log, foxglove, pace=pace, start=start, as_json=as_json)
        return
    # bad input: one line, exit 2, nothing written. Every chunk is checked up front before
    # sending to a viewer; a file is discarded if a damaged chunk turns up on the way.
    run = require_slots(open_log(log, verify=viewer.asked), "replay")
    if rrd is None and not viewer.asked:
        rrd = _default_rrd(log)
    if rrd is not None:
        from recorder.paths import check_output

        _not_an_input(rrd, [log])
        check_output(rrd, overwrite=force, what="Rerun recording")
    if run.cut_short and not as_json:
        warn(f"{run.path}: {run.summary}; replaying slots 1..{run.n_slots}")
    url = viewer.start() if viewer.asked else None
    try:
        with _progress(run.n_slots, "replay") as bar:
            done = do_replay(run, rrd_path=rrd, viewer_url=url, overwrite=force,
                             on_block=bar.update)  # fmt: skip
    except BaseException:
        viewer.stop()
        raise
    if as_json:
        click.echo(json.dumps({
            "log": str(log), "label": done.label, "slots": done.slots,
            "horizon": done.horizon, "status": done.status,
            "rrd": None if done.path is None else str(done.path), "viewer": url,
        }, indent=2))  # fmt: skip
        viewer.serve_until_stopped()
        return
    where = [safe_text(done.path)] if done.path is not None else []
    if url is not None:
        where.append(f"the viewer at {url}")
    click.echo(f"replayed {safe_text(done.label)}: slots 1..{done.slots} of {done.horizon} "
               f"({done.status}) to {' and '.join(where)}")  # fmt: skip
    if done.path is not None and not viewer.asked:
        from recorder.live import view_command

        click.echo(f"open in the Rerun viewer:  {safe_text(view_command([str(done.path)]))}")
    viewer.serve_until_stopped()


def _replay_foxglove(log: Path, address: str, *, pace: float | None, start: int,
                     as_json: bool) -> None:  # fmt: skip
    """``replay --foxglove``: serve the log's slots from ``start`` on, then stop."""
    from recorder.foxglove_live import stream_log
    from recorder.reader import open_log
    from viewer.runs import require_slots

    live = FoxgloveChoice(address, pace=pace)
    run = require_slots(open_log(log, verify=True), "replay")
    if not 1 <= start <= run.n_slots:
        raise UsageError(f"--start {start}: {log} holds slots 1..{run.n_slots}, "
                         "expected a slot there")  # fmt: skip
    server = live.start([run.config])
    try:
        with _progress(run.n_slots - start + 1, "replay") as bar:
            last = stream_log(server, run, start=start, on_block=bar.update,
                              sink=live.sink(run.config, lambda: False))  # fmt: skip
    finally:
        live.stop()
    if as_json:
        click.echo(json.dumps({"log": str(log), "label": run.label, "first": start,
                               "last": last, "foxglove": server.url}, indent=2))  # fmt: skip
        return
    click.echo(f"replayed {safe_text(run.label)}: slots {start}..{last} of "
               f"{run.config.horizon} to Foxglove at {server.url}")  # fmt: skip


# ---------------------------------------------------------------------------- compare


@click.command("compare")
@click.argument("logs", nargs=-1, type=_LOG, metavar="A.mcap B.mcap ...")
@click.option("--from", "from_", metavar="SWEEP", default=None,
              help="Instead of logs: record the chosen run of every policy of the sweep folder "
                   "SWEEP into runs/ (as `record --from`) and compare those.")  # fmt: skip
@click.option("--run", "run", metavar="N|worst|best|median|widest-gap", default=None,
              help="With --from: which run of each policy (as for record) [default: worst].")
@click.option("--cell", "cell", metavar="LABEL", multiple=True,
              help="With --from: only these cells (as for record); repeat for several.")
@output_option(metavar="OUT.rrd", aliases=("--out", "--rrd"),
               help="Rerun recording to write [default: compare.rrd, unless a viewer option "
               "is given].")  # fmt: skip
@click.option("--no-rrd", is_flag=True, help="Only print the summary table; write nothing.")
@viewer_options
@click.option("--force", "-f", is_flag=True, help="Overwrite an existing recording.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as one JSON object.")
@handle_errors
def compare(
    logs: tuple[Path, ...],
    output: Path | None,
    no_rrd: bool,
    spawn: bool,
    connect: str | None,
    serve_web: bool,
    web_port: int,
    force: bool,
    as_json: bool,
    from_: str | None,
    run: str | None,
    cell: tuple[str, ...],
) -> None:
    """Put recorded runs side by side in one Rerun recording, and print their summary.

    Every run goes under runs/<label>/ (labels from the policy names, made unique with
    the instance, seed or horizon where needed). The embedded layout has one column per
    run -- AoI against the oracle's, the channel played, the empirical means, the
    candidate (competitive) set -- above one panel overlaying every run's regret curve.
    The table gives per run the final pathwise regret, the paper's estimator, pulls per
    arm, the share of slots on the best arm, the slots where the AoI-aware override
    fired and the first slot from which the run stayed on the best arm. Runs on
    different instances or horizons are allowed, with a warning.

    \b
    Examples:
      corraoi compare runs/ucb-I1-s0.mcap runs/cucb-I1-s0.mcap -o ucb-vs-cucb.rrd
      corraoi compare runs/*.mcap --serve-web
      corraoi compare --from sweeps/I2 --run worst    # each policy's worst run of a sweep
    """
    from viewer.compare import compare as do_compare
    from viewer.compare import prepare

    if from_ is not None:
        if logs:
            raise UsageError("A.mcap ... and --from: compare logs or a sweep's runs, not both")
        logs = _record_from(from_, run if run is not None else "worst", cell, force)
    elif run is not None or cell:
        raise UsageError(f"{'--run' if run is not None else '--cell'}: only with --from SWEEP")
    elif not logs:
        raise UsageError("nothing to compare: give logs (A.mcap B.mcap ...) or --from SWEEP")
    keep_pandas_out()

    out = output
    viewer = ViewerChoice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port)
    if no_rrd and (out is not None or viewer.asked):
        raise UsageError("--no-rrd: nothing to send; leave out -o and the viewer options")
    runs, warnings = prepare(logs)  # bad input: one line, exit 2, nothing written
    if out is None and not viewer.asked and not no_rrd:
        out = Path("compare.rrd")
    if out is not None:
        from recorder.paths import check_output

        _not_an_input(out, logs)
        check_output(out, overwrite=force, what="Rerun recording")
    for w in warnings:
        warn(w)
    url = viewer.start() if viewer.asked else None
    total = sum(r.log.n_slots for r in runs)
    try:
        with _progress(total, "compare") as bar:
            result = do_compare([r.log for r in runs], rrd_path=out, viewer_url=url,
                                overwrite=force, on_block=bar.update)  # fmt: skip
    except BaseException:
        viewer.stop()
        raise
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2))
    else:
        say(result.table())
        if result.path is not None:
            click.echo(f"Rerun recording: {safe_text(result.path)}")
            if not viewer.asked:
                from recorder.live import view_command

                click.echo(
                    f"open in the Rerun viewer:  {safe_text(view_command([str(result.path)]))}"
                )
    viewer.serve_until_stopped()


# ---------------------------------------------------------------------------- diff


@click.command("diff")
@click.argument("a", type=_LOG, metavar="A.mcap")
@click.argument("b", type=_LOG, metavar="B.mcap")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option("--fields", multiple=True, metavar="NAME[,NAME...]",
              help="Compare only these fields (x, arm, success, aoi, oracle_aoi, regret, "
              "estimator, override, mu_hat, pulls, candidates) [default: all].")  # fmt: skip
@click.option("--atol", type=float, default=0.0, show_default=True,
              help="Absolute tolerance of the float fields (estimator, mu_hat); the others "
              "compare exactly.")  # fmt: skip
@click.option("--quiet", "-q", is_flag=True, help="Print nothing; only the exit status.")
@errors_exit(2)  # any trouble exits 2, as diff(1)
def diff(
    a: Path, b: Path, as_json: bool, fields: tuple[str, ...], atol: float, quiet: bool
) -> None:
    """Compare two recorded runs slot by slot.

    Configuration differences come first, then per field the first slot where the runs
    diverge and how many slots differ, then the final figures of both. Exit status as
    diff(1): 0 identical, 1 different, 2 trouble (a file that is not a readable log, a
    bad option).

    \b
    Examples:
      corraoi diff a.mcap b.mcap                  # the same seed twice: exit 0
      corraoi diff ucb.mcap cucb.mcap --fields x,arm
    """
    from viewer.diffs import diff as do_diff

    report = do_diff(a, b, fields=fields or None, atol=atol)
    if not quiet:
        if as_json:
            click.echo(json.dumps(report.to_dict(), indent=2))
        else:
            say(report.message())
    sys.exit(0 if report.identical else 1)


def _record_from(folder: str, run: str, cells: tuple[str, ...], force: bool) -> tuple[Path, ...]:
    """``compare --from``: the chosen runs of the sweep, recorded into ``runs/`` (MCAP only;
    a log already there with the same run and complete is used as it is)."""
    from corraoi.drill import choose
    from corraoi.engine import set_workers
    from corraoi.experiments import record_run
    from corraoi.text import safe_name
    from recorder.errors import LogError, OutputError
    from recorder.reader import open_log

    drills = choose(folder, run, cells=cells, warn=warn)
    plans = [(d, Path("runs") / f"{safe_name(d.name)}.mcap") for d in drills]
    todo = []
    for d, path in plans:
        if path.is_file():
            try:
                log = open_log(path, verify=False)
                same = log.status == "complete" and log.config.to_dict() == d.config.to_dict()
            except LogError:
                same = False
            if same:
                continue
            if not force:
                raise OutputError(f"{path}: already exists and holds another run; use --force "
                                  "to overwrite it")  # fmt: skip
        todo.append((d, path))
    set_workers(1)  # one run has nothing to spread over threads
    for d, path in todo:
        click.echo(f"recording {safe_text(path)} ({safe_text(d.config.instance.name)} "
                   f"{safe_text(d.cell or d.config.label)}, run {d.run}, seed "
                   f"{d.config.seed}, {d.choice})", err=True)  # fmt: skip
        record_run(d.config, path, overwrite=True)
    return tuple(path for _, path in plans)


# ---------------------------------------------------------------------------- info


@click.command("info")
@click.argument("log", type=_LOG, metavar="RUN.mcap|SWEEP")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@handle_errors
def info(log: Path, as_json: bool) -> None:
    """Show what a log holds: configuration, slots, how it ended, summary figures.

    For a sweep folder (SWEEP, as `sweep -o` or `reproduce -o` wrote it): its grid and
    status and, per instance, the runs worth watching (worst, median and best per policy,
    the widest paired gaps), each with the `corraoi record --from` command that records it.

    A log whose writer was killed (RUN.mcap.partial, or a file without footer) is
    reported as cut short, with the last slot it holds; `corraoi recover` finishes it.
    """
    if log.is_dir() and any((d / "manifest.json").is_file() for d in (log, log.parent)):
        # a sweep folder (or one group's folder in it): its runs worth watching
        from viewer.info import sweep_info, sweep_info_text

        data = sweep_info(log)
        text = sweep_info_text
    else:
        from viewer.info import info_text, log_info

        data = log_info(log)
        text = info_text
    if as_json:
        click.echo(json.dumps(data, indent=2))
    else:
        say(text(data))


# ---------------------------------------------------------------------------- recover


@click.command("recover")
@click.argument("log", type=_LOG, metavar="BROKEN.mcap")
@output_option(metavar="FIXED.mcap",
               help="Where to write the finished log [default: BROKEN.recovered.mcap beside "
               "it; for RUN.mcap.partial, RUN.recovered.mcap].")  # fmt: skip
@click.option("--force", "-f", is_flag=True, help="Overwrite FIXED.mcap if it exists.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON object.")
@handle_errors
def recover(log: Path, output: Path | None, force: bool, as_json: bool) -> None:
    """Rewrite a log whose writer died into a finished, indexed one.

    Every complete chunk of BROKEN.mcap is copied (message bytes unchanged) into
    FIXED.mcap, which gets the end record, indexes, summary and footer, so that every
    MCAP reader opens it. A damaged chunk (bad CRC, bad sizes, invalid slots) ends the
    copy: the slots before it are kept and the damage is named. BROKEN.mcap is not
    modified.

    \b
    Examples:
      corraoi recover runs/cucb-I1-s0.mcap.partial     # -> runs/cucb-I1-s0.recovered.mcap
      corraoi recover runs/cucb-I1-s0.mcap.partial -o runs/cucb-I1-s0.mcap
    """
    from viewer.recover import default_output
    from viewer.recover import recover as do_recover

    out = output if output is not None else default_output(log)
    done = do_recover(log, out, overwrite=force)
    if as_json:
        click.echo(json.dumps(done.to_dict(), indent=2))
        return
    if done.source_status == "complete":
        warn(f"{done.source}: was already finished; wrote an identical re-indexed copy")
    if done.damage:
        warn(f"{done.damage}; kept the slots before it")
    dropped = f"; dropped {done.dropped_bytes} bytes of a torn record" if done.dropped_bytes else ""
    click.echo(
        f"recovered {done.slots} of {done.horizon} slots (slots 1..{done.slots}) from "
        f"{safe_text(done.source)} ({done.source_status}{dropped}) into "
        f"{safe_text(done.path)} ({done.status})"
    )


__all__ = ["compare", "diff", "info", "recover", "replay"]
