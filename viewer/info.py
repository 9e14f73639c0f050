"""``corraoi info``: what a log holds -- configuration, slot count, how it ended, figures."""

from __future__ import annotations

from typing import Any

from corraoi.text import safe_text
from corraoi.theory import analyse

from .runs import LogLike, as_log
from .summary import RunSummary, summarize_blocks


def log_info(log: LogLike) -> dict[str, Any]:
    """Everything ``corraoi info --json`` prints, as one JSON-ready dict (arms from 1)."""
    run = as_log(log)
    cfg = run.config
    summary = summarize_blocks(cfg, run.blocks(4096))
    theory = analyse(cfg.instance)
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
        "theory": {
            "mu": [float(v) for v in theory.mu],
            "best_arm": theory.best_arm + 1,
            "competitive": [a + 1 for a in theory.competitive],
            "C": theory.C,
        },
        "summary": summary.to_dict(),
    }


def info_text(info: dict[str, Any]) -> str:
    """The table ``corraoi info`` prints from :func:`log_info`'s dict."""
    cfg = info["config"]
    inst, pol, th = cfg["instance"], cfg["policy"], info["theory"]
    s = info["summary"]
    params = ", ".join(f"{k}={v:g}" for k, v in sorted(pol["params"].items()))
    p = " ".join(f"{v:g}" for v in inst["p"])
    mu = " ".join(f"{v:g}" for v in th["mu"])
    comp = ", ".join(str(a) for a in th["competitive"]) or "none"
    lines = [
        f"{info['path']}: corraoi slot log, format version {info['format_version']}"
        + (f" (written by {info['library']})" if info["library"] else ""),
        f"  {'status':<22} {info['description']}",
        f"  {'run':<22} {info['label']}",
        f"  {'instance':<22} {inst['name']}: K={len(inst['Y'])} arms, {len(inst['p'])} states,"
        f" p = [{p}]",
        f"  {'theory':<22} mu = [{mu}], best arm {th['best_arm']}, competitive arms: {comp}"
        f" (C = {th['C']})",
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
    lines += [
        f"  {'hidden states':<22} {chan}",
        f"  {'seed':<22} {cfg['seed']}",
        f"  {'horizon':<22} {cfg['horizon']}",
        f"  {'slots recorded':<22} {info['slots']} (in {info['chunks']} chunks)",
        f"  {'corraoi version':<22} {cfg['version']}",
    ]
    lines += ["summary figures:"] + [f"  {k:<22} {v}" for k, v in summary_rows(s)]
    # names and paths come from the file: one line each, no control codes
    return "\n".join(safe_text(line) for line in lines)


def summary_rows(s: dict[str, Any] | RunSummary) -> list[tuple[str, str]]:
    """(name, text) rows of the summary figures, as info and compare print them."""
    d = s.to_dict() if isinstance(s, RunSummary) else s

    def opt(v: Any, fmt: str = "{}") -> str:
        return "-" if v is None else fmt.format(v)

    return [
        ("pathwise regret", opt(d["regret"])),
        ("paper's estimator", opt(d["estimator"], "{:.6g}")),
        ("pulls per arm", " ".join(str(v) for v in d["pulls"])),
        ("best arm", str(d["best_arm"])),
        ("share on best arm", opt(d["best_share"], "{:.2%}")),
        ("AoI override slots", str(d["overrides"])),
        ("on best arm from slot", opt(d["settled_at"])),
    ]
