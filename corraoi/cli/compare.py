"""``corraoi compare``: recorded runs side by side in one Rerun recording, with their summary
table; with ``--from SWEEP``, the chosen runs of a sweep are recorded first. The face
(:mod:`corraoi.face.views`) is imported inside the command, so ``corraoi --help`` stays fast.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from corraoi.errors import UsageError
from corraoi.text import safe_text

from .common import handle_errors, keep_pandas_out, say, warn
from .live import viewer_choice, viewer_options
from .options import code_options, from_only, output_option
from .reading import LOG, progress


@click.command("compare")
@click.argument("logs", nargs=-1, type=LOG, metavar="A.mcap B.mcap ...")
@click.option("--from", "from_", metavar="SWEEP", default=None,
              help="Instead of logs: record the chosen run of every policy of the sweep folder "
                   "SWEEP into runs/ (as `record --from`) and compare those.")  # fmt: skip
@click.option("--run", "run", metavar="N|worst|best|median|widest-gap", default=None,
              help="With --from: which run of each policy (as for record) [default: worst].")
@click.option("--cell", "cell", metavar="LABEL", multiple=True,
              help="With --from: only these cells (as for record); repeat for several.")
@code_options
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
    kept_code: bool,
    allow_changed_code: bool,
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
    from corraoi.face.views import compare_logs

    if from_ is not None:
        if logs:
            raise UsageError("A.mcap ... and --from: compare logs or a sweep's runs, not both")
        logs = _record_from(from_, run if run is not None else "worst", cell, force,
                            kept_code=kept_code, allow_changed_code=allow_changed_code)
    elif run is not None or cell or kept_code or allow_changed_code:
        given = from_only(run, cell, kept_code, allow_changed_code)
        raise UsageError(f"{given}: only with --from SWEEP")
    elif not logs:
        raise UsageError("nothing to compare: give logs (A.mcap B.mcap ...) or --from SWEEP")
    keep_pandas_out()

    out = output
    viewer = viewer_choice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port)
    if no_rrd and (out is not None or viewer.asked):
        raise UsageError("--no-rrd: nothing to send; leave out -o and the viewer options")
    result, url = compare_logs(logs, out, viewer=viewer, write=not no_rrd, force=force,
                               progress=progress, warn=warn)  # fmt: skip
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2))
    else:
        say(result.table())
        if result.path is not None:
            click.echo(f"Rerun recording: {safe_text(result.path)}")
            if not viewer.asked:
                from corraoi.face.live import open_command

                click.echo(
                    f"open in the Rerun viewer:  {safe_text(open_command([str(result.path)]))}"
                )
    viewer.serve_until_stopped()


def _record_from(folder: str, run: str, cells: tuple[str, ...], force: bool, *,
                 kept_code: bool = False, allow_changed_code: bool = False) -> tuple[Path, ...]:
    """``compare --from``: the chosen runs of the sweep, recorded into ``runs/``
    (:meth:`corraoi.face.sweeps.Sweep.record_each`)."""
    from corraoi.face.sweeps import record_each_from

    runs = record_each_from(folder, run, cells=cells, force=force, kept_code=kept_code,
                            allow_changed_code=allow_changed_code,
                            say=lambda line: click.echo(line, err=True), warn=warn)  # fmt: skip
    return tuple(r.path for r in runs)


__all__ = ["compare"]
