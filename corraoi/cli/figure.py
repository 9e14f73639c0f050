"""``corraoi figure``: redraw a sweep's regret figure from its log, without simulating."""

from __future__ import annotations

import json
from pathlib import Path

import click

from ..errors import UsageError
from ..text import safe_text
from .common import handle_errors, say, warn


def _split(values: tuple[str, ...]) -> list[str] | None:
    names = [n.strip() for v in values for n in v.split(",") if n.strip()]
    return names or None


@click.command("figure")
@click.argument("sweep_log", metavar="SWEEP_MCAP", type=click.Path(path_type=Path))
@click.option("--output", "-o", "output", required=True, metavar="OUT.png",
              type=click.Path(path_type=Path),
              help="Figure file; its suffix picks the format (.png, .pdf, .svg).")  # fmt: skip
@click.option("--log-x", is_flag=True, help="Logarithmic t axis.")
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
    """
    from recorder.sweep_log import read_sweep
    from viewer.figure import check_policies, draw_figure

    if output.is_dir():
        raise UsageError(f"{output}: is a directory; give a file name for the figure")
    if output.exists() and not force:
        raise UsageError(f"{output}: already exists (use --force to overwrite it)")
    sweep = read_sweep(sweep_log)
    names = check_policies(sweep, _split(policies))
    if not sweep.complete:
        warn(
            f"{sweep_log}: the sweep did not finish ({sweep.status}); drawing the "
            f"{sweep.messages} checkpoint(s) it holds"
        )
    draw_figure(sweep, output, log_x=log_x, policies=names)
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
