"""``corraoi reproduce``: the paper's simulations (I1 and I2, all twelve policies), each
instance written as ``sweep -o`` writes it, and a summary.md with both ranked tables;
``corraoi reproduce decentralized``: our experiment of many sources (docs/decentralized.md).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from corraoi.text import safe_text

from .common import handle_errors
from .options import RUNS, WORKERS, backend_option, horizon_option, output_option, seed_option
from .sweep_run import interrupted_or
from .sweep_table import print_table


@click.command()
@click.argument("which", required=False, default="paper",
                type=click.Choice(["paper", "decentralized"]), metavar="[paper|decentralized]")
@output_option(metavar="DIR", help="paper: writes DIR/I1/, DIR/I2/ (each as `sweep -o`), "
               "DIR/summary.md; decentralized: the sweep folder, regret-vs-sources.png and "
               "decentralized.md [default: paper, or decentralized].")  # fmt: skip
@click.option("--runs", "-n", type=RUNS, default=None,
              help="Monte Carlo runs per policy [default: 200; decentralized 50].")
@horizon_option(10_000)
@seed_option
@click.option("--workers", "-j", type=WORKERS, default=None,
              help="Threads for the engine [default: every core].")  # fmt: skip
@click.option("--force", is_flag=True, help="Overwrite sweeps already in DIR.")
@backend_option("cpu, gpu or auto, as for sweep [default: cpu] (docs/gpu.md).")
@click.option("--json", "as_json", is_flag=True,
              help="Print both summaries as one JSON object instead of tables.")  # fmt: skip
@handle_errors
def reproduce(
    which: str,
    output: Path | None,
    runs: int | None,
    horizon: int,
    seed: int,
    workers: int | None,
    force: bool,
    backend: str | None,
    as_json: bool,
) -> None:
    """Regenerate the paper's simulations: I1 and I2, all twelve policies, 200 runs, T = 10,000.

    Each instance gets the logs, summary and figure of `corraoi sweep -o`; DIR/summary.md
    puts the two ranked tables side by side.

    `corraoi reproduce decentralized` runs our experiment of many sources sharing the
    channels (docs/decentralized.md: the decentralized paper's body could not be read, so
    the choices and the ordering are ours): I1, M = 1..4 sources, rhoRand, MCTopM and the
    centralized baseline over UCB, CUCB, TS and CTS, 50 runs, T = 10,000; the figure of
    regret against M is DIR/regret-vs-sources.png.

    \b
    Examples:
      corraoi reproduce -o paper && open paper/I1/figure.png
      corraoi reproduce decentralized -o dec && open dec/regret-vs-sources.png
    """
    from corraoi.face.sweeps import reproduce_from_options

    from .common import keep_pandas_out, warn
    from .reading import progress

    out = output if output is not None else Path(which)
    start = time.perf_counter()
    done = interrupted_or(reproduce_from_options(
        which, out=out, runs=runs, horizon=horizon, seed=seed, workers=workers, force=force,
        backend=backend, warn=warn, say=lambda line: click.echo(line, err=True),
        progress=progress, before_folder=keep_pandas_out))  # fmt: skip
    if as_json:
        key, value = (("instances", {s["instance"]["name"]: s for s in done.summaries})
                      if which == "paper" else ("summary", done.summaries[0]))  # fmt: skip
        click.echo(json.dumps({"output": str(out), key: value}, indent=2))
    else:
        for summary in done.summaries:
            print_table(summary, out if which == "decentralized" else output)
            if which == "paper":
                click.echo("")
        click.echo(f"wrote {safe_text(out)}/: " + ", ".join(done.wrote))
    click.echo(f"total wall time {time.perf_counter() - start:.2f} s", err=True)


__all__ = ["reproduce"]
