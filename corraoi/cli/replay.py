"""``corraoi replay``: one recorded run re-rendered into Rerun (an ``.rrd`` file or a viewer),
or served to Foxglove, without recomputing anything (:mod:`corraoi.face.views`, imported
inside the command, so ``corraoi --help`` stays fast).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from corraoi.errors import UsageError
from corraoi.text import safe_text

from .common import handle_errors, keep_pandas_out, warn
from .live import foxglove_choice, foxglove_options, viewer_choice, viewer_options
from .options import output_option
from .reading import LOG, progress


@click.command("replay")
@click.argument("log", type=LOG, metavar="RUN.mcap")
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
    from corraoi.face.views import replay_log

    keep_pandas_out()

    viewer = viewer_choice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port)
    if foxglove is not None or pace is not None or start != 1:
        if foxglove is None:
            raise UsageError("--pace and --start: only with --foxglove")
        if output is not None or viewer.asked:
            raise UsageError("--foxglove: replays to Foxglove only; leave out -o and the "
                             "Rerun viewer options")  # fmt: skip
        _replay_foxglove(log, foxglove, pace=pace, start=start, as_json=as_json)
        return
    done, url = replay_log(log, output, viewer=viewer, force=force, progress=progress,
                           warn=None if as_json else warn)  # fmt: skip
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
        from corraoi.face.live import open_command

        click.echo(f"open in the Rerun viewer:  {safe_text(open_command([str(done.path)]))}")
    viewer.serve_until_stopped()


def _replay_foxglove(log: Path, address: str, *, pace: float | None, start: int,
                     as_json: bool) -> None:  # fmt: skip
    """``replay --foxglove``: serve the log's slots from ``start`` on, then stop."""
    from corraoi.face.views import replay_foxglove

    live = foxglove_choice(address, pace=pace)
    run, last, url = replay_foxglove(log, live, start=start, progress=progress)
    if as_json:
        click.echo(json.dumps({"log": str(log), "label": run.label, "first": start,
                               "last": last, "foxglove": url}, indent=2))  # fmt: skip
        return
    click.echo(f"replayed {safe_text(run.label)}: slots {start}..{last} of "
               f"{run.config.horizon} to Foxglove at {url}")  # fmt: skip


__all__ = ["replay"]
