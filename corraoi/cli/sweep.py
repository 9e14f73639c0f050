"""``corraoi sweep``: grids of Monte Carlo runs (corraoi.experiments.sweeps), in this process or on
a
Dask cluster, optionally into a resumable results folder.

The grid is built, checked and run by the face in one call
(:func:`corraoi.face.sweeps.sweep_from_options`), the printed tables are
:mod:`corraoi.cli.sweep_table`'s; ``corraoi reproduce`` (:mod:`corraoi.cli.reproduce`) and
``print_table`` stay importable from here.

recorder and viewer are imported by the library only with ``-o``; Dask only with --scheduler.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from corraoi import limits
from corraoi.errors import ConfigError
from corraoi.text import split_list

from .common import handle_errors, keep_pandas_out, warn
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
from .reading import progress
from .sweep_run import interrupted_or
from .sweep_table import print_table

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
@click.option("--sources", "sources", multiple=True, metavar="M[,M...]",
              help="Sources sharing the channels, each value a cell (1 to the number of arms; "
              "several need a multi-source policy such as rhorand-ucb, mctopm-cucb, "
              "centralized-ts; docs/model.md) [default: 1].")  # fmt: skip
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
    sources: tuple[str, ...],
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
      corraoi sweep -p rhorand-ucb,mctopm-ucb --sources 1,2,3,4 -n 50 -o many
      corraoi figure grid/I1/sweep.mcap -o i1.png --log-x
    """
    from corraoi.face.sweeps import sweep_from_options

    out = output
    if resume and out is None:
        raise ConfigError("--resume needs -o DIR (the folder of the sweep to continue)")
    if kept_code and (not resume or out is None):
        raise ConfigError("--kept-code: only with --resume -o DIR (the sweep whose copies "
                          "of its plug-ins run)")  # fmt: skip
    if instance and not split_list(instance):  # -i '' (an empty shell variable)
        raise click.BadParameter("no instance given (expected a built-in, a file path or a "
                                 "comma list)", param_hint="'--instance' / '-i'")  # fmt: skip
    options = {
        "instances": split_list(instance) or None,
        "policies": list(policy) or None,
        "horizons": _horizons(horizon) or None,
        "runs": runs,
        "seed": seed,
        "chunk": chunk,
        "checkpoints": checkpoints,
        "channel": channel,
        "baseline": baseline,
        "backend": backend,
        "sources": list(sources) or None,  # the words: checked by the face
    }
    done = sweep_from_options(
        experiment, options, params=param, scalars={"c": c, "beta": beta}, out=out,
        scheduler=scheduler, resume=resume, force=force, workers=workers, allow_huge=allow_huge,
        kept=kept_code, hold=click.get_current_context().with_resource, warn=warn,
        say=lambda line: click.echo(line, err=True), progress=progress,
        before_folder=keep_pandas_out, label="sweep",
    )  # fmt: skip
    outcome = interrupted_or(done).outcome
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
    if done.wrote is not None:
        click.echo(done.wrote, err=as_json)
    wall = max((s["wall_s"] for s in outcome.summaries), default=0.0)
    click.echo(f"total wall time {wall:.2f} s", err=True)



def _horizons(values: tuple[str, ...]) -> list[int]:
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
    if values and not out:  # -T '' (an empty shell variable): never the default horizon
        raise click.BadParameter("no horizon given (expected slots, or a comma list)",
                                 param_hint="'--horizon' / '-T'")  # fmt: skip
    return out


__all__ = [
    "SWEEP_FILES",
    "sweep",
]
