"""``corraoi export``: a slot log or a sweep's per-run results as CSV or Parquet."""

from __future__ import annotations

from pathlib import Path

import click

from .common import handle_errors, keep_pandas_out


@click.command()
@click.argument("log", metavar="LOG", type=click.Path(path_type=Path))
@click.option("--out", "-o", "out", type=click.Path(path_type=Path), required=True,
              metavar="FILE",
              help="FILE.csv or FILE.parquet (the format is the extension).")  # fmt: skip
@click.option("--force", is_flag=True, help="Overwrite FILE if it exists.")
@handle_errors
def export(log: Path, out: Path, force: bool) -> None:
    """Write the table of a slot log (one row per slot) or of a sweep (one row per run and
    checkpoint, from DIR/results.parquet) to CSV or Parquet.

    LOG is a slot log (runs/cucb-I1-s0.mcap), a sweep folder written by `corraoi sweep -o
    DIR`, or its sweep.mcap. The columns are those of corraoi.load (docs/analysis.md);
    arms and states are numbered from 1. CSV has no lists: a sweep of several sources'
    regret_by_source becomes regret_by_source_1 .. _M there. Needs the analysis extra
    (pip install "corraoi[analysis]").

    \b
    Examples:
      corraoi export runs/cucb-I1-s0.mcap -o cucb.parquet
      corraoi export sweeps/I1 -o I1-runs.csv
    """
    from corraoi.face.load import export as export_table

    keep_pandas_out()

    done = export_table(log, out, force=force)
    click.echo(f"wrote {done.path}: {done.rows} rows ({done.kind}, {done.format})")
