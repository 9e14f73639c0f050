"""``corraoi record``'s report: the runs the face recorded
(:func:`corraoi.face.sessions.record_from_options`), printed (or their JSON) once they are done.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import click

from corraoi.text import safe_text

if TYPE_CHECKING:  # the face imports the recorder: `corraoi --help` must not
    from corraoi.face.sessions import Session


def report(session: Session, *, as_json: bool) -> None:
    """The runs recorded: one JSON object, or a few lines per run; then how to view them."""
    results = session.results
    command = session.view_command()
    if as_json:
        out = {
            "runs": [
                {
                    "label": r.plan.config.label,
                    "policy": r.plan.config.policy.name,
                    "params": r.plan.config.policy.params,
                    "instance": r.plan.config.instance_name,
                    "seed": r.plan.config.seed,
                    "horizon": r.plan.config.horizon,
                    "slots": r.slots,
                    "complete": r.slots == r.plan.config.horizon,
                    "regret": r.regret,
                    "estimator": r.estimator,
                    "pulls": r.pulls,
                    **(
                        {
                            "sources": r.plan.config.sources,
                            "regret_by_source": list(r.summary.regret_by_source or ()),
                            "collisions": r.summary.collisions,
                        }
                        if r.plan.config.sources > 1 and r.summary is not None
                        else {}
                    ),
                    "mcap": str(r.mcap) if r.mcap else None,
                    "rrd": str(r.rrd) if r.rrd else None,
                    "wall_s": round(r.wall, 4),
                    "compile_s": round(r.compile_s, 4),
                }
                for r in results
            ],
            "view": command,
        }
        click.echo(json.dumps(out, indent=2))
        return
    for r in results:
        c = r.plan.config
        params = ", ".join(f"{k}={v:g}" for k, v in c.policy.params.items())
        run_s = r.wall - r.compile_s
        rate = r.slots / run_s if run_s > 0 else 0.0
        compiled = f", after {r.compile_s:.1f} s compiling" if r.compile_s else ""
        done = "" if r.slots == c.horizon else " (interrupted)"
        click.echo(
            f"{safe_text(c.policy.name)}{f' ({params})' if params else ''} on "
            f"{safe_text(c.instance_name)}, seed "
            f"{c.seed}: {r.slots} of {c.horizon} slots{done} in {r.wall:.2f} s "
            f"({rate:,.0f} slots/s{compiled})"
        )
        if r.regret is not None and r.estimator is not None:
            click.echo(
                f"  AoI regret at slot {r.slots}: {r.regret} (pathwise), "
                f"{r.estimator:.1f} (paper's estimator sum aoi - t/mu*)"
            )
            pulls = "  ".join(f"{k + 1}: {n}" for k, n in enumerate(r.pulls))
            click.echo(f"  pulls per arm: {pulls}")
        elif c.sources > 1 and r.summary is not None and r.regret is not None:
            each = ", ".join(str(v) for v in r.summary.regret_by_source or ())
            click.echo(
                f"  {c.sources} sources: AoI regret at slot {r.slots}: {r.regret} (pathwise, "
                f"summed; by source {each}), {r.summary.collisions} collisions"
            )
            pulls = "  ".join(f"{k + 1}: {n}" for k, n in enumerate(r.pulls))
            click.echo(f"  pulls per arm (all sources): {pulls}")
        click.echo(f"  MCAP log:        {safe_text(r.mcap)}")
        if r.rrd is not None:
            click.echo(f"  Rerun recording: {safe_text(r.rrd)}")
    if command:
        click.echo(f"open in the Rerun viewer:  {safe_text(command)}")


__all__ = ["report"]
