"""No writer but the sweep itself overwrites a sweep folder's own files.

A run recorded from a sweep (``record --from``, ``compare --from``), a replay, an export, a
recovered log: each is refused, in one line, an output path that is one of a sweep folder's
own files -- its manifest, parts, plug-in copies, ``results.parquet``, and per group its
sweep log, recording and summaries -- even with ``--force`` (the sweep's writers say
``sweep=True`` to :class:`~corraoi.files.partial.PartialFile`). ``figure.png`` is left out: it
is drawn again from the sweep log, and ``corraoi figure`` redraws it there on purpose.
"""

from __future__ import annotations

import json
from pathlib import Path

from corraoi.errors import OutputError

#: The ``format`` of a sweep folder's manifest (corraoi.experiments.folder writes it).
MANIFEST_FORMAT = "corraoi.sweep-folder"
#: Folders of a sweep whose every file is the sweep's own.
OWN_FOLDERS = ("parts", "plugins", "results.parquet")
#: Files of a sweep's group folder (the root for one group) that are the sweep's own.
OWN_GROUP_FILES = ("sweep.mcap", "sweep.rrd", "summary.json", "summary.md")


def owner_sweep(path: str | Path) -> Path | None:
    """The sweep folder of which ``path`` (or its ``.partial``) would be an own file; None
    when it is none's. Looks for a sweep manifest up to three folders up."""
    p = Path(path)
    try:
        p = p.parent.resolve() / p.name
    except (OSError, RuntimeError):
        return None
    name = p.name.removesuffix(".partial")
    for root in list(p.parents)[:3]:
        groups = _groups(root)
        if groups is None:
            continue
        rel = p.relative_to(root)
        if rel.parts[0].removesuffix(".partial") in (*OWN_FOLDERS, "manifest.json"):
            return root
        if name in OWN_GROUP_FILES and str(rel.parent) in groups:
            return root
    return None


def refuse_sweep_file(path: str | Path, what: str) -> None:
    """OutputError (one line) when ``path`` is one of a sweep folder's own files."""
    root = owner_sweep(path)
    if root is not None:
        raise OutputError(f"{path}: is a file of the sweep in {root}, not written over by the "
                          f"{what} (even with --force); give another path")  # fmt: skip


def _groups(root: Path) -> set[str] | None:
    """The group folders (relative, "." for the root) of the sweep whose manifest is in
    ``root``; None when ``root`` holds no sweep manifest."""
    manifest = root / "manifest.json"
    try:
        if not manifest.is_file() or manifest.stat().st_size > (64 << 20):
            return None
        data = json.loads(manifest.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
        return None
    groups = data.get("groups")
    return {str(Path(g)) for g in groups} | {"."} if isinstance(groups, dict) else {"."}


__all__ = ["MANIFEST_FORMAT", "OWN_FOLDERS", "OWN_GROUP_FILES", "owner_sweep",
           "refuse_sweep_file"]
