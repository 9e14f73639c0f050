"""A sweep's summary as the tables ``corraoi sweep`` and ``corraoi reproduce`` print: the
regret per policy, the paired differences against a baseline, and the runs worth watching.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from corraoi.text import safe_text

from .common import say


def print_table(summary: dict[str, Any], folder: Path | None = None) -> None:
    name = safe_text(summary["instance"]["name"])
    runs, seed = summary["runs"], summary["seed"]
    click.echo(
        f"instance {name}, {runs} runs (seeds {seed}..{seed + runs - 1}), "
        f"horizon {summary['horizon']}, C = {summary['theory']['C']}"
    )
    click.echo(
        f"{'policy':22s} {'regret':>10} {'+-95%':>9} {'estimator':>11} {'best-arm':>9}"
        f" {'wall s':>7}  bound at T"
    )
    click.echo(f"{'':22s} {'':>10} {'':>9} {'':>11} {'share':>9} {'(runs)':>7}")
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
    storms = [(n, c["most-collisions"]) for n, c in notable["cells"].items()
              if isinstance(c.get("most-collisions"), dict)]  # cells of several sources
    if storms:
        name, e = max(storms, key=lambda s: s[1]["collisions"])
        say(f"most collisions: {safe_text(name)}, {e['collisions']} at run {e['run']} "
            f"(seed {e['seed']})")  # fmt: skip
    if folder is not None:
        storm = "|most-collisions" if storms else ""
        say(f"record one slot by slot: corraoi record --from {safe_text(folder)} "
            f"--run worst|median|best|widest-gap{storm}|N [-p POLICY]")  # fmt: skip


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


__all__ = ["print_table"]
