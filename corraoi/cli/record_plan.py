"""The runs ``corraoi record --from SWEEP`` records: chosen from a sweep folder
(corraoi.experiments.drill), with what the sweep fixed refused as an option. Their files are
planned by the face (:func:`corraoi.face.recording.plan_files`).
"""

from __future__ import annotations

from typing import Any

import click

from corraoi.errors import UsageError
from corraoi.text import safe_text

from .common import warn


def from_sweep(
    folder: str,
    run: str,
    cells: tuple[str, ...],
    policy: tuple[str, ...],
    param: tuple[str, ...],
    *,
    c: float | None,
    beta: float | None,
    kept_code: bool = False,
    allow_changed_code: bool = False,
) -> list[Any]:
    """The runs ``--from`` names (:func:`corraoi.face.sessions.runs_from_sweep`); what the
    sweep fixed cannot be given too."""
    from click.core import ParameterSource

    from corraoi.face.sessions import runs_from_sweep

    ctx = click.get_current_context()
    fixed = [("instance", "--instance"), ("horizon", "--horizon"), ("seed", "--seed"),
             ("channel", "--channel")]  # fmt: skip
    for name, option in fixed:
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None):
            raise UsageError(f"{option} and --from: the sweep fixes the {name} of its runs; "
                             "leave out " + option)  # fmt: skip
    given = ctx.get_parameter_source("policy") not in (ParameterSource.DEFAULT, None)
    return runs_from_sweep(folder, run, cells, policy if given else None, param, c=c, beta=beta,
                           kept_code=kept_code, allow_changed_code=allow_changed_code,
                           hold=ctx.with_resource, warn=warn)  # fmt: skip


def say_where_from(drills: list[Any]) -> None:
    for d in drills:
        what = "" if d.cell is not None else ", added"
        label = d.cell if d.cell is not None else d.config.policy.label
        click.echo(f"from {safe_text(d.folder)}: {safe_text(d.config.instance.name)} "
                   f"{safe_text(label)}, run {d.run} (seed {d.config.seed}, {d.choice}{what})",
                   err=True)  # fmt: skip


__all__ = ["from_sweep", "say_where_from"]
