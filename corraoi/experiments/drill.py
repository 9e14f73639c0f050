"""From a sweep folder to single runs worth recording slot by slot.

A sweep's run ``i`` of a cell is the CPU engine's run with seed ``grid seed + i``, the cell's
instance, policy and parameters, channel and horizon: all in the folder's ``manifest.json``.
:func:`choose` turns ``--run N|worst|best|median|widest-gap`` (with ``--cell`` and
``--policy`` to select) into the :class:`~corraoi.engine.block.RunConfig` of each run to record; the
named runs come from each group's ``summary.json`` (:mod:`corraoi.experiments.notable`), or, for a
folder
from before they were named, from its parts (the per-run finals, no simulation).
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from corraoi.engine.block import RunConfig
from corraoi.errors import ConfigError, DamagedPart
from corraoi.model.channels import TraceReader
from corraoi.policies.spec import PolicySpec

from .folder import (
    CLI_WORDS,
    MANIFEST,
    PARTS,
    CellRuns,
    ChunkResult,
    Words,
    group_dirs,
    read_manifest,
    read_parts,
)
from .grid import Cell, Grid
from .kept_code import (
    changed_note,
    check_code,
    current_spec,
    read_manifest_dict,
    use_kept_code,
)
from .notable import CHOICES, notable_runs, pick_pair, well_formed


@dataclass(frozen=True)
class Drill:
    """One run to record: its configuration and where in the sweep it came from."""

    config: RunConfig
    run: int
    #: "worst", "best", "median", "widest-gap" or "run" (an index given)
    choice: str
    #: the cell's label in its group (None for a policy added on the run, not swept)
    cell: str | None
    folder: Path
    #: (checkpoint slot, regret) of this run in the sweep's part: what the recording must
    #: give again (empty: nothing to check -- a policy added, a part missing, other code)
    expect: tuple[tuple[int, float], ...] = ()
    #: what the log says beside the run (recorded with code other than the sweep's)
    notes: tuple[str, ...] = ()
    #: the sweep's row of a run recorded with other code (``--allow-changed-code``): not
    #: checked as it runs, only compared once it is recorded (:func:`row_verdict`)
    row: tuple[tuple[int, float], ...] = ()

    @property
    def name(self) -> str:
        """A file name stem that says where the run came from."""
        label = self.cell if self.cell is not None else self.config.policy.label
        what = "" if self.choice == "run" else f"-{self.choice}"
        return f"{self.folder.name}-{self.config.instance_name}-{label}-run{self.run}{what}"


def row_mismatch(expect: Sequence[tuple[int, float]], block: Any) -> str | None:
    """Where the regret of ``block`` (a SlotBlock, or a SourcesBlock: its regret summed over
    its sources, as the sweep's row is) differs from the sweep's row ``expect`` ((checkpoint,
    regret) pairs): a one-line account of the first difference, or None."""
    first, last = int(block.t[0]), int(block.t[-1])
    parts = getattr(block, "sources", None)
    regret = block.regret if parts is None else sum(s.regret for s in parts)
    for t, want in expect:
        if first <= t <= last:
            got = float(regret[t - first])
            if got != want:
                return (f"the re-recorded run's regret at slot {t} is {got:g}, the sweep's row "
                        f"says {want:g}: the engine or the code changed since the sweep")
    return None


def row_verdict(drill: Drill, slots: int, regret: float | None) -> str | None:
    """Whether a run recorded with changed code (``drill.row``) still gives the sweep's
    regret at its last slot ``slots`` (``regret``): one line saying it is equal to the sweep's
    row or differs from it; None when there is nothing to compare (no row, a run cut short
    of a checkpoint)."""
    want = dict(drill.row).get(slots)
    if want is None or regret is None:
        return None
    label = drill.cell if drill.cell is not None else drill.config.policy.label
    what = f"{drill.config.instance_name} {label} run {drill.run}, recorded with changed code"
    if float(regret) == want:
        return f"{what}: equal to the sweep's row (regret {want:g} at slot {slots})"
    return (f"{what}: differs from the sweep's row: regret {float(regret):g} vs {want:g} at "
            f"slot {slots}")


def sweep_root(path: str | Path, option: str = "--from ") -> tuple[Path, Grid, str | None]:
    """The folder with the manifest, its grid, and the group sub-folder named (if any);
    ``option`` starts the error lines (the option that named ``path``)."""
    p = Path(path).expanduser()
    if not p.exists():
        raise ConfigError(f"{option}{path}: no such folder")
    if not p.is_dir():
        raise ConfigError(f"{option}{path}: not a folder (expected a sweep folder, with "
                          f"{MANIFEST})")  # fmt: skip
    for root, sub in ((p, None), (p.parent, p.name)):
        grid = read_manifest(root)
        if grid is None:
            continue
        if sub is not None:  # a group's folder inside a sweep of several groups
            named = [name for (name, _), d in group_dirs(grid, root).items() if d.name == sub]
            if not named:
                break
            return root, grid, named[0]
        return root, grid, None
    raise ConfigError(f"{option}{path}: not a sweep folder (no {MANIFEST} in it; expected the "
                      "folder `corraoi sweep -o` or `corraoi reproduce -o` wrote)")  # fmt: skip


def parse_run(text: str | int, words: Words = CLI_WORDS) -> str | int:
    """``--run``: a run index (0-based) or one of :data:`CHOICES`."""
    if isinstance(text, int):
        return text
    t = text.strip().lower()
    if t in CHOICES:
        return t
    try:
        return int(t)
    except ValueError:
        raise ConfigError(f"{words.run}{text!r}: expected a run index (0, 1, ...) or one of "
                          f"{', '.join(CHOICES)}") from None  # fmt: skip


def split_policy_words(path: str | Path, values: Sequence[str]) -> tuple[list[str], list[str]]:
    """``--policy`` words (names or comma lists) for the sweep folder ``path``, split into the
    labels its own table prints for its cells (``eps-greedy``, ``cucb(c=2)``: what
    :func:`choose` takes as ``swept_labels``) and the rest (policies to resolve as anywhere). A
    plug-in's label is no registered name in a new process: it is the sweep's to resolve."""
    import re

    _, grid, _ = sweep_root(path)
    known = set(grid.labels().values())
    labels: list[str] = []
    rest: list[str] = []
    for value in values:  # a label's own commas are inside its parentheses
        for word in (w.strip() for w in re.split(r",(?![^()]*\))", value)):
            if word:
                (labels if word in known else rest).append(word)
    return list(dict.fromkeys(labels)), rest


def choose(
    path: str | Path,
    run: str | int,
    *,
    cells: Sequence[str] = (),
    policies: Sequence[PolicySpec] = (),
    swept_labels: Sequence[str] = (),
    warn: Any = None,
    kept_code: bool = False,
    allow_changed_code: bool = False,
    trace_readers: Mapping[str, TraceReader] | None = None,
    words: Words = CLI_WORDS,
) -> list[Drill]:
    """The runs to record from the sweep folder ``path`` (module docstring).

    ``cells``: labels (``cucb``, ``cucb(c=2)``), instance names or ``INSTANCE/LABEL`` that
    restrict the sweep's cells. ``policies``: those the sweep ran select its cells; any
    other is added on the chosen run (paired: the same seed, so the same hidden path),
    said through ``warn``. ``swept_labels``: cells named by the labels the sweep's table
    prints (:func:`split_policy_words`), selected as ``policies`` select theirs.
    ``trace_readers``: as for :func:`~corraoi.model.channels.parse_channel` (a trace
    channel's file is read again).

    A plug-in whose source is not the one the sweep ran is refused (one line: the file, both
    hashes, the way out; :mod:`corraoi.experiments.kept_code`), unless ``kept_code`` (the
    sweep's copy runs: record the drills inside :func:`kept_code_scope`) or
    ``allow_changed_code`` (the current code runs, and the log says so). Each
    :class:`Drill` carries the sweep's regret of its run at the checkpoints (``expect``).
    The kept code runs under module names of its own: the session's modules, classes and
    registrations stay the user's. ``words``: how refusals name the options.
    """
    root, grid, group = sweep_root(path)
    manifest = read_manifest_dict(root)
    if kept_code and allow_changed_code:
        raise ConfigError(f"{words.kept_code} and {words.allow_changed_code}: choose one")
    kept = use_kept_code(root, manifest) if kept_code else contextlib.nullcontext()
    what = parse_run(run, words)
    if isinstance(what, int) and not 0 <= what < grid.runs:
        raise ConfigError(f"{words.run}{what}: out of range; the sweep in {root} has runs "
                          f"0..{grid.runs - 1}")  # fmt: skip
    named = tuple(swept_labels)
    labels = grid.labels()
    unknown = [w for w in named if w not in labels.values()]
    if unknown:
        raise ConfigError(f"{words.policy}{unknown[0]!r}: no cell of the sweep in {root} has that "
                          f"label (its labels: {', '.join(dict.fromkeys(labels.values()))})")
    groups = {k: v for k, v in grid.groups().items() if group is None or k[0] == group}
    swept = {c.policy.name for g in groups.values() for c in g}
    extra = [s for s in policies if s.name not in swept]
    names = [s.name for s in policies if s.name in swept] if policies or named else None
    chosen = _select(groups, labels, cells, names, root, named, words)
    if not any(chosen.values()) and not (extra and isinstance(what, int)):
        raise ConfigError(
            f"{words.policy}{', '.join([*named, *(s.name for s in policies)])}: not in the "
            f"sweep in {root} (its policies: {', '.join(sorted(swept))}); a {what} run is "
            f"chosen among the sweep's policies: name one of them too, or give {words.run}N"
        )
    picked = {key: _picks(root, grid, key, groups[key], members, labels, what, words)
              if members else [] for key, members in chosen.items()}  # fmt: skip
    if grid.backend == "gpu":  # every run is recorded with the GPU kernel: each needs its form
        from corraoi.gpu.runner import gpu_problem

        for key, members in chosen.items():
            K = groups[key][0].instance.K
            problem = next((p for spec in [*(c.policy for c in members), *extra]
                            if (p := gpu_problem(spec, K)) is not None), None)  # fmt: skip
            if problem is not None:
                raise ConfigError(f"{problem}: a GPU sweep's runs are recorded with the GPU "
                                  f"kernel; leave it out of {words.policy.strip()}")  # fmt: skip
    swept_specs = [cell.policy for picks in picked.values() for cell, _ in picks]
    with kept:
        notes = check_code(swept_specs, root, manifest, allow_changed=allow_changed_code,
                           words=words)  # fmt: skip
    for note in notes:
        if warn is not None:
            warn(note)
    streams = _streams(grid, warn)  # after every check: a refusal stays one line
    if extra and warn is not None:
        added = ", ".join(s.label for s in extra)
        warn(f"{added}: not in the sweep; recorded on the chosen run too (paired: the same "
             "seed, so the same hidden path)")  # fmt: skip
    drills: list[Drill] = []
    for key, members in chosen.items():
        picks = picked[key]
        for cell, r in picks:
            drills.append(_drill(root, grid, cell, labels[cell.key], r, what, streams,
                                 allow_changed_code, trace_readers))  # fmt: skip
        runs = list(dict.fromkeys(r for _, r in picks)) or ([what] if isinstance(what, int) else [])
        base = (members or groups[key])[0]
        for spec in extra:
            for r in runs:
                drills.append(_drill(root, grid, Cell(base.instance, spec, base.horizon,
                                                      base.channel, base.sources), None, r, what,
                                     streams, trace_readers=trace_readers))  # fmt: skip
    return drills


def kept_code_scope(path: str | Path, kept_code: bool) -> contextlib.AbstractContextManager[Any]:
    """The block in which the runs chosen from the sweep folder ``path`` with ``kept_code``
    are chosen and recorded: its kept copies are handed over to the loader there, and only
    there (:func:`corraoi.experiments.kept_code.use_kept_code`); nothing without."""
    if not kept_code:
        return contextlib.nullcontext()
    return use_kept_code(sweep_root(path)[0])


def _select(
    groups: dict[tuple[str, int], list[Cell]],
    labels: dict[str, str],
    cells: Sequence[str],
    names: Sequence[str] | None,
    root: Path,
    named: Sequence[str] = (),
    words: Words = CLI_WORDS,
) -> dict[tuple[str, int], list[Cell]]:
    def matches(cell: Cell, text: str) -> bool:
        inst, _, label = text.rpartition("/")
        if inst and inst != cell.instance.name:
            return False
        return label in (labels[cell.key], cell.policy.name) or (not inst
                                                                and label == cell.instance.name)

    out: dict[tuple[str, int], list[Cell]] = {}
    for text in cells:
        if not any(matches(c, text) for g in groups.values() for c in g):
            known = ", ".join(dict.fromkeys(f"{k[0]}/{labels[c.key]}"
                                            for k, g in groups.items() for c in g))  # fmt: skip
            raise ConfigError(f"{words.cell}{text!r}: no such cell in {root} (its cells: "
                              f"{known})")  # fmt: skip
    for key, members in groups.items():
        keep = [c for c in members if not cells or any(matches(c, t) for t in cells)]
        if cells and not keep:
            continue  # a group --cell leaves out
        out[key] = keep if names is None else [c for c in keep if c.policy.name in names
                                               or labels[c.key] in named]  # fmt: skip
    return out


def _picks(
    root: Path,
    grid: Grid,
    key: tuple[str, int],
    group: list[Cell],
    members: list[Cell],
    labels: dict[str, str],
    what: str | int,
    words: Words = CLI_WORDS,
) -> list[tuple[Cell, int]]:
    if isinstance(what, int):
        return [(c, what) for c in members]
    notable = _notable(root, grid, key, group, labels, words)
    if what == "widest-gap":
        among = [labels[c.key] for c in members] if len(members) < len(group) else None
        gap = pick_pair(notable.get("pairs", []), among)
        if gap is None:
            raise ConfigError(f"{words.run}widest-gap: no pair of policies on one hidden path "
                              f"among {', '.join(labels[c.key] for c in members)} in "
                              f"{root}")  # fmt: skip
        by_label = {labels[c.key]: c for c in group}
        return [(by_label[name], _run_of(gap, grid, root, words)) for name in gap["policies"]]
    if what == "most-collisions":
        alone = [labels[c.key] for c in members if c.sources == 1]
        if alone:
            raise ConfigError(f"{words.run}most-collisions: {alone[0]} runs one source (no "
                              f"collisions); name a cell of several sources with "
                              f"{words.cell.strip()} or {words.policy.strip()}")  # fmt: skip
    return [(c, _run_of(notable["cells"][labels[c.key]].get(what), grid, root, words))
            for c in members]  # fmt: skip


def _run_of(entry: Any, grid: Grid, root: Path, words: Words = CLI_WORDS) -> int:
    run = entry.get("run") if isinstance(entry, dict) else None
    if not isinstance(run, int) or not 0 <= run < grid.runs:
        raise ConfigError(f"{root}: its summary.json names run {run!r}, not one of the sweep's "
                          f"0..{grid.runs - 1} (a damaged summary: sweep again with "
                          f"{words.resume})")  # fmt: skip
    return run


def _notable(
    root: Path, grid: Grid, key: tuple[str, int], group: list[Cell], labels: dict[str, str],
    words: Words = CLI_WORDS,
) -> dict[str, Any]:
    """The group's notable runs: from its summary.json, else from the parts."""
    path = group_dirs(grid, root)[key] / "summary.json"
    want = [labels[c.key] for c in group]
    if path.is_file():
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError) as exc:
            why = " ".join(str(exc).split())[:120] or type(exc).__name__
            raise ConfigError(f"{path}: unreadable ({why}); sweep again with "
                              f"{words.resume}") from None  # fmt: skip
        notable = data.get("notable") if isinstance(data, dict) else None
        if well_formed(notable, want):
            return notable  # type: ignore[return-value]
    try:  # an older folder (none named in its summary, or damaged): from the per-run finals
        parts = read_parts(root, grid)
        runs = [CellRuns.join(c, labels[c.key], parts.get(c.key, []), grid.runs) for c in group]
    except DamagedPart as exc:
        raise ConfigError(f"{exc}; a sweep with {words.resume} runs it again") from None
    except ConfigError as exc:
        raise ConfigError(f"{root}: {exc}: finish the sweep with {words.resume}, or give "
                          f"{words.run}N") from None  # fmt: skip
    base = [r.label for r in runs if r.cell.policy.name == grid.baseline]
    return notable_runs([r.label for r in runs], [r.regret[:, -1] for r in runs],
                        [r.cell.channel.to_dict() for r in runs], seed=grid.seed,
                        baseline=base[0] if base else None,
                        collisions=[r.collisions[:, -1] if r.collisions is not None else None
                                    for r in runs])  # fmt: skip


def _streams(grid: Grid, warn: Any) -> str:
    """Whose streams re-record the sweep's runs: the CPU engine's for a CPU sweep; for a GPU
    sweep the GPU kernel's, on this machine's CUDA device, else emulated on the host."""
    if grid.backend != "gpu":
        return "cpu"
    import os

    from corraoi.errors import GpuUnavailable
    from corraoi.gpu.device import DEVICE_ENV, device_of

    if os.environ.get(DEVICE_ENV, "").strip().lower() != "emulate":
        try:
            device_of("cuda")
            return "gpu-cuda"
        except GpuUnavailable as exc:
            why = str(exc)
    else:
        why = f"{DEVICE_ENV}=emulate"
    try:
        device_of("emulate")
    except GpuUnavailable as exc:
        raise ConfigError(f"this sweep ran on the GPU; its runs are recorded again with the GPU "
                          f"kernel, which needs a CUDA device ({why}) or {exc}") from None
    if warn is not None:
        warn(f"a GPU sweep's runs are captured from the GPU kernel compiled for this CPU ({why}): "
             "the same streams and rule; a transcendental that rounds differently from CUDA's "
             "can flip a near-tie (the log says streams gpu-emulated)")  # fmt: skip
    return "gpu-emulated"


def _drill(root: Path, grid: Grid, cell: Cell, label: str | None, run: int,
           what: str | int, streams: str = "cpu", allow_changed: bool = False,
           trace_readers: Mapping[str, TraceReader] | None = None) -> Drill:  # fmt: skip
    """With ``allow_changed`` (--allow-changed-code) a plug-in whose code changed runs as it
    is now: the spec names that code, the log says so, and the sweep's row is kept to say
    afterwards whether the run still equals it (``row``); otherwise the run must give the
    sweep's regret again (``expect``)."""
    channel = cell.channel
    if channel.kind == "trace" and channel.trace is None:
        channel = _reload_trace(cell, root, trace_readers)
    spec = cell.policy
    expect: tuple[tuple[int, float], ...] = ()
    notes: tuple[str, ...] = ()
    if allow_changed and label is not None and not spec.builtin and spec.digest:
        now = current_spec(spec)
        if not now.digest.startswith(spec.digest):
            where = spec.qualname.removeprefix("file:").rpartition(":")[0] or spec.qualname
            notes = (changed_note(where, spec.digest, now.digest),)
            spec = now
    row: tuple[tuple[int, float], ...] = ()
    if label is not None:  # changed code: compared once recorded, not a check that stops it
        if notes:
            row = expected_row(root, grid, cell, run)
        else:
            expect = expected_row(root, grid, cell, run)
    config = RunConfig(cell.instance, spec, grid.seed + run, cell.horizon, channel=channel,
                       streams=streams, sources=cell.sources)  # fmt: skip
    choice = what if isinstance(what, str) else "run"
    return Drill(config, run, choice, label, root, expect, notes, row)


def expected_row(root: Path, grid: Grid, cell: Cell, run: int) -> tuple[tuple[int, float], ...]:
    """(checkpoint, regret) of run ``run`` of ``cell`` in its part file (only the part that
    holds it is read; () when it is missing or damaged: nothing to check against)."""
    for f in sorted((root / PARTS).glob(f"{cell.key}-*.npz")):
        try:
            start, stop = (int(v) for v in f.stem.rsplit("-", 2)[1:])
        except ValueError:
            continue
        if start <= run < stop:
            try:
                part = ChunkResult.load(f)
            except DamagedPart:
                return ()
            row = part.regret[run - start]
            return tuple((int(t), float(v)) for t, v in zip(part.t, row, strict=True))
    return ()


def _reload_trace(
    cell: Cell, root: Path, readers: Mapping[str, TraceReader] | None = None
) -> Any:
    """A trace channel's states, read again from the file the sweep read them from."""
    from corraoi.model.channels import parse_channel

    ch = cell.channel
    try:
        fresh = parse_channel(f"trace:{ch.source}", cell.instance, readers=readers)
    except ConfigError as exc:
        raise ConfigError(f"{root}: the sweep's trace channel cannot be read again: "
                          f"{exc}") from None  # fmt: skip
    if fresh.digest != ch.digest:
        raise ConfigError(f"{root}: the trace {ch.source} has changed since the sweep read it "
                          "(its digest differs): its runs cannot be recorded again")  # fmt: skip
    return fresh
