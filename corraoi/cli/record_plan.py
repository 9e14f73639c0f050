"""``corraoi record --from SWEEP``'s options: what the sweep fixes refused as an option, and
where each run comes from said. The runs are chosen from the sweep folder by the face
(:func:`corraoi.face.sessions.record_from_options`).
"""

from __future__ import annotations

from typing import Any

import click

from corraoi.errors import UsageError
from corraoi.text import safe_text


def from_sweep_policies(policy: tuple[str, ...]) -> tuple[str, ...] | None:
    """``--policy`` with ``--from``: its words when it was given (the sweep's labels select its
    cells, any other word adds a policy), else None; what the sweep fixes cannot be given."""
    from click.core import ParameterSource

    ctx = click.get_current_context()
    fixed = [("instance", "--instance"), ("horizon", "--horizon"), ("seed", "--seed"),
             ("channel", "--channel")]  # fmt: skip
    for name, option in fixed:
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None):
            raise UsageError(f"{option} and --from: the sweep fixes the {name} of its runs; "
                             "leave out " + option)  # fmt: skip
    given = ctx.get_parameter_source("policy") not in (ParameterSource.DEFAULT, None)
    return policy if given else None


def say_where_from(plans: list[Any]) -> None:
    """Where each run planned with ``--from`` comes from (one line each, on stderr)."""
    for d in (p.drill for p in plans):
        what = "" if d.cell is not None else ", added"
        label = d.cell if d.cell is not None else d.config.policy.label
        click.echo(f"from {safe_text(d.folder)}: {safe_text(d.config.instance.name)} "
                   f"{safe_text(label)}, run {d.run} (seed {d.config.seed}, {d.choice}{what})",
                   err=True)  # fmt: skip


__all__ = ["from_sweep_policies", "say_where_from"]
