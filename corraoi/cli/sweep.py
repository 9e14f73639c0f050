"""``corraoi sweep`` and ``corraoi reproduce``: grids of Monte Carlo runs (corraoi.experiments),
in this process or on a Dask cluster, optionally into a resumable results folder.

recorder and viewer are imported by the library only with ``-o``; Dask only with --scheduler.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import click

from .. import limits
from ..errors import ConfigError, CorraoiError
from ..text import safe_text
from .common import handle_errors, say, warn
from .options import (
    CHECKPOINTS,
    RUNS,
    WORKERS,
    backend_option,
    channel_option,
    horizon_option,
    output_option,
    policy_option,
    seed_option,
)

#: From this many run-slots (about a minute here) a sweep states its size before it starts.
SAY_SIZE_FROM = 10**9

#: What ``sweep -o DIR`` writes beside the group files (corraoi.experiments).
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
@click.option("--param", "param", multiple=True, metavar="NAME=V[,V...]",
              help="Sweep a policy parameter over values (repeatable): each value goes to every "
              "listed policy that declares NAME ('corraoi policies').")  # fmt: skip
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
    from ..grid import build_grid, parse_param_lists, read_experiment, split_list

    out = output
    if resume and out is None:
        raise ConfigError("--resume needs -o DIR (the folder of the sweep to continue)")
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
    try:
        grid = build_grid(**spec)
    except CorraoiError as exc:
        if experiment is None:
            raise
        raise type(exc)(f"{experiment}: {exc}") from None
    for cell in grid.cells:
        from ..engine import check_instance

        check_instance(cell.instance)
    grid = _settle_backend(grid)
    # the biggest cell's runs x checkpoints are held at once when its results are joined (a
    # GPU sweep keeps every run's final values only)
    per_run = out is not None and grid.backend == "cpu"
    limits.check_sweep_memory(grid.runs, max(c.instance.K for c in grid.cells), policies=1,
                              checkpoints=grid.checkpoints if per_run else 0)  # fmt: skip
    run_slots = sum(int(c.horizon) for c in grid.cells) * int(grid.runs)
    size = limits.check_sweep_size(len(grid.cells), grid.runs, run_slots, allow=allow_huge)
    if run_slots >= SAY_SIZE_FROM:
        click.echo(f"corraoi: sweep of {size}; the progress bar shows the time left", err=True)
    for note in _notes(grid):
        warn(note)
    outcome = _run(grid, out=out, scheduler=scheduler, resume=resume, force=force,
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
        done = f"{outcome.chunks_run} chunk(s) run"
        if outcome.chunks_skipped:
            done += f", {outcome.chunks_skipped} already done"
        click.echo(f"wrote {out}/ ({done}): " + ", ".join(
            str(p.relative_to(out)) + "/" if p != out else "." for p in outcome.folders
        ), err=as_json)  # fmt: skip
    wall = max((s["wall_s"] for s in outcome.summaries), default=0.0)
    click.echo(f"total wall time {wall:.2f} s", err=True)


def _settle_backend(grid: Any) -> Any:
    """The grid with ``auto`` resolved (a notice when it falls back to the CPU) and ``gpu``
    checked; says which device runs it."""
    if grid.backend == "cpu":
        return grid
    from ..gpu import choose_backend, get_device

    grid = choose_backend(grid, warn=warn)
    if grid.backend == "gpu":
        click.echo(f"backend gpu: {get_device().name}", err=True)
    return grid


def _horizons(values: tuple[str, ...]) -> list[int]:
    from ..grid import split_list

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
    from ..summary import instance_notes

    seen: dict[str, list[str]] = {}
    for cell in grid.cells:
        if cell.instance.name not in seen:
            seen[cell.instance.name] = instance_notes(cell.instance)
    return [f"{name}: {n}" if len(seen) > 1 else n for name, notes in seen.items() for n in notes]


def _run(
    grid: Any,
    *,
    out: Path | None,
    scheduler: str | None,
    resume: bool,
    force: bool,
    workers: int | None,
    label: str,
) -> Any:
    """Run the grid with a progress bar (slots in this process, chunks on a cluster)."""
    from contextlib import ExitStack

    from ..experiments import GPU_NOT_ON_CLUSTER
    from ..experiments import sweep as run_sweep
    from ..progress import Progress

    if scheduler is not None and grid.backend == "gpu":  # before a cluster is started
        raise ConfigError(GPU_NOT_ON_CLUSTER)
    with ExitStack() as stack:
        client = None
        if scheduler is not None:
            from ..cluster import connect

            client = stack.enter_context(connect(scheduler))
        if client is None:
            total = sum(c.horizon for c in grid.cells) * grid.runs // grid.chunk_runs
            bar = stack.enter_context(Progress(max(total, 1), label))
            on_slots = bar.update
            on_chunk = None
        else:
            chunks = sum(-(-grid.runs // grid.chunk_runs) for _ in grid.cells)
            bar = stack.enter_context(Progress(chunks, f"{label} (chunks)"))

            def on_chunk(done: int, total: int) -> None:
                bar.update(1, note=f"{done}/{total} chunks")

            on_slots = None
        try:
            return run_sweep(grid, out=out, client=client, resume=resume, force=force,
                             workers=workers, on_chunk=on_chunk, on_slots=on_slots,
                             warn=warn)  # fmt: skip
        except KeyboardInterrupt:
            where = f"; finished chunks are saved in {out}: --resume continues" if out else ""
            click.echo(f"corraoi: interrupted{where}", err=True)
            sys.exit(130)


def print_table(summary: dict[str, Any], folder: Path | None = None) -> None:
    name = safe_text(summary["instance"]["name"])
    runs, seed = summary["runs"], summary["seed"]
    click.echo(
        f"instance {name}, {runs} runs (seeds {seed}..{seed + runs - 1}), "
        f"horizon {summary['horizon']}, C = {summary['theory']['C']}"
    )
    click.echo(
        f"{'policy':22s} {'regret':>10} {'+-95%':>9} {'estimator':>11} {'best arm':>9}"
        f" {'wall s':>7}  bound at T"
    )
    for pname, s in summary["policies"].items():
        ci = s["regret_ci95"]
        ci_text = f"{ci:9.1f}" if ci is not None else f"{'n/a':>9}"
        bound = s.get("bound")
        btext = ""
        if bound is not None:
            btext = f"  {bound['value']:.4g}" if bound["value"] is not None else "  n/a"
        say(
            f"{safe_text(pname):22s} {s['regret_mean']:10.1f} {ci_text} "
            f"{s['estimator_mean']:11.1f} "
            f"{s['best_arm_share']:9.3f} {s['wall_s']:7.3f}{btext}"
        )
    if summary.get("baseline") is not None:
        _print_paired(summary)
    _print_notable(summary, folder)


def _print_notable(summary: dict[str, Any], folder: Path | None) -> None:
    """The runs worth watching: per policy its worst, median and best run, and the widest
    paired gap; with a folder, the command that records one slot by slot."""
    notable = summary.get("notable")
    if not notable:
        return
    click.echo("runs worth watching: final regret (run index)")
    click.echo(f"{'policy':22s} {'worst':>16} {'median':>16} {'best':>16}")
    for pname, c in notable["cells"].items():
        cols = "".join(f" {c[k]['regret']:g} (run {c[k]['run']})".rjust(17)
                       for k in ("worst", "median", "best"))  # fmt: skip
        say(f"{safe_text(pname):22s}{cols}")
    if notable["pairs"]:
        g = notable["pairs"][0]
        a, b = (safe_text(n) for n in g["policies"])
        say(f"widest paired gap: {a} - {b} = {g['difference']:+g} at run {g['run']} "
            f"(seed {g['seed']})")  # fmt: skip
    if folder is not None:
        say(f"record one slot by slot: corraoi record --from {safe_text(folder)} "
            "--run worst|median|best|widest-gap|N [-p POLICY]")  # fmt: skip


def _print_paired(summary: dict[str, Any]) -> None:
    base = summary["baseline"]
    click.echo(f"paired against {base}: per-run regret(policy) - regret({base}), same seeds")
    click.echo(f"{'policy':22s} {'diff':>10} {'+-paired':>9} {'+-unpaired':>11}")

    def ci(v: float | None, width: int) -> str:
        return f"{v:{width}.1f}" if v is not None else f"{'n/a':>{width}}"

    for pname, s in summary["policies"].items():
        if "paired_diff_mean" in s:
            click.echo(
                f"{pname:22s} {s['paired_diff_mean']:10.1f} {ci(s['paired_diff_ci95'], 9)} "
                f"{ci(s['unpaired_diff_ci95'], 11)}"
            )




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
    from ..experiments import PAPER_INSTANCES, paper_grid, write_text
    from ..summary import summary_markdown

    out = output
    limits.check_seed(seed, runs=runs, name="--seed")
    grid = paper_grid(runs=runs, horizon=horizon, seed=seed, backend=backend or "cpu")
    grid = _settle_backend(grid)
    limits.check_sweep_memory(runs, 4, policies=1,
                              checkpoints=grid.checkpoints if grid.backend == "cpu" else 0)
    start = time.perf_counter()
    outcome = _run(grid, out=out, scheduler=None, resume=False, force=force, workers=workers,
                   label="reproduce")  # fmt: skip
    parts = []
    summaries: dict[str, Any] = {}
    for summary in outcome.summaries:
        summaries[summary["instance"]["name"]] = summary
        if not as_json:
            print_table(summary, output)
            click.echo("")
        parts.append(summary_markdown(summary).replace("# Sweep:", "## Sweep:", 1))
    head = (
        "# The paper's simulations, regenerated\n\n"
        f"`corraoi reproduce --runs {runs} --horizon {horizon} --seed {seed}`; figures in "
        + ", ".join(f"`{n}/figure.png`" for n in PAPER_INSTANCES)
        + ".\n\n"
    )
    write_text(
        out / "summary.md",
        head + "\n".join(p.replace("\n## Theory", "\n### Theory") for p in parts),
    )
    if as_json:
        click.echo(json.dumps({"output": str(out), "instances": summaries}, indent=2))
    else:
        click.echo(f"wrote {safe_text(out)}/: " + ", ".join(f"{n}/" for n in PAPER_INSTANCES)
                   + ", summary.md")  # fmt: skip
    click.echo(f"total wall time {time.perf_counter() - start:.2f} s", err=True)
