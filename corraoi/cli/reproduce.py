"""``corraoi reproduce``: the paper's simulations (I1 and I2, all twelve policies), each
instance written as ``sweep -o`` writes it, and a summary.md with both ranked tables.
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
@output_option(metavar="DIR", default=Path("paper"), show_default=True,
               help="Writes DIR/I1/, DIR/I2/ (each as `sweep -o`), DIR/summary.md.")  # fmt: skip
@click.option("--runs", "-n", type=RUNS, default=200, show_default=True,
              help="Monte Carlo runs per policy.")  # fmt: skip
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
    output: Path,
    runs: int,
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

    \b
    Example:
      corraoi reproduce -o paper && open paper/I1/figure.png
    """
    from corraoi.face.sweeps import paper_grid, write_paper_summary

    out = output
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


__all__ = ["reproduce"]
