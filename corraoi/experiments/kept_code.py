"""A sweep folder's plug-in code: the copy of each plug-in's source it keeps beside its hash,
the check that the code about to run is the code the sweep ran, and the way out.

A sweep writes ``plugins/<first 16 hex digits of the sha256>/<file name>`` for every plug-in
file its cells ran, and lists them in ``manifest.json`` under ``provenance.plugins`` (file,
path, full sha256, copy). ``corraoi sweep --resume``, ``record --from`` and ``compare --from``
compare each plug-in's current source with the sweep's (:func:`check_code`): a mismatch is one
line naming the file and both hashes, with the way out -- ``--kept-code`` runs the kept copy
(:func:`use_kept_code`: the file is not touched), ``--allow-changed-code`` (``record`` and
``compare --from`` only) records with the current code and says so in the log.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from corraoi.errors import CodeChanged, ConfigError, PolicyError
from corraoi.files.partial import PartialFile

from .folder import CLI_WORDS, Words

#: Where a sweep folder keeps its plug-ins' sources.
PLUGINS = "plugins"


def keep_sources(folder: Path, provenance: Any) -> list[dict[str, str]]:
    """Write a copy of each source of ``provenance`` (a :class:`~corraoi.provenance.
    Provenance`) into ``folder/plugins``; returns its plug-in entries with ``copy`` (the
    path in the folder). A copy already there with the right bytes is kept as it is."""
    entries = []
    for src in provenance.sources:
        rel = kept_copy(src)
        target = folder / rel
        if not (target.is_file() and not target.is_symlink() and _sha(target) == src.sha256):
            target.parent.mkdir(parents=True, exist_ok=True)
            PartialFile.write_bytes(target, src.data, what="plug-in copy", sweep=True)
        entries.append({**src.to_dict(), "copy": rel})
    return entries


def kept_copy(source: Any) -> str:
    """Where in a sweep folder the copy of ``source`` (a provenance Source) is kept."""
    return f"{PLUGINS}/{source.sha256[:16]}/{safe_file_name(source.name)}"


def kept_sources(folder: Path, manifest: dict[str, Any]) -> list[dict[str, Any]]:
    """The plug-in copies a sweep's manifest lists, each with its bytes (``data``) when the
    copy is there, inside the folder, and hashes to the sha256 listed (else ``None``)."""
    prov = manifest.get("provenance")
    plugins = prov.get("plugins") if isinstance(prov, dict) else None
    out: list[dict[str, Any]] = []
    for p in plugins if isinstance(plugins, list) else []:
        if not (isinstance(p, dict) and all(isinstance(p.get(k), str)
                                            for k in ("path", "sha256", "copy"))):  # fmt: skip
            continue
        copy = (folder / p["copy"]).resolve()
        data = None
        if copy.is_relative_to((folder / PLUGINS).resolve()) and copy.is_file():
            raw = copy.read_bytes()
            data = raw if hashlib.sha256(raw).hexdigest() == p["sha256"] else None
        out.append({**p, "data": data})
    return out


def use_kept_code(folder: Path, manifest: dict[str, Any] | None = None, *,
                  pin: bool = False) -> contextlib.AbstractContextManager[list[str]]:  # fmt: skip
    """``kept_code``: while the block runs, the sweep's copy of every plug-in file it ran is
    handed over to the loader (:func:`corraoi.policies.loading.handed_over`): a spec naming
    the sweep's code (each of its cells does) runs that copy, under a module name of its own.
    The user's module, class and registration are left as they are, and after the block a
    call that names the file runs the file. ``pin`` (``corraoi sweep --resume
    --kept-code``): a file named without a hash (``-p FILE.py:Class``) runs the copy too.
    A copy that is missing or does not hash to the manifest's sha256 is refused."""
    from corraoi.policies.loading import handed_over

    data: dict[str, bytes] = {}
    for p in kept_sources(folder, read_manifest_dict(folder) if manifest is None else manifest):
        if p["data"] is None:
            raise ConfigError(f"{folder / p['copy']}: the sweep's copy of {p['path']} is missing "
                              f"or does not hash to sha256:{p['sha256'][:16]}; the kept code "
                              "cannot run it")  # fmt: skip
        data[p["path"]] = p["data"]
    return handed_over(data, pin=pin)


def check_code(specs: Iterable[Any], folder: Path, manifest: dict[str, Any], *,
               allow_changed: bool = False, words: Words = CLI_WORDS) -> list[str]:  # fmt: skip
    """Whether every plug-in of ``specs`` (a sweep's cells) loads the code the sweep ran.
    Raises :class:`CodeChanged` with the way out when one does not; with ``allow_changed``,
    returns instead one note per changed plug-in (for the log: recorded with other code)."""
    kept = kept_sources(folder, manifest)
    notes: list[str] = []
    for spec in specs:
        if spec.builtin or not spec.digest:
            continue
        copy = next((p for p in kept if p["sha256"].startswith(spec.digest)), {})
        try:
            spec.resolve()
        except CodeChanged as exc:
            if not allow_changed:
                raise exc.with_way_out(way_out(folder, copy, words)) from None
            notes.append(changed_note(exc.path, exc.expected, exc.found))
        except PolicyError as exc:  # the file is gone (or no longer a plug-in): say so too
            if copy.get("data") is None:
                raise
            raise PolicyError(f"{exc}; the sweep ran sha256:{spec.digest[:16]}: "
                              f"{way_out(folder, copy, words)}") from None  # fmt: skip
    return notes


def changed_note(where: str, expected: str, found: str) -> str:
    """What the log of a run recorded with ``--allow-changed-code`` says."""
    where = where.removeprefix("file:")
    return (f"recorded with changed code: {where} is sha256:{found[:16]} now, the sweep ran "
            f"sha256:{expected[:16]} (--allow-changed-code)")


def current_spec(spec: Any) -> Any:
    """``spec`` naming the code its plug-in file holds now (``--allow-changed-code``: the
    log names the code that ran, never the sweep's hash)."""
    import dataclasses

    from corraoi.policies.registry import resolve

    qual = spec.qualname
    res = resolve(qual[len("file:"):] if qual.startswith("file:") else qual)
    return dataclasses.replace(spec, version=res.version, sha256=res.sha256)


def way_out(folder: Path, kept: dict[str, Any], words: Words = CLI_WORDS) -> str:
    """The end of a refusal line: where the sweep's copy is, and the two options (in the
    caller's ``words``)."""
    copy = kept.get("copy") if kept.get("data") is not None else None
    where = (f"the sweep's copy is {folder / copy}" if copy else
             "the sweep kept no copy of it")  # fmt: skip
    which = ("record and compare --from" if words == CLI_WORDS else
             "Sweep.record and Sweep.record_each")  # fmt: skip
    return (f"{where}; {words.kept_code} runs that copy, {words.allow_changed_code} ({which}) "
            "records with the current code and says so in the log")


def read_manifest_dict(folder: Path) -> dict[str, Any]:
    """``manifest.json`` as a dict ({} when unreadable: read_manifest has said why)."""
    try:
        data = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError):
        return {}
    return data if isinstance(data, dict) else {}


def safe_file_name(name: str) -> str:
    from corraoi.text import safe_name

    return safe_name(Path(name).name) or "plugin.py"


def _sha(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return ""


__all__ = ["PLUGINS", "changed_note", "check_code", "current_spec", "keep_sources", "kept_copy",
           "kept_sources", "read_manifest_dict", "use_kept_code", "way_out"]  # fmt: skip
