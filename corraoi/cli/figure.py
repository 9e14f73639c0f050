"""``corraoi figure``: redraw a sweep's regret figure from its log, without simulating."""

from __future__ import annotations

import json
from pathlib import Path

import click

from corraoi.text import safe_text

from .common import handle_errors, say, warn


@click.command("figure")
@click.argument("sweep_log", metavar="SWEEP_MCAP", type=click.Path(path_type=Path))
@click.option("--output", "-o", "output", required=True, metavar="OUT.png",
              type=click.Path(path_type=Path),
              help="Figure file; its extension picks the format: .png, .svg, .pdf, .jpg, "
              ".webp or .tif.")  # fmt: skip
@click.option("--log-x", is_flag=True, help="Logarithmic t axis.")
@click.option("--log-y", is_flag=True,
              help="Logarithmic regret axis (symmetric: linear within +-1, as regret can be "
              "0 or negative early on).")  # fmt: skip
@click.option("--dpi", type=int, default=150, show_default=True,
              help="Resolution in dots per inch (20..1200; the size is 10 x 6 inches).")
@click.option("--split", is_flag=True,
              help="Small multiples: the base policies beside their AoI-aware forms, on "
              "one y scale.")  # fmt: skip
@click.option("--policies", "policies", multiple=True, metavar="NAME[,NAME...]",
              help="Draw only these policies, in this order [default: every policy in the "
              "log].")  # fmt: skip
@click.option("--force", "-f", is_flag=True, help="Overwrite OUT if it exists.")
@click.option("--json", "as_json", is_flag=True, help="Print the result as one JSON object.")
@handle_errors
def figure(
    sweep_log: Path,
    output: Path,
    log_x: bool,
    log_y: bool,
    dpi: int,
    split: bool,
    policies: tuple[str, ...],
    force: bool,
    as_json: bool,
) -> None:
    """Draw the AoI regret figure of a sweep from its log (DIR/sweep.mcap) alone.

    One line per policy (mean pathwise AoI regret against t) with its shaded 95% confidence
    band; AoI-aware variants dashed in their base policy's colour. Needs matplotlib:
    pip install 'corraoi[plot]'.

    \b
    Example:
      corraoi sweep --instance I1 -o sweeps/I1
      corraoi figure sweeps/I1/sweep.mcap -o i1.png --log-x --policies ucb,cucb,ts,cts
      corraoi figure sweeps/I1/sweep.mcap -o i1.pdf --split --log-y
    """
    from corraoi.face.sweeps import draw_sweep_figure

    sweep, names = draw_sweep_figure(sweep_log, output, log_x=log_x, log_y=log_y, dpi=dpi,
                                     split=split, policies=policies, force=force,
                                     warn=warn)  # fmt: skip
    if as_json:
        click.echo(json.dumps({
            "output": str(output), "sweep": str(sweep_log), "policies": list(names),
            "instance": sweep.instance_name, "runs": sweep.runs, "horizon": sweep.horizon,
            "complete": bool(sweep.complete),
        }, indent=2))  # fmt: skip
        return
    say(
        f"wrote {safe_text(output)}: {len(names)} polic{'y' if len(names) == 1 else 'ies'}, "
        "instance "
        f"{safe_text(sweep.instance_name)}, {sweep.runs} runs, horizon {sweep.horizon}"
    )
