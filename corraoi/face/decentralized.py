"""``corraoi reproduce decentralized``: the files beside its sweep folder's own -- the figure of
the regret at T against the number of sources M, a panel per rule and a line per base policy
(``regret-vs-sources.png``),
and ``decentralized.md``: the table of regret against M and the ordering measured.

The experiment is ours (docs/decentralized.md): the body of Prasad, Jain and Moharir's paper
(arXiv 2009.12961) could not be read, so neither its instances nor its ordering are quoted.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from corraoi.experiments.folder import write_text
from corraoi.experiments.grid import Grid
from corraoi.experiments.summary import summary_markdown
from corraoi.experiments.sweeps import (
    DECENTRALIZED_BASES,
    DECENTRALIZED_RULES,
    DECENTRALIZED_RUNS,
    regret_by_sources,
)
from corraoi.files.partial import PartialFile

#: The runs per cell unless told (a minute or two on two cores, the kernels compiled).
RUNS = DECENTRALIZED_RUNS
#: The figure's file name in the output folder.
FIGURE = "regret-vs-sources.png"
#: The table of regret against M and the orderings (the sweep keeps its own summary.md).
SUMMARY = "decentralized.md"


def ordering(table: dict[str, dict[int, Any]], sources: int) -> list[str]:
    """The policies by mean regret at T with ``sources`` sources, lowest first."""
    return sorted((p for p in table if sources in table[p]), key=lambda p: table[p][sources][0])


def write_decentralized(out: Path, summary: dict[str, Any], grid: Grid, *, runs: int,
                        horizon: int, seed: int,
                        warn: Callable[[str], None] | None = None) -> list[str]:  # fmt: skip
    """``out/regret-vs-sources.png`` and ``out/decentralized.md`` of the sweep ``grid`` (one group,
    ``summary``); returns the files written (the figure is left out, said through ``warn``,
    without matplotlib)."""
    table = regret_by_sources(summary, grid)
    counts = sorted({c.sources for c in grid.cells})
    written = []
    try:
        draw_regret_vs_sources(table, out / FIGURE, title=(
            f"{summary['instance']['name']}: AoI regret at T = {horizon} summed over the sources, "
            f"{runs} runs (mean, 95% CI)"))  # fmt: skip
        written.append(FIGURE)
    except ImportError:
        if warn is not None:
            warn(f"{out / FIGURE} not written: install the plot extra, pip install "
                 '"corraoi[plot]"')  # fmt: skip
    head = [
        "# Many sources on one set of channels (our experiment)",
        "",
        f"`corraoi reproduce decentralized --runs {runs} --horizon {horizon} --seed {seed}`. "
        "After Prasad, Jain and Moharir, \"Decentralized Age-of-Information Bandits\" (arXiv "
        "2009.12961), whose body could not be read: the instance, the rules and the horizon "
        "are our choices and the ordering below is what corraoi measures, not the paper's "
        "(docs/decentralized.md).",
        "",
        f"Mean pathwise AoI regret at T summed over the M sources (95% CI); figure: `{FIGURE}`.",
        "",
        "| policy | " + " | ".join(f"M = {m}" for m in counts) + " |",
        "|---|" + "---:|" * len(counts),
    ]
    for name in table:
        cols = []
        for m in counts:
            mean, half = table[name].get(m, (None, None))
            cols.append("-" if mean is None else
                        f"{mean:.1f} +-{half:.1f}" if half is not None else f"{mean:.1f}")
        head.append(f"| {name} | " + " | ".join(cols) + " |")
    head += ["", "Ordering measured (lowest regret first):", ""]
    head += [f"- M = {m}: " + " < ".join(ordering(table, m)) for m in counts]
    body = summary_markdown(summary).replace("# Sweep:", "## Sweep:", 1)
    write_text(out / SUMMARY, "\n".join(head) + "\n\n"
               + body.replace("\n## Theory", "\n### Theory"))  # fmt: skip
    return [*written, SUMMARY]


def draw_regret_vs_sources(table: dict[str, dict[int, Any]], out: Path, *, title: str) -> None:
    """The figure: regret at T against M, a panel per rule (each with its own scale: a
    decentralized rule's worst case dwarfs the others), a line per base policy in the
    same colour in every panel, 95% error bars. ImportError without matplotlib."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    rules = [r for r in DECENTRALIZED_RULES if any(n.startswith(f"{r}-") for n in table)]
    fig = Figure(figsize=(4 * len(rules), 4.2), dpi=150, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(rules), squeeze=False)[0]
    colours = {b: f"C{i}" for i, b in enumerate(DECENTRALIZED_BASES)}
    counts = sorted({m for p in table.values() for m in p})
    for ax, rule in zip(axes, rules, strict=True):
        for name, points in table.items():
            base = name.removeprefix(f"{rule}-")
            if base == name:
                continue
            ms = sorted(points)
            ax.errorbar(ms, [points[m][0] for m in ms], yerr=[points[m][1] or 0.0 for m in ms],
                        label=base, color=colours.get(base), marker="o", markersize=3,
                        capsize=2)  # fmt: skip
        ax.axhline(0, color="0.6", linewidth=0.6)
        ax.set_title(rule, fontsize=9)
        ax.set_xlabel("sources M")
        ax.set_xticks(counts)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("AoI regret at T (slots)")
    fig.suptitle(title, fontsize=9)
    with PartialFile(out, overwrite=True, what="figure") as target:
        fig.savefig(target.file, format="png")


__all__ = ["FIGURE", "RUNS", "SUMMARY", "draw_regret_vs_sources", "ordering", "write_decentralized"]
