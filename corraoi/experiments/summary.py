"""The summary of a sweep: JSON (``--json``, ``summary.json``) and Markdown (``summary.md``).

Beside the measured figures it states the theory of the instance (k*, competitive arms,
C) and the values at T of the paper's upper bounds (Theorems 2 and 3) for the policies
they are about.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from corraoi.model.bounds import DEFAULT_BOUND_BETA, Bound, cts_bound, cucb_bound
from corraoi.model.instance import Instance
from corraoi.model.theory import analyse
from corraoi.policies.spec import PolicySpec

from .montecarlo import PolicyResult

if TYPE_CHECKING:
    from .folder import CellRuns
    from .grid import Grid


def policy_bound(instance: Instance, policy: PolicySpec, horizon: int) -> Bound | None:
    """The theorem about ``policy`` (plain CUCB or CTS), or None for the others.

    Theorem 3 is stated for CTS with Gaussian priors and beta > 1: cts-gauss gets it with
    its own beta (n/a at beta <= 1); Beta-prior cts gets an n/a that says so.
    """
    theorem = policy.resolve().theorem if policy.builtin else None
    if theorem == "cucb":
        return cucb_bound(instance, horizon)
    if theorem == "cts" and "beta" in policy.params:
        return cts_bound(instance, horizon, policy.params["beta"])
    if theorem == "cts":
        return Bound(
            "Theorem 3 (CTS)", horizon, None, "n/a", None,
            "stated for Gaussian priors (cts-gauss with beta > 1), not for Beta priors",
        )  # fmt: skip
    return None


def _theory_cts_bound(instance: Instance, horizon: int, results: Sequence[PolicyResult]) -> Bound:
    """Theorem 3 at the beta a swept Gaussian CTS runs with (the first above 1), else at
    the default beta when no CTS ran, else n/a saying that the swept betas are <= 1."""
    betas = [
        r.policy.params["beta"]
        for r in results
        if "beta" in r.policy.params and policy_bound(instance, r.policy, horizon) is not None
    ]
    usable = [b for b in betas if b > 1.0]
    if usable:
        return cts_bound(instance, horizon, usable[0])
    if betas:
        shown = ", ".join(f"{b:g}" for b in dict.fromkeys(betas))
        return Bound(
            "Theorem 3 (CTS)", horizon, None, "n/a", None,
            f"stated for beta > 1; the swept cts-gauss runs with beta = {shown}",
        )  # fmt: skip
    return cts_bound(instance, horizon, DEFAULT_BOUND_BETA)


def bound_text(bound: dict[str, Any], digits: int = 4) -> str:
    """A bound for tables: ``1234 (Theorem 2 (CUCB); log)`` or ``n/a: <why>``."""
    if bound.get("value") is None:
        return f"n/a: {bound.get('note', '')}".rstrip(": ")
    return f"{bound['value']:.{digits}g} ({bound['theorem']}; {bound['regime']})"


def instance_notes(instance: Instance) -> list[str]:
    """Statements about legitimate but special instances (ties, identical arms)."""
    th = analyse(instance)
    notes = []
    if len(th.best_tied) == instance.K:
        notes.append(
            "every arm has the same mean: every policy plays an optimal arm, so the expected "
            "regret is 0 (pathwise regret is exactly 0 when the arms are identical)"
        )
    elif len(th.best_tied) > 1:
        arms = ", ".join(str(a + 1) for a in th.best_tied)
        notes.append(
            f"arms {arms} tie for the best mean; regret is measured against arm "
            f"{th.best_arm + 1} (the lowest index); the bounds do not apply"
        )
    return notes


def sweep_summary(
    instance: Instance,
    results: Sequence[PolicyResult],
    *,
    runs: int,
    horizon: int,
    seed: int,
    workers: int,
) -> dict[str, Any]:
    """The JSON object of ``corraoi sweep --json`` and ``summary.json``."""
    th = analyse(instance)
    policies: dict[str, Any] = {}
    for r in results:
        entry = {**r.summary(), "params": r.policy.params}
        b = policy_bound(instance, r.policy, horizon)
        if b is not None:
            entry["bound"] = b.to_dict()
        policies[r.name] = entry
    ranking = sorted(policies, key=lambda n: policies[n]["regret_mean"])
    for rank, name in enumerate(ranking, start=1):
        policies[name]["rank"] = rank
    return {
        "instance": instance.to_dict(),
        "theory": {
            "mu": [float(v) for v in th.mu],
            "best_arm": th.best_arm + 1,
            "competitive": [a + 1 for a in th.competitive],
            "strictly_competitive": [a + 1 for a in th.strictly_competitive],
            "C": th.C,
            "bounds": {
                "cucb": cucb_bound(instance, horizon).to_dict(),
                "cts": _theory_cts_bound(instance, horizon, results).to_dict(),
            },
            "notes": instance_notes(instance),
        },
        "runs": runs,
        "horizon": horizon,
        "seed": seed,
        "seeds": [seed, seed + runs - 1],
        "workers": workers,
        "ranking": ranking,
        "policies": policies,
    }


def _ci(v: float | None) -> str:
    return f"{v:.1f}" if v is not None else "n/a"


def summary_markdown(summary: dict[str, Any]) -> str:
    """``summary.md``: final regret +- 95% CI per policy, ranked, with the theory beside it."""
    inst = summary["instance"]
    th = summary["theory"]
    lines = [
        f"# Sweep: instance {inst['name']}",
        "",
        f"{summary['runs']} paired runs (seeds {summary['seeds'][0]}..{summary['seeds'][1]}), "
        f"horizon T = {summary['horizon']}. Regret is the pathwise AoI regret "
        "sum_t (aoi_t - oracle_aoi_t) at T; the estimator is the paper's sum_t aoi_t - T/mu*. "
        "Intervals are 95% (Student t).",
        "",
        "| rank | policy | regret at T | 95% CI | estimator | best-arm share | bound at T |",
        "|---:|---|---:|---:|---:|---:|---|",
    ]
    for name in summary["ranking"]:
        p = summary["policies"][name]
        bound = p.get("bound")
        btext = "-"
        if bound is not None:
            btext = bound_text(bound)
        lines.append(
            f"| {p['rank']} | {name} | {p['regret_mean']:.1f} | +-{_ci(p['regret_ci95'])} "
            f"| {p['estimator_mean']:.1f} | {p['best_arm_share']:.3f} | {btext} |"
        )
    comp = ", ".join(str(a) for a in th["competitive"]) or "none"
    mu = " ".join(f"{v:g}" for v in th["mu"])
    lines += [
        "",
        "## Theory",
        "",
        f"mu = {mu}; best arm k* = {th['best_arm']}; competitive sub-optimal arms: {comp}; "
        f"C = {th['C']}.",
        "",
    ]
    for b in th["bounds"].values():
        if b["value"] is None:
            lines.append(f"- {b['theorem']} at T = {b['horizon']}: n/a ({b['note']})")
        else:
            lines.append(f"- {b['theorem']}: {b['value']:.6g} at T = {b['horizon']} ({b['note']})")
    for note in th["notes"]:
        lines.append(f"- Note: {note}")
    lines += notable_markdown(summary.get("notable"))
    return "\n".join(lines) + "\n"


def notable_markdown(notable: dict[str, Any] | None, pairs: int = 5) -> list[str]:
    """The "runs worth watching" section of ``summary.md`` (none for older summaries)."""
    if not notable:
        return []
    lines = [
        "",
        "## Runs worth watching",
        "",
        "Final regret (run index, seed); `corraoi record --from <this folder> --run worst` "
        "records one slot by slot.",
        "",
        "| policy | worst | median | best |",
        "|---|---:|---:|---:|",
    ]
    for name, c in notable["cells"].items():
        cols = [f"{c[k]['regret']:g} (run {c[k]['run']}, seed {c[k]['seed']})"
                for k in ("worst", "median", "best")]  # fmt: skip
        lines.append(f"| {name} | " + " | ".join(cols) + " |")
    storms = [(n, c["most-collisions"]) for n, c in notable["cells"].items()
              if isinstance(c.get("most-collisions"), dict)]
    if storms:
        lines += ["", "Most collisions (several sources; `--run most-collisions`):", ""]
        lines += [f"- {n}: {e['collisions']} collisions, regret {e['regret']:g} (run {e['run']}, "
                  f"seed {e['seed']})" for n, e in storms]  # fmt: skip
    if notable["pairs"]:
        lines += ["", "Widest paired gaps, regret(a) - regret(b) on one run (same hidden "
                  "path):", ""]  # fmt: skip
        for g in notable["pairs"][:pairs]:
            a, b = g["policies"]
            lines.append(f"- {a} - {b}: {g['difference']:+g} at run {g['run']} (seed {g['seed']})")
    return lines


# ------------------------------------------------------------- a sweep's (instance, horizon) group


def group_summary(
    grid: Grid, cells: Sequence[CellRuns], *, workers: int, wall_s: float
) -> dict[str, Any]:
    """The summary (``--json``, summary.json) of one (instance, horizon) group."""
    inst, horizon = cells[0].cell.instance, cells[0].cell.horizon
    best = analyse(inst).best_arm
    results = [c.result(best) for c in cells]
    summary = sweep_summary(inst, results, runs=grid.runs, horizon=horizon, seed=grid.seed,
                            workers=workers)  # fmt: skip
    summary["wall_s"] = round(wall_s, 4)
    summary["notable"] = group_notable(grid, cells)
    if grid.backend != "cpu":
        summary["backend"] = grid.backend
    if grid.baseline is not None:
        from .paired import paired_against

        base = [c for c in cells if c.cell.policy.name == grid.baseline]
        if base:
            summary["baseline"] = base[0].label
            for name, entry in paired_against(results, base[0].label).items():
                summary["policies"][name].update(entry)
            for c in cells:
                curve = c.paired_curve(base[0]) if c is not base[0] else None
                if curve is not None:
                    summary["policies"][c.label]["paired_diff_curve"] = curve
    return summary


def group_notable(grid: Grid, cells: Sequence[CellRuns]) -> dict[str, Any]:
    """The group's notable runs (:mod:`corraoi.experiments.notable`) from the per-run finals."""
    from .notable import notable_runs

    base = [c.label for c in cells if c.cell.policy.name == grid.baseline]
    return notable_runs([c.label for c in cells], [c.regret[:, -1] for c in cells],
                        [c.cell.channel.to_dict() for c in cells], seed=grid.seed,
                        baseline=base[0] if base else None,
                        collisions=[c.collisions[:, -1] if c.collisions is not None else None
                                    for c in cells])  # fmt: skip
