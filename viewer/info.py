"""``corraoi info``: what a log holds -- configuration, slot count, how it ended, figures --
and what a sweep folder holds, with its runs worth watching and the command that records each."""

from __future__ import annotations

import hashlib
import json
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from corraoi.engine.summary import RunSummary, summarize_blocks
from corraoi.experiments.notable import well_formed
from corraoi.limits import MAX_HORIZON
from corraoi.provenance import Provenance, short
from corraoi.text import safe_text

from .runs import LogLike, as_log


def log_info(log: LogLike) -> dict[str, Any]:
    """Everything ``corraoi info --json`` prints, as one JSON-ready dict (arms from 1)."""
    run = as_log(log)
    cfg = run.config
    summary = summarize_blocks(cfg, run.blocks(4096))
    theory = cfg.theory  # None for a run without an instance
    return {
        "path": str(run.path),
        "label": cfg.label,
        "format_version": run.format_version,
        "library": run.library,
        "status": run.status,
        "cut_short": run.cut_short,
        "finished": run.finished,
        "slots": run.n_slots,
        "horizon": cfg.horizon,
        "last_slot": run.n_slots,
        "chunks": run.n_chunks,
        "description": run.summary,
        "config": cfg.to_dict(),
        "provenance": provenance_info(run.provenance, run.attachments),
        "theory": None if theory is None else {
            "mu": [float(v) for v in theory.mu],
            "best_arm": theory.best_arm + 1,
            "competitive": [a + 1 for a in theory.competitive],
            "C": theory.C,
        },
        "absent": list(run.absent),
        "summary": summary.to_dict(),
    }


def info_text(info: dict[str, Any]) -> str:
    """The table ``corraoi info`` prints from :func:`log_info`'s dict."""
    cfg = info["config"]
    inst, pol, th = cfg.get("instance"), cfg["policy"], info["theory"]
    s = info["summary"]
    params = ", ".join(f"{k}={v:g}" for k, v in sorted(pol["params"].items()))
    if inst is None or th is None:  # a loop logged without an instance
        model = [f"  {'instance':<22} none: K={cfg['arms']} arms (p and Y unknown)",
                 f"  {'theory':<22} - (no instance)"]  # fmt: skip
    else:
        p = " ".join(f"{v:g}" for v in inst["p"])
        mu = " ".join(f"{v:g}" for v in th["mu"])
        comp = ", ".join(str(a) for a in th["competitive"]) or "none"
        model = [
            f"  {'instance':<22} {inst['name']}: K={len(inst['Y'])} arms, {len(inst['p'])} "
            f"states, p = [{p}]",
            f"  {'theory':<22} mu = [{mu}], best arm {th['best_arm']}, competitive arms: "
            f"{comp} (C = {th['C']})",
        ]
    lines = [
        f"{info['path']}: corraoi slot log, format version {info['format_version']}"
        + (f" (written by {info['library']})" if info["library"] else ""),
        f"  {'status':<22} {info['description']}",
        f"  {'run':<22} {info['label']}",
        *([f"  {'streams':<22} {cfg['streams']}: a GPU sweep's run, its slots captured from the "
           "GPU kernel"] if cfg.get("streams", "cpu") != "cpu" else []),
        *model,
        f"  {'policy':<22} {pol['name']}" + (f" ({params})" if params else ""),
    ]
    plugin = pol.get("plugin")
    if isinstance(plugin, dict):
        lines.append(
            f"  {'plug-in':<22} {plugin.get('qualname', '?')} ({plugin.get('tier', '?')}, "
            f"version {plugin.get('version') or '?'})"
        )
    channel = cfg.get("channel") or {"kind": "iid"}
    chan = str(channel.get("kind", "iid"))
    if chan == "trace":
        chan += f" of {channel.get('length', '?')} slots from {channel.get('source', '?')}"
    elif chan == "markov":
        chan += " (the instance's transition matrix)"
    if inst is None:
        chan = "none (no instance)"
    lines += [
        f"  {'hidden states':<22} {chan}",
        f"  {'seed':<22} {cfg['seed']}",
        *([f"  {'sources':<22} {cfg['sources']} sharing the channels"]
          if cfg.get("sources", 1) > 1 else []),
        f"  {'horizon':<22} {horizon_text(cfg['horizon'])}",
        f"  {'slots recorded':<22} {info['slots']} (in {info['chunks']} "
        f"chunk{'' if info['chunks'] == 1 else 's'})",
        *([f"  {'fields absent':<22} {', '.join(info['absent'])}"] if info.get("absent") else []),
        f"  {'corraoi version':<22} {cfg['version']}",
    ]
    lines += provenance_rows(info.get("provenance"))
    lines += ["summary figures:"] + [f"  {k:<22} {v}" for k, v in summary_rows(s)]
    # names and paths come from the file: one line each, no control codes
    return "\n".join(safe_text(line) for line in lines)


def provenance_info(
    metadata: dict[str, str], attachments: Sequence[tuple[str, str, bytes]]
) -> dict[str, Any] | None:
    """What made a log's numbers (its ``corraoi.provenance`` record), with each plug-in's
    attached source checked against the hash the record names (None: an older log)."""
    if not metadata:
        return None
    prov = Provenance.read(metadata)
    carried: dict[str, list[str]] = {}
    for name, _, data in attachments:
        carried.setdefault(name, []).append(hashlib.sha256(data).hexdigest())
    for p in prov["plugins"]:
        p["attached"] = p["sha256"] in carried.get(p["file"], [])
    return prov


def provenance_rows(prov: dict[str, Any] | None) -> list[str]:
    """The lines ``info`` prints about what made the numbers (log or sweep folder)."""
    if not prov:
        return [f"  {'provenance':<22} not recorded (written before corraoi recorded it)"]
    v = dict(prov.get("versions", {}))
    corraoi = f"corraoi {v.pop('corraoi', '?')}"
    if "git" in v:
        commit = str(v.pop("git"))
        corraoi += f" (git {commit[:12]}{', dirty' if commit.endswith('+dirty') else ''})"
    kernel = v.pop("kernel_sources", "?")
    others = ", ".join(f"{k.replace('python', 'Python')} {val}" for k, val in v.items())
    lines = [f"  {'code':<22} {corraoi}, kernel sources {short(str(kernel))}",
             f"  {'versions':<22} {others}",
             f"  {'backend':<22} {prov.get('backend') or '?'}"]  # fmt: skip
    for p in prov.get("plugins", []):
        where = ("a copy of its source kept in the folder" if p.get("kept") else
                 "its source attached, byte for byte" if p.get("attached", True)
                 else "its source NOT attached")  # fmt: skip
        lines.append(f"  {'plug-in source':<22} {p['file']} {short(p['sha256'])} ({where})")
    for note in prov.get("notes", []):
        lines.append(f"  {'note':<22} {note}")
    return lines


def summary_rows(s: dict[str, Any] | RunSummary) -> list[tuple[str, str]]:
    """(name, text) rows of the summary figures, as info and compare print them."""
    d = s.to_dict() if isinstance(s, RunSummary) else s

    def opt(v: Any, fmt: str = "{}") -> str:
        return "-" if v is None else fmt.format(v)

    several = []  # a run of several sources: each one's regret, and the collisions
    if d.get("regret_by_source") is not None:
        several = [("regret per source", " ".join(str(v) for v in d["regret_by_source"])),
                   ("collisions", opt(d.get("collisions")))]  # fmt: skip
    return [
        ("pathwise regret", opt(d["regret"]) + (" (all sources)" if several else "")),
        *several,
        ("paper's estimator", opt(d["estimator"], "{:.6g}")),
        ("pulls per arm", " ".join(str(v) for v in d["pulls"])),
        ("best arm", opt(d["best_arm"])),
        ("share on best arm", opt(d["best_share"], "{:.2%}")),
        ("AoI override slots", opt(d["overrides"])),
        ("on best arm from slot", opt(d["settled_at"])),
    ]


def sweep_info(folder: Path) -> dict[str, Any]:
    """``corraoi info DIR`` of a sweep folder (or one group's folder in it): its grid, status
    and, per group, the runs worth watching with the ``corraoi record --from`` line of each.
    Reads the JSON files only, so that it stays as quick as ``info`` of a log."""
    from corraoi.experiments.drill import sweep_root
    from corraoi.experiments.folder import group_dirs
    from corraoi.experiments.kept_code import read_manifest_dict

    root, grid, only = sweep_root(folder, option="")
    manifest = read_manifest_dict(root)  # the grid read above is checked; the rest is shown
    groups = []
    dirs = group_dirs(grid, root)  # from the grid: the manifest's own list is not trusted
    several = len(dirs) > 1
    for (name, horizon), where in sorted(dirs.items(), key=lambda kv: str(kv[1])):
        entry = {"instance": name, "horizon": horizon}
        if only is not None and name != only:
            continue
        summary_path = where / "summary.json"
        notable = None
        if summary_path.is_file():
            try:
                notable = json.loads(summary_path.read_text(encoding="utf-8")).get("notable")
            except (OSError, ValueError, AttributeError, RecursionError):
                notable = None
        named = _with_commands(notable, root, entry.get("instance"), several)
        groups.append({"folder": str(where), "instance": entry.get("instance"),
                       "horizon": entry.get("horizon"), "notable": named})  # fmt: skip
    prov = manifest.get("provenance")
    return {
        "path": str(root),
        "status": str(manifest.get("status")),
        "corraoi_version": str(manifest.get("corraoi_version")),
        "provenance": prov if isinstance(prov, dict) else None,
        "backend": grid.backend,
        "cells": len(grid.cells),
        "runs": grid.runs,
        "seeds": [grid.seed, grid.seed + grid.runs - 1],
        "groups": groups,
    }


def _sweep_provenance(info: dict[str, Any]) -> dict[str, Any] | None:
    """A manifest's provenance as provenance_rows reads it (whatever is malformed left out)."""
    prov = info.get("provenance")
    if not isinstance(prov, dict):
        return None
    versions = prov.get("versions")
    plugins = prov.get("plugins")
    return {
        "versions": {str(k): str(v) for k, v in versions.items()}
        if isinstance(versions, dict) else {},
        "backend": str(prov.get("backend", "")),
        "plugins": [{"file": str(p.get("copy") or p.get("file")), "sha256": p["sha256"],
                     "kept": True} for p in plugins if isinstance(p, dict)
                    and isinstance(p.get("sha256"), str)] if isinstance(plugins, list) else [],
        "notes": [],
    }  # fmt: skip


def _with_commands(
    notable: Any, root: Path, instance: Any, several: bool
) -> dict[str, Any] | None:
    if not well_formed(notable, list(notable["cells"]) if isinstance(notable, dict)
                       and isinstance(notable.get("cells"), dict) else ()):  # fmt: skip
        return None
    base = ["corraoi", "record", "--from", str(root)]
    out: dict[str, Any] = {"cells": {}, "pairs": []}
    for label, runs in notable["cells"].items():
        cell = f"{instance}/{label}" if several else str(label)
        out["cells"][label] = {
            k: {**v, "command": shlex.join([*base, "--cell", cell, "--run", k])}
            for k, v in runs.items() if isinstance(v, dict)
        }
    for gap in notable.get("pairs", [])[:5]:
        cells = [c for name in gap["policies"]
                 for c in ("--cell", f"{instance}/{name}" if several else str(name))]  # fmt: skip
        out["pairs"].append({**gap, "command": shlex.join([*base, *cells, "--run", "widest-gap"])})
    return out


def sweep_info_text(info: dict[str, Any]) -> str:
    """The lines ``corraoi info DIR`` prints from :func:`sweep_info`'s dict."""
    lo, hi = info["seeds"]
    lines = [
        f"{safe_text(info['path'])}: corraoi sweep folder ({safe_text(info['status'])}), "
        f"{info['cells']} cells x {info['runs']} runs (seeds {lo}..{hi}), backend "
        f"{info['backend']}",
    ]
    lines += [safe_text(line) for line in provenance_rows(_sweep_provenance(info))]
    for g in info["groups"]:
        lines.append(f"  {safe_text(g['instance'])}, T = {g['horizon']}: {safe_text(g['folder'])}")
        notable = g["notable"]
        if notable is None:
            lines.append("    no runs named in its summary.json (an older sweep, or a damaged "
                         "summary); `corraoi record --from` names them from the parts")  # fmt: skip
            continue
        if info["backend"] == "gpu":
            lines.append("    (a GPU sweep: its runs cannot be recorded again on the CPU)")
        lines.append("    runs worth watching (final regret), and the command that records each:")
        cells = notable["cells"].items()
        # columns as wide as their longest entry (most-collisions, a long plug-in's label)
        wl = max([20, *(len(safe_text(label)) for label, _ in cells)])
        wk = max([7, *(len(k) for _, runs in cells for k in runs)])
        for label, runs in cells:
            for k, v in runs.items():
                lines.append(f"    {safe_text(label):<{wl}} {k:<{wk}} {v['regret']:>9g}  run "
                             f"{v['run']:<6} {safe_text(v['command'])}")  # fmt: skip
        for gap in notable["pairs"]:
            a, b = (safe_text(n) for n in gap["policies"])
            lines.append(f"    {a} - {b}: {gap['difference']:+g} at run {gap['run']}  "
                         f"{safe_text(gap['command'])}")  # fmt: skip
    return "\n".join(lines)


def horizon_text(horizon: int) -> str:
    """A run's horizon as info prints it: a log of a stream given none (corraoi.Logger)
    carries the largest horizon a log can hold, and says it has none."""
    return str(horizon) if horizon < MAX_HORIZON else "none given (an open-ended stream)"
