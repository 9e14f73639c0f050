"""``corraoi sweep``: Monte Carlo sweeps, optionally streamed to a directory of logs and figures.

recorder and viewer are imported inside the command (only with ``-o``).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import click

from ..errors import ConfigError
from ..text import safe_text
from .common import (
    CHECKPOINTS,
    RUNS,
    WORKERS,
    handle_errors,
    horizon_option,
    instance_option,
    output_option,
    param_options,
    policy_option,
    say,
    seed_option,
    warn,
)

#: What ``sweep -o DIR`` writes; a DIR holding any of them is refused without --force.
SWEEP_FILES = ("sweep.mcap", "sweep.rrd", "summary.json", "summary.md", "figure.png")
#: Suffix of a file that is being written (recorder.paths.PARTIAL_SUFFIX).
PARTIAL = ".partial"


def _sweep_files(out: Path) -> list[str]:
    """The files of a sweep (finished or not) that ``out`` holds."""
    names = [*SWEEP_FILES, *(f + PARTIAL for f in SWEEP_FILES)]
    return [f for f in names if (out / f).exists()]


def check_out_dir(out: Path, *, force: bool) -> None:
    """Refuse a file, an unwritable directory, or one that already holds a sweep."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: exists and is not a directory (expected a directory for -o)")
    if out.is_dir():
        present = _sweep_files(out)
        from recorder.paths import lock_holder

        for name in present:  # --force or not: never touch what another sweep is writing
            holder = lock_holder(out / name)
            if holder is not None:
                who = f"process {holder}" if holder else "another process"
                raise ConfigError(
                    f"{out / name}: is being written by {who} right now; not touched (wait "
                    "for it, stop it, or give another output folder)"
                )
        if present and not force:
            raise ConfigError(
                f"{out}: already holds a sweep ({', '.join(present)}); use --force to overwrite"
            )
        if not os.access(out, os.W_OK | os.X_OK):
            raise ConfigError(f"{out}: directory is not writable")
        return
    parent = out.parent if str(out.parent) else Path(".")
    probe = parent
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise ConfigError(f"{out}: cannot create the directory ({probe} is not writable)")


def _clear_out_dir(out: Path) -> None:
    """Remove an earlier sweep's files (reached only with --force), so that an interrupted
    sweep never leaves the old complete files beside its own unfinished ones."""
    for name in _sweep_files(out):
        (out / name).unlink()


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + PARTIAL)
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


@click.command()
@instance_option
@policy_option(default=("all",))
@click.option("--runs", "-n", type=RUNS, default=200, show_default=True,
              help="Monte Carlo runs per policy (seeds seed .. seed+runs-1, shared by all "
              "policies).")  # fmt: skip
@horizon_option(10_000)
@seed_option
@param_options
@click.option("--workers", "-j", type=WORKERS, default=None,
              help="Threads for the engine [default: every core].")  # fmt: skip
@output_option(metavar="DIR", help="Stream the curves to DIR/sweep.mcap and DIR/sweep.rrd "
               "and write DIR/summary.json, DIR/summary.md and DIR/figure.png.")  # fmt: skip
@click.option("--checkpoints", type=CHECKPOINTS, default=200, show_default=True,
              help="With -o: about this many checkpoint slots per curve.")  # fmt: skip
@click.option("--force", is_flag=True, help="With -o: overwrite a DIR that holds a sweep.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of a table.")
@handle_errors
def sweep(
    instance: str,
    policy: tuple[str, ...],
    runs: int,
    horizon: int,
    seed: int,
    c: float | None,
    beta: float | None,
    workers: int | None,
    output: Path | None,
    checkpoints: int,
    force: bool,
    as_json: bool,
) -> None:
    """Run policies over paired seeds and report the AoI regret at the horizon.

    Per policy: the mean pathwise AoI regret sum_t (aoi_t - oracle_aoi_t) at T with its 95%
    confidence half-width, the paper's estimator sum_t aoi_t - T/mu*, the share of pulls on
    the best arm, the wall time, and the paper's bound where a theorem covers the policy.

    \b
    Examples:
      corraoi sweep --instance I1 --policy all --runs 200 --horizon 10000
      corraoi sweep --instance I2 -o sweeps/I2      # logs, summary and figure
      corraoi figure sweeps/I2/sweep.mcap -o i2.png --log-x
    """
    from .. import limits
    from ..engine import check_instance, set_workers
    from ..instance import load_instance
    from ..policies import make_policies

    out = output
    limits.check_seed(seed, runs=runs, name="--seed")
    inst = load_instance(instance)
    check_instance(inst)
    specs = make_policies(policy, c=c, beta=beta)
    limits.check_sweep_memory(
        runs, inst.K, policies=len(specs), checkpoints=checkpoints if out is not None else 0
    )
    if out is not None:
        check_out_dir(out, force=force)
    used = set_workers(workers)
    try:
        summary = sweep_instance(
            inst, specs, runs=runs, horizon=horizon, seed=seed, workers=used, out=out,
            checkpoints=checkpoints,
        )  # fmt: skip
    except KeyboardInterrupt:
        left = ", ".join(str(out / f) for f in _sweep_files(out)) if out is not None else ""
        where = f"; the unfinished logs: {left}" if left else ""
        click.echo(f"corraoi: interrupted{where}", err=True)
        sys.exit(130)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        print_table(summary)
    if out is not None:
        click.echo(f"wrote {out}/: " + ", ".join(f for f in SWEEP_FILES if (out / f).exists()))
    click.echo(f"total wall time {summary['wall_s']:.2f} s on {used} thread(s)", err=True)


def sweep_instance(
    inst: Any,
    specs: Any,
    *,
    runs: int,
    horizon: int,
    seed: int,
    workers: int,
    out: Path | None,
    checkpoints: int = 200,
    label: str = "sweep",
) -> dict[str, Any]:
    """One instance's sweep with a progress bar; with ``out``, its logs, summary and figure."""
    from ..progress import CompileWatch, Progress
    from ..summary import instance_notes, summary_markdown, sweep_summary
    from ..sweep import default_checkpoints, run_sweep

    for note in instance_notes(inst):
        warn(note)
    start = time.perf_counter()
    watch = CompileWatch()
    with Progress(len(specs) * horizon, label) as bar:

        def on_slots(n: int) -> None:
            watch.first_block()
            bar.update(n)

        if out is None:
            results = run_sweep(
                inst, specs, runs=runs, horizon=horizon, seed=seed, on_slots=on_slots
            )
        else:
            stops = default_checkpoints(horizon, checkpoints)
            results = _sweep_to_dir(
                out, inst, specs, runs=runs, horizon=horizon, seed=seed, stops=stops,
                on_slots=on_slots,
            )  # fmt: skip
    summary = sweep_summary(inst, results, runs=runs, horizon=horizon, seed=seed, workers=workers)
    watch.first_block()
    # the speed figure leaves out the one-off kernel compilation (said on stderr)
    summary["wall_s"] = round(time.perf_counter() - start - watch.seconds, 4)
    summary["compile_s"] = round(watch.seconds, 4)
    if out is not None:
        _write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
        _write_text(out / "summary.md", summary_markdown(summary))
        _draw(out)
    return summary


def _sweep_to_dir(
    out: Path,
    inst: Any,
    specs: Any,
    *,
    runs: int,
    horizon: int,
    seed: int,
    stops: list[int],
    on_slots: Any,
) -> Any:
    from recorder.sweep_log import SweepMcapSink
    from recorder.sweep_rerun import open_sweep_recording

    from ..sweep import checkpoint_point, run_sweep, sweep_config

    out.mkdir(parents=True, exist_ok=True)
    _clear_out_dir(out)
    config = sweep_config(inst, specs, runs=runs, horizon=horizon, seed=seed, checkpoints=stops)
    with (
        SweepMcapSink(out / "sweep.mcap", config) as mcap_sink,
        open_sweep_recording(out / "sweep.rrd", config) as rerun_sink,
    ):

        def hook(policy: Any, snap: Any) -> None:
            point = checkpoint_point(policy, snap)
            mcap_sink.write(point)
            rerun_sink.write(point)

        return run_sweep(
            inst, specs, runs=runs, horizon=horizon, seed=seed, checkpoints=stops,
            on_checkpoint=hook, on_slots=on_slots,
        )  # fmt: skip


def _draw(out: Path) -> None:
    """figure.png, drawn from the log alone; skipped with a warning without matplotlib."""
    from recorder.sweep_log import read_sweep
    from viewer.figure import FigureUnavailable, draw_figure

    try:
        draw_figure(read_sweep(out / "sweep.mcap"), out / "figure.png")
    except FigureUnavailable as exc:
        warn(f"figure.png not written: {exc}")


def print_table(summary: dict[str, Any]) -> None:
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


#: The paper's simulation settings (section "Simulations"; 200 runs as its published code).
PAPER_INSTANCES = ("I1", "I2")


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
    as_json: bool,
) -> None:
    """Regenerate the paper's simulations: I1 and I2, all twelve policies, 200 runs, T = 10,000.

    Each instance gets the logs, summary and figure of `corraoi sweep -o`; DIR/summary.md
    puts the two ranked tables side by side.

    \b
    Example:
      corraoi reproduce -o paper && open paper/I1/figure.png
    """
    from .. import limits
    from ..engine import set_workers
    from ..instance import load_instance
    from ..policies import make_policies
    from ..summary import summary_markdown

    out = output
    limits.check_seed(seed, runs=runs, name="--seed")
    for name in PAPER_INSTANCES:
        limits.check_sweep_memory(runs, load_instance(name).K, policies=12, checkpoints=200)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: exists and is not a directory (expected a directory for -o)")
    if out.is_dir() and (out / "summary.md").exists() and not force:
        raise ConfigError(f"{out}: already holds a reproduction; use --force to overwrite")
    for name in PAPER_INSTANCES:
        check_out_dir(out / name, force=force)
    used = set_workers(workers)
    specs = make_policies(["all"])
    start = time.perf_counter()
    parts = []
    summaries: dict[str, Any] = {}
    for name in PAPER_INSTANCES:
        summary = sweep_instance(
            load_instance(name), specs, runs=runs, horizon=horizon, seed=seed, workers=used,
            out=out / name, label=f"sweep {name}",
        )  # fmt: skip
        summaries[name] = summary
        if not as_json:
            print_table(summary)
            click.echo("")
        parts.append(summary_markdown(summary).replace("# Sweep:", "## Sweep:", 1))
    head = (
        "# The paper's simulations, regenerated\n\n"
        f"`corraoi reproduce --runs {runs} --horizon {horizon} --seed {seed}`; figures in "
        + ", ".join(f"`{n}/figure.png`" for n in PAPER_INSTANCES)
        + ".\n\n"
    )
    _write_text(
        out / "summary.md",
        head + "\n".join(p.replace("\n## Theory", "\n### Theory") for p in parts),
    )
    if as_json:
        click.echo(json.dumps({"output": str(out), "instances": summaries}, indent=2))
    else:
        click.echo(f"wrote {out}/: " + ", ".join(f"{n}/" for n in PAPER_INSTANCES) + ", summary.md")
    click.echo(f"total wall time {time.perf_counter() - start:.2f} s on {used} thread(s)", err=True)
