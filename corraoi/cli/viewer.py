"""``corraoi diff | info | recover``: commands that read logs only, and nothing else.

Nothing here simulates: the logs hold every slot. Each command calls the face
(:mod:`corraoi.face.views`), imported inside the command so that ``corraoi --help`` stays
fast. ``replay`` and ``compare`` are :mod:`corraoi.cli.replay`'s and
:mod:`corraoi.cli.compare`'s.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import click

from corraoi.face.words import DIFF_FIELDS, TOLERANT_FIELDS
from corraoi.text import safe_text

from .common import errors_exit, handle_errors, say, warn
from .options import output_option
from .reading import LOG

# ---------------------------------------------------------------------------- diff


@click.command("diff")
@click.argument("a", type=LOG, metavar="A.mcap")
@click.argument("b", type=LOG, metavar="B.mcap")
@click.option("--json", "as_json", is_flag=True, help="Print the report as one JSON object.")
@click.option(
    "--fields",
    multiple=True,
    metavar="NAME[,NAME...]",
    help=f"Compare only these fields ({', '.join(DIFF_FIELDS)}) [default: all].",
)
@click.option("--atol", type=float, default=0.0, show_default=True,
              help=f"Absolute tolerance of the float fields ({', '.join(TOLERANT_FIELDS)}); the "
              "others compare exactly.")  # fmt: skip
@click.option("--quiet", "-q", is_flag=True, help="Print nothing; only the exit status.")
@errors_exit(2)  # any trouble exits 2, as diff(1)
def diff(
    a: Path, b: Path, as_json: bool, fields: tuple[str, ...], atol: float, quiet: bool
) -> None:
    """Compare two recorded runs slot by slot.

    Runs that are not paired (another instance, channel or seed: they did not see one
    hidden path) are said so on the first line. Configuration differences come next, then
    per field the first slot where the runs diverge and how many slots differ, then the
    final figures of both. Exit status as diff(1): 0 identical, 1 different (runs that are
    not paired always are: their configurations differ), 2 trouble (a file that is not a
    readable log, a bad option).

    \b
    Examples:
      corraoi diff a.mcap b.mcap                  # the same seed twice: exit 0
      corraoi diff ucb.mcap cucb.mcap --fields x,arm
    """
    from corraoi.face.views import diff_files

    report = diff_files(a, b, fields=fields, atol=atol)
    if not quiet:
        if as_json:
            click.echo(json.dumps(report.to_dict(), indent=2))
        else:
            say(report.message())
    sys.exit(0 if report.identical else 1)


# ---------------------------------------------------------------------------- info


@click.command("info")
@click.argument("log", type=LOG, metavar="RUN.mcap|SWEEP")
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
    from corraoi.face.views import info as log_info

    found = log_info(log)
    if as_json:
        click.echo(json.dumps(found.to_dict(), indent=2))
    else:
        say(found.text())


# ---------------------------------------------------------------------------- recover


@click.command("recover")
@click.argument("log", type=LOG, metavar="BROKEN.mcap")
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
    from corraoi.face.views import recover as recover_log

    done = recover_log(log, output, force=force)
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


__all__ = [
    "diff",
    "info",
    "recover",
]
