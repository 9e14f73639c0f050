"""What ``corraoi record`` records, and into which files: the runs named by the options or
chosen from a sweep folder (``--from``, corraoi.experiments.drill), their MCAP and Rerun paths
(templates
filled in, clashes refused), and whether a run's files already hold it (up to date).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click

from corraoi.errors import UsageError
from corraoi.text import safe_text

from .common import warn

DEFAULT_OUT = "runs/{label}.mcap"
_PLACEHOLDERS = ("{label}", "{policy}", "{instance}", "{seed}", "{run}", "{from}")
#: The default name of a run recorded from a sweep (--from): where it came from.
FROM_OUT = "runs/{from}.mcap"


@dataclass
class Plan:
    """One run to record: its configuration (a ``RunConfig``) and its files."""

    config: Any  # RunConfig
    mcap: Path
    rrd: Path | None
    #: where it came from (a corraoi.experiments.drill.Drill, --from): what it must give again
    drill: Any = None


def _expand(template: str, config: Any, drill: Any = None) -> Path:
    """The path ``template`` names for ``config``. The names filled in are data (from an
    instance file or a plug-in): each goes through ``safe_name``, so none can add a folder,
    climb out of one (``../``) or carry control codes into the file name."""
    from corraoi.text import safe_name

    values = {
        "{label}": config.label,
        "{policy}": config.policy.name,
        "{instance}": config.instance.name,
        "{seed}": str(config.seed),
        "{run}": str(drill.run) if drill is not None else str(config.seed),
        "{from}": drill.name if drill is not None else config.label,
    }
    out = template
    for key, value in values.items():
        out = out.replace(key, safe_name(value))
    return Path(out)


def _rrd_beside(mcap: Path) -> Path:
    return mcap.with_suffix(".rrd") if mcap.suffix == ".mcap" else Path(f"{mcap}.rrd")


def plan_files(
    configs: list[Any], out: str | None, rrd: str | None, no_rrd: bool, drills: Any = None
) -> list[Plan]:
    several = len(configs) > 1
    for option, value in (("-o/--output", out), ("--rrd", rrd)):
        if value is not None and several and not any(p in value for p in _PLACEHOLDERS):
            raise UsageError(
                f"{option} {value}: names one file but {len(configs)} "
                f"{'runs' if drills else 'policies'} are recorded; put {{label}} or "
                f"{'{from}' if drills else '{policy}'} in it (e.g. -o "
                f"'runs/{'{from}' if drills else '{label}'}.mcap')"
            )
        if value is not None and value.strip() == "":
            raise UsageError(f"{option}: empty path")
    plans = []
    for i, config in enumerate(configs):
        drill = drills[i] if drills else None
        mcap = _expand(out or (FROM_OUT if drill else DEFAULT_OUT), config, drill)
        path = None if no_rrd else (_expand(rrd, config, drill) if rrd else _rrd_beside(mcap))
        plans.append(Plan(config, mcap, path, drill))
    seen: dict[str, str] = {}
    for plan in plans:
        for kind, p in (("MCAP log", plan.mcap), ("Rerun recording", plan.rrd)):
            if p is None:
                continue
            key = os.path.abspath(p)
            if key in seen:
                raise UsageError(f"{p}: used twice (as {seen[key]} and as {kind})")
            seen[key] = kind
    return plans


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
    """The runs ``--from`` names (corraoi.experiments.drill); what the sweep fixed cannot be given
    too."""
    from click.core import ParameterSource

    from corraoi.experiments.drill import choose
    from corraoi.policies import make_policies, parse_param_assignments

    ctx = click.get_current_context()
    fixed = [("instance", "--instance"), ("horizon", "--horizon"), ("seed", "--seed"),
             ("channel", "--channel")]  # fmt: skip
    for name, option in fixed:
        if ctx.get_parameter_source(name) not in (ParameterSource.DEFAULT, None):
            raise UsageError(f"{option} and --from: the sweep fixes the {name} of its runs; "
                             "leave out " + option)  # fmt: skip
    given = ctx.get_parameter_source("policy") not in (ParameterSource.DEFAULT, None)
    if not given and (param or c is not None or beta is not None):
        raise UsageError("--c/--beta/--param and --from: the sweep fixes its policies' "
                         "parameters (with --policy they set those of a policy added)")
    specs = (make_policies(policy, parse_param_assignments(param), c=c, beta=beta, warn=warn)
             if given else [])  # fmt: skip
    from corraoi.face.resolve import TRACE_READERS

    return choose(folder, run, cells=cells, policies=specs, warn=warn, kept_code=kept_code,
                  allow_changed_code=allow_changed_code,
                  trace_readers=TRACE_READERS)  # fmt: skip


def say_where_from(drills: list[Any]) -> None:
    for d in drills:
        what = "" if d.cell is not None else ", added"
        label = d.cell if d.cell is not None else d.config.policy.label
        click.echo(f"from {safe_text(d.folder)}: {safe_text(d.config.instance.name)} "
                   f"{safe_text(label)}, run {d.run} (seed {d.config.seed}, {d.choice}{what})",
                   err=True)  # fmt: skip


def up_to_date(plan: Plan) -> bool:
    """The plan's files exist, and its MCAP log is complete with the same configuration
    (the version of corraoi included): recording again would write the same bytes."""
    from corraoi.errors import LogError
    from recorder.slotlog.reader import open_log

    if not plan.mcap.is_file() or (plan.rrd is not None and not plan.rrd.is_file()):
        return False
    try:
        log = open_log(plan.mcap, verify=False)
    except LogError:
        return False
    return log.status == "complete" and log.config.to_dict() == plan.config.to_dict()


__all__ = ["DEFAULT_OUT", "FROM_OUT", "Plan", "from_sweep", "plan_files", "say_where_from",
           "up_to_date"]  # fmt: skip
