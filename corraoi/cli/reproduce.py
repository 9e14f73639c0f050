"""``corraoi reproduce``: the paper's simulations (I1 and I2, all twelve policies), each
instance written as ``sweep -o`` writes it, and a summary.md with both ranked tables;
``corraoi reproduce decentralized``: our experiment of many sources (docs/decentralized.md).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import click

from corraoi import limits
from corraoi.text import safe_text

from .common import handle_errors
from .options import RUNS, WORKERS, backend_option, horizon_option, output_option, seed_option
from .sweep_run import run_grid, settle_backend
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
    from corraoi.face.sweeps import paper_grid, write_paper_summary

    out = output if output is not None else Path(which)
    if which == "decentralized":
        from corraoi.face.decentralized import RUNS

        _decentralized(out, runs if runs is not None else RUNS, horizon, seed,
                       workers, force, backend, as_json)  # fmt: skip
        return
    runs = runs if runs is not None else 200
    limits.check_seed(seed, runs=runs, name="--seed")
    grid = paper_grid(runs=runs, horizon=horizon, seed=seed, backend=backend or "cpu")
    grid = settle_backend(grid)
    limits.check_sweep_memory(runs, 4, policies=1,
                              checkpoints=grid.checkpoints if grid.backend == "cpu" else 0)
    start = time.perf_counter()
    outcome = run_grid(grid, out=out, scheduler=None, resume=False, force=force, workers=workers,
                   label="reproduce")  # fmt: skip
    summaries: dict[str, Any] = {}
    for summary in outcome.summaries:
        summaries[summary["instance"]["name"]] = summary
        if not as_json:
            print_table(summary, output)
            click.echo("")
    instances = write_paper_summary(out, outcome.summaries, runs=runs, horizon=horizon,
                                    seed=seed)  # fmt: skip
    if as_json:
        click.echo(json.dumps({"output": str(out), "instances": summaries}, indent=2))
    else:
        click.echo(f"wrote {safe_text(out)}/: " + ", ".join(f"{n}/" for n in instances)
                   + ", summary.md")  # fmt: skip
    click.echo(f"total wall time {time.perf_counter() - start:.2f} s", err=True)


def _decentralized(out: Path, runs: int, horizon: int, seed: int, workers: int | None,
                   force: bool, backend: str | None, as_json: bool) -> None:  # fmt: skip
    from corraoi.face.decentralized import write_decentralized
    from corraoi.face.sweeps import decentralized_grid

    from .common import warn

    limits.check_seed(seed, runs=runs, name="--seed")
    grid = settle_backend(decentralized_grid(runs=runs, horizon=horizon, seed=seed,
                                             backend=backend or "cpu"))  # fmt: skip
    start = time.perf_counter()
    outcome = run_grid(grid, out=out, scheduler=None, resume=False, force=force,
                       workers=workers, label="reproduce decentralized")  # fmt: skip
    (summary,) = outcome.summaries
    if not as_json:
        print_table(summary, out)
    files = write_decentralized(out, summary, grid, runs=runs, horizon=horizon, seed=seed,
                                warn=warn)  # fmt: skip
    if as_json:
        click.echo(json.dumps({"output": str(out), "summary": summary}, indent=2))
    else:
        click.echo(f"wrote {safe_text(out)}/: the sweep folder, " + ", ".join(files))
    click.echo(f"total wall time {time.perf_counter() - start:.2f} s", err=True)


__all__ = ["reproduce"]
