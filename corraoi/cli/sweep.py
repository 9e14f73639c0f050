"""``corraoi sweep``: grids of Monte Carlo runs (corraoi.experiments.sweeps), in this process or on
a
Dask cluster, optionally into a resumable results folder.

Running the grid is :mod:`corraoi.cli.sweep_run`'s, the printed tables
:mod:`corraoi.cli.sweep_table`'s; ``corraoi reproduce`` (:mod:`corraoi.cli.reproduce`) and
``print_table`` stay importable from here.

recorder and viewer are imported by the library only with ``-o``; Dask only with --scheduler.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from corraoi import limits
from corraoi.errors import ConfigError, CorraoiError

from .common import handle_errors, warn
from .options import (
    CHECKPOINTS,
    RUNS,
    WORKERS,
    backend_option,
    channel_option,
    output_option,
    policy_option,
    seed_option,
)
from .sweep_run import run_grid, settle_backend
from .sweep_table import print_table

#: From this many run-slots (about a minute here) a sweep states its size before it starts.
SAY_SIZE_FROM = 10**9

#: What ``sweep -o DIR`` writes beside the group files (corraoi.experiments.sweeps).
SWEEP_FILES = ("manifest.json", "results.parquet", "sweep.mcap", "sweep.rrd", "summary.json",
               "summary.md", "figure.png")  # fmt: skip


@click.command()
@click.argument("experiment", required=False, type=click.Path(path_type=Path),
                metavar="[EXPERIMENT.toml]")  # fmt: skip
@click.option("--instance", "-i", "instance", multiple=True, metavar="NAME|PATH[,...]",
              help="Instances: built-in names (I1, I2, GE) or instance files; a comma list or "
              "the flag repeated [default: I1].")  # fmt: skip
@policy_option(default=(), required=False)
@click.option("--runs", "-n", type=RUNS, default=None,
              help="Monte Carlo runs per cell (seeds seed .. seed+runs-1, shared by every "
              "policy and parameter value) [default: 200].")  # fmt: skip
@click.option("--horizon", "-T", "horizon", multiple=True, metavar="T[,T...]",
              help="Horizons (slots); a comma list sweeps each [default: 10000].")  # fmt: skip
@seed_option
@click.option("--param", "param", multiple=True, metavar="[POLICY.]NAME=V[,V...]",
              help="Sweep a policy parameter over values (repeatable): each value goes to every "
              "listed policy that declares NAME (a warning when that is more than one), or with "
              "POLICY.NAME to that policy only ('corraoi policies').")  # fmt: skip
@click.option("--c", "c", type=float, default=None, help="Shorthand for --param c=VALUE.")
@click.option("--beta", type=float, default=None, help="Shorthand for --param beta=VALUE.")
@channel_option
@click.option("--workers", "-j", type=WORKERS, default=None,
              help="Threads for the in-process engine [default: every core].")  # fmt: skip
@click.option("--scheduler", default=None, metavar="tcp://HOST:PORT|local:N",
              help="Run the chunks on a Dask cluster: a running scheduler, or N local worker "
              "processes (needs the cluster extra) [default: this process].")  # fmt: skip
@click.option("--chunk", type=RUNS, default=None,
              help="Runs per chunk, the unit of work that is saved and resumed "
              "[default: all runs of a cell].")  # fmt: skip
@output_option(metavar="DIR", help="Write the results folder: manifest, per-run results, and "
               "per instance the sweep log, summary and figure (docs/scaling.md).")  # fmt: skip
@click.option("--resume", is_flag=True,
              help="Continue the sweep in DIR (finished chunks are kept), or extend it: more "
              "runs, policies or parameter values are appended.")  # fmt: skip
@click.option("--checkpoints", type=CHECKPOINTS, default=None,
              help="About this many checkpoint slots per curve [default: 200].")  # fmt: skip
@click.option("--force", is_flag=True, help="With -o: start over in a DIR that holds a sweep.")
@click.option("--kept-code", "kept_code", is_flag=True,
              help="With --resume: run the copy of each plug-in's source the folder kept "
              "(plugins/), whatever the file holds now.")  # fmt: skip
@click.option("--baseline", default=None, metavar="POLICY",
              help="Also report, for every other policy, the mean and 95% CI of the per-run "
              "regret difference against POLICY on the same hidden paths (paired).")  # fmt: skip
@backend_option("Where the runs go: cpu (the engine: every policy), gpu (every built-in policy "
                "on a CUDA GPU, one thread per run; needs the gpu extra), auto (the GPU when it "
                "can run every cell, else the CPU with a notice) [default: cpu] (docs/gpu.md).")
@click.option("--allow-huge", is_flag=True,
              help=f"Run a sweep of more than {limits.MAX_RUN_SLOTS:.0e} run-slots (refused "
              "otherwise: months of CPU time).")  # fmt: skip
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of a table.")
@handle_errors
def sweep(
    experiment: Path | None,
    instance: tuple[str, ...],
    policy: tuple[str, ...],
    runs: int | None,
    horizon: tuple[str, ...],
    seed: int,
    param: tuple[str, ...],
    c: float | None,
    beta: float | None,
    channel: str | None,
    workers: int | None,
    scheduler: str | None,
    chunk: int | None,
    output: Path | None,
    resume: bool,
    checkpoints: int | None,
    force: bool,
    baseline: str | None,
    backend: str | None,
    allow_huge: bool,
    as_json: bool,
    kept_code: bool,
) -> None:
    """Run a grid of policies over paired seeds and report the AoI regret at the horizon.

    A grid is every instance x policy x parameter value x horizon (a cell); every cell runs
    the same seeds, so the numbers pair across policies. Per cell: the mean pathwise AoI
    regret at T with its 95% half-width, the paper's estimator, the share of pulls on the best
    arm, the wall time, and the paper's bound where a theorem covers the policy.

    \b
    Examples:
      corraoi sweep --instance I1 --policy all --runs 200 --horizon 10000
      corraoi sweep -i I1,I2 -p ucb,cucb,sw-ucb --param window=100,1000 -o grid
      corraoi sweep experiment.toml -o grid --scheduler local:2
      corraoi sweep experiment.toml -o grid --resume        # after a crash, or to add runs
      corraoi sweep -p ucb,cucb -n 1000000 -T 10000 --backend gpu -o big
      corraoi figure grid/I1/sweep.mcap -o i1.png --log-x
    """
    from corraoi.experiments.grid import build_grid, parse_param_lists, read_experiment, split_list

    out = output
    if resume and out is None:
        raise ConfigError("--resume needs -o DIR (the folder of the sweep to continue)")
    if kept_code:
        if not resume or out is None:
            raise ConfigError("--kept-code: only with --resume -o DIR (the sweep whose copies "
                              "of its plug-ins run)")  # fmt: skip
        from corraoi.experiments.kept_code import use_kept_code

        # while this command runs, before the grid is built: its plug-ins load from the copies
        click.get_current_context().with_resource(use_kept_code(out, pin=True))
    spec: dict[str, Any] = read_experiment(experiment) if experiment is not None else {}
    given_params = parse_param_lists(param)
    for key, value in (("c", c), ("beta", beta)):
        if value is not None:
            given_params[key] = [value]
    cli = {
        "instances": split_list(instance) or None,
        "policies": list(policy) or None,
        "horizons": _horizons(horizon) or None,
        "runs": runs,
        "seed": seed if seed != 0 or "seed" not in spec else None,
        "chunk": chunk,
        "checkpoints": checkpoints,
        "channel": channel,
        "baseline": baseline,
        "backend": backend,
    }
    spec.update({k: v for k, v in cli.items() if v is not None})
    spec.setdefault("instances", ["I1"])
    spec.setdefault("policies", ["all"])
    spec.setdefault("horizons", [10_000])
    spec.setdefault("runs", 200)
    spec["params"] = {**spec.get("params", {}), **given_params}
    limits.check_seed(spec.get("seed", 0), runs=int(spec["runs"]), name="--seed")
    from corraoi.face.resolve import TRACE_READERS

    try:
        grid = build_grid(**spec, warn=warn, trace_readers=TRACE_READERS)
    except CorraoiError as exc:
        if experiment is None:
            raise
        raise type(exc)(f"{experiment}: {exc}") from None
    grid = settle_backend(grid)
    from corraoi.face.sweeps import check_grid

    size = check_grid(grid, out, allow_huge=allow_huge)
    run_slots = sum(int(c.horizon) for c in grid.cells) * int(grid.runs)
    if run_slots >= SAY_SIZE_FROM:
        click.echo(f"corraoi: sweep of {size}; the progress bar shows the time left", err=True)
    for note in _notes(grid):
        warn(note)
    outcome = run_grid(grid, out=out, scheduler=scheduler, resume=resume, force=force,
                   workers=workers, label="sweep")  # fmt: skip
    if as_json:
        if len(outcome.summaries) == 1:
            click.echo(json.dumps(outcome.summaries[0], indent=2))
        else:
            click.echo(json.dumps({"sweeps": outcome.summaries}, indent=2))
    else:
        for i, summary in enumerate(outcome.summaries):
            if i:
                click.echo("")
            print_table(summary, out)
    if out is not None:
        click.echo(wrote_line(out, outcome), err=as_json)
    wall = max((s["wall_s"] for s in outcome.summaries), default=0.0)
    click.echo(f"total wall time {wall:.2f} s", err=True)



def wrote_line(out: Path, outcome: Any) -> str:
    """What a sweep into ``out`` wrote, by name: ``wrote sw/: manifest.json, ...`` and, for a
    grid of several groups, their folders with the files each holds; then the chunks run."""
    from corraoi.experiments.folder import GROUP_FILES

    def n(count: int, what: str) -> str:
        return f"{count} {what}{'' if count == 1 else 's'}"

    done = n(outcome.chunks_run, "chunk") + " run"
    if outcome.chunks_skipped:
        done += f", {outcome.chunks_skipped} already done"
    names = [f for f in ("manifest.json", "results.parquet", "plugins") if (out / f).exists()]
    folders = [p for p in outcome.folders if p != out]
    group = outcome.folders[0] if outcome.folders else out
    files = [f for f in GROUP_FILES if (group / f).exists()]
    if folders:
        names += [f"{p.relative_to(out)}/" for p in folders]
        return (f"wrote {out}/: {', '.join(names)}, each group folder with "
                f"{', '.join(files)} ({done})")  # fmt: skip
    return f"wrote {out}/: {', '.join(names + files)} ({done})"


def _horizons(values: tuple[str, ...]) -> list[int]:
    from corraoi.experiments.grid import split_list

    out = []
    for item in split_list(values):
        try:
            h = int(item)
        except ValueError:
            raise click.BadParameter(f"{item!r} is not a valid integer",
                                     param_hint="'--horizon' / '-T'") from None  # fmt: skip
        if not 1 <= h <= limits.MAX_HORIZON:
            raise click.BadParameter(f"{h} is not in the range 1<=x<={limits.MAX_HORIZON}",
                                     param_hint="'--horizon' / '-T'")  # fmt: skip
        out.append(h)
    return out


def _notes(grid: Any) -> list[str]:
    from corraoi.experiments.summary import instance_notes

    seen: dict[str, list[str]] = {}
    for cell in grid.cells:
        if cell.instance.name not in seen:
            seen[cell.instance.name] = instance_notes(cell.instance)
    return [f"{name}: {n}" if len(seen) > 1 else n for name, notes in seen.items() for n in notes]


__all__ = [
    "SAY_SIZE_FROM",
    "SWEEP_FILES",
    "sweep",
]
