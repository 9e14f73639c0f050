"""Sweeps from Python: :func:`sweep` runs a grid into a folder and returns a :class:`Sweep`, what
:func:`corraoi.load` gives for a sweep folder too; ``corraoi sweep`` and ``corraoi reproduce``
run their grids through :func:`run_grid`.

A :class:`Sweep` is the recorder's :class:`~corraoi.recorder.sweeplog.results.SweepData` (``.runs``,
``.summary``, ``.curves``, ``.config``) with what comes next: the runs worth watching
(``.notable``), one of them recorded slot by slot (``.record``, what ``corraoi record --from``
does), its figure, the viewer, and a table in Jupyter.
"""

from __future__ import annotations

import html
import os
import shutil
import tempfile
import weakref
from collections.abc import Callable, Mapping, Sequence
from contextlib import AbstractContextManager, ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from corraoi import arguments
from corraoi.errors import ConfigError, CorraoiError, InstanceError, PolicyError, UsageError
from corraoi.recorder.sweeplog.results import SweepData

from .resolve import PolicyLike, python_warn

if TYPE_CHECKING:
    from corraoi.experiments.folder import Words
    from corraoi.experiments.grid import Grid
    from corraoi.experiments.sweeps import SweepOutcome
    from corraoi.model.instance import Instance
    from corraoi.policies.spec import PolicySpec

    from .runs import Run
    from .viewing import Shown


class Sweep(SweepData):
    """A sweep folder (``corraoi sweep -o DIR``, :func:`corraoi.sweep`), loaded.

    * ``.runs``: every run at every checkpoint (pandas); ``.summary``: ``summary.json``;
      ``.curves``: the sweep log's mean curves; ``.config``: the grid;
    * ``.notable``: per policy its worst, median and best run, and the pairs of policies with
      the widest paired gaps;
    * ``.record(which)``: one of those runs (or run N) recorded slot by slot, a
      :class:`corraoi.Run` whose regret equals the sweep's row; ``.record_each(which)``:
      that run of every cell (what ``corraoi compare --from`` compares);
    * ``.figure(path)``: the sweep figure.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        super().__init__(arguments.path(path, name="path", kind=UsageError,
                                        what="a sweep folder's path"))  # fmt: skip

    @property
    def notable(self) -> dict[str, Any] | None:
        """The runs worth watching (``summary.json``'s ``notable``; None without one)."""
        summary = self.summary
        value = summary.get("notable") if isinstance(summary, dict) else None
        return value if isinstance(value, dict) else None

    @property
    def rrd(self) -> Path | None:
        """The sweep's Rerun recording (``sweep.rrd``), if it has one."""
        path = self.folder / "sweep.rrd"
        return path if path.is_file() else None

    def record(
        self,
        which: int | str = "worst",
        *,
        policy: PolicyLike | Sequence[PolicyLike] | None = None,
        cell: str | None = None,
        path: str | os.PathLike[str] | None = None,
        rrd: str | os.PathLike[str] | bool | None = None,
        force: bool = False,
        kept_code: bool = False,
        allow_changed_code: bool = False,
    ) -> Run:
        """Record one run of this sweep slot by slot, as ``corraoi record --from`` does (the
        same files): ``which`` is a run index or ``worst``, ``median``, ``best``; ``policy``
        (a label the sweep's table prints, a name, a class, ...) and ``cell`` (a label such
        as ``cucb(c=2)``, or ``INSTANCE/LABEL``) say whose. The run's regret must equal the
        sweep's row (:class:`~corraoi.errors.SweepMismatch` if not: the engine or the code
        changed).

        ``path``: the slot log (default ``runs/<folder>-<instance>-<label>-run<N>-<which>.mcap``),
        ``rrd`` as for :func:`corraoi.record`: a complete log of the same run already there
        (the same code, settings and engine) is returned as it is, nothing runs, unless
        ``force``; one that holds another run is refused unless ``force``. A plug-in edited
        since the sweep is refused unless ``kept_code`` (the folder's copy runs, for this
        call only, under a module name of its own: your module and class stay as they are)
        or ``allow_changed_code`` (the code as it is now runs, and a
        :class:`~corraoi.errors.CorraoiWarning` says whether its regret is still equal to the
        sweep's row or differs from it). Where ``which`` names runs of several cells,
        :class:`~corraoi.errors.CorraoiError` lists them."""
        from corraoi.experiments.drill import kept_code_scope, split_policy_words

        from .resolve import policies

        which = check_which(which)  # the arguments checked before anything is done
        arguments.optional(arguments.text, cell, name="cell",
                           expected="a cell's label (cucb(c=2)) or INSTANCE/LABEL")  # fmt: skip
        arguments.optional(arguments.path, path, name="path")
        arguments.path_or_flag(rrd, name="rrd", what="the Rerun recording's path")
        for name, value in (("force", force), ("kept_code", kept_code),
                            ("allow_changed_code", allow_changed_code)):  # fmt: skip
            arguments.flag(value, name=name)
        given = _listed(policy) if policy is not None else []
        # the labels the sweep's table prints name its cells; anything else is a policy
        labels = split_policy_words(self.folder, [p for p in given if isinstance(p, str)])[0]
        rest = [p for p in given if not (isinstance(p, str) and p in labels)]
        specs = policies(rest) if rest else []
        with kept_code_scope(self.folder, kept_code):  # the kept copies run here, only here
            return self._record(which, specs, labels, cell, path, rrd, force, kept_code,
                                allow_changed_code)  # fmt: skip

    def _record(self, which: int | str, specs: list[PolicySpec], labels: list[str],
                cell: str | None, path: str | os.PathLike[str] | None,
                rrd: str | os.PathLike[str] | bool | None, force: bool, kept_code: bool,
                allow_changed_code: bool) -> Run:  # fmt: skip
        from corraoi.experiments.drill import choose, row_verdict
        from corraoi.experiments.folder import PYTHON_WORDS

        from .recording import Outlets, plan_files, record_plans, refuse, up_to_date
        from .resolve import TRACE_READERS
        from .runs import Run

        cells = (cell,) if cell is not None else ()
        drills = choose(self.folder, which, cells=cells, policies=specs, swept_labels=labels,
                        warn=python_warn, kept_code=kept_code,
                        allow_changed_code=allow_changed_code,
                        trace_readers=TRACE_READERS, words=PYTHON_WORDS)  # fmt: skip
        if len(drills) != 1:
            listed = "; ".join(f"{d.config.instance_name}/{d.cell or d.config.policy.label} "
                               f"run {d.run}" for d in drills)  # fmt: skip
            raise CorraoiError(
                f"{self.folder}: {which!r} names {len(drills)} runs ({listed}); choose one "
                "with cell='INSTANCE/LABEL' or policy=..."
            )
        rrd_path = None if rrd is None or rrd is False or rrd is True else rrd
        plans = plan_files([drills[0].config], path, rrd_path, no_rrd=rrd is False,
                           drills=drills)  # fmt: skip
        if not force and up_to_date(plans[0]):  # the cell run again: the run it recorded
            return Run(plans[0].mcap, rrd=plans[0].rrd)
        refuse(plans, force=force, hint="force=True")
        (done,) = record_plans(plans, Outlets(overwrite=force))
        assert done.mcap is not None
        verdict = row_verdict(drills[0], done.slots, done.regret)  # changed code: still equal?
        if verdict is not None:
            import warnings

            from corraoi.errors import CorraoiWarning

            warnings.warn(verdict, CorraoiWarning, stacklevel=2)
        return Run(done.mcap, rrd=done.rrd, summary=done.summary)

    def record_each(
        self,
        which: int | str = "worst",
        *,
        cells: Sequence[str] = (),
        folder: str | os.PathLike[str] = "runs",
        force: bool = False,
        kept_code: bool = False,
        allow_changed_code: bool = False,
        say: Callable[[str], None] | None = None,
        warn: Callable[[str], None] = python_warn,
        words: Words | None = None,
    ) -> list[Run]:
        """The chosen run (``which``, as for :meth:`record`) of every cell of this sweep (or
        of ``cells`` only), each recorded slot by slot into ``folder`` (MCAP only, named after
        the run), as ``corraoi compare --from`` does before it compares them. A log already
        there that holds the same run, complete, is used as it is; one holding another run
        is an :class:`~corraoi.errors.OutputError` unless ``force``. Each run's regret must
        equal the sweep's row (:class:`~corraoi.errors.SweepMismatch`). ``say`` is told of
        each run as it starts; ``warn`` of what the choice notices (a
        :class:`~corraoi.errors.CorraoiWarning` by default); ``words``: how refusals name the
        options (Python's unless told: ``corraoi compare --from`` gives the command line's)."""
        from corraoi.experiments.drill import kept_code_scope
        from corraoi.experiments.folder import PYTHON_WORDS, Words

        if words is not None and not isinstance(words, Words):
            raise arguments.wrong_type(UsageError, "words", words,
                                       "None or corraoi.experiments.folder.Words")  # fmt: skip
        words = words or PYTHON_WORDS
        with kept_code_scope(self.folder, kept_code):  # the kept copies run here, only here
            return self._record_each(which, cells, folder, force, kept_code,
                                     allow_changed_code, say, warn, words)  # fmt: skip

    def _record_each(self, which: int | str, cells: Sequence[str],
                     folder: str | os.PathLike[str], force: bool, kept_code: bool,
                     allow_changed_code: bool, say: Callable[[str], None] | None,
                     warn: Callable[[str], None], words: Words) -> list[Run]:  # fmt: skip
        from corraoi.engine.threads import set_workers
        from corraoi.experiments.drill import choose
        from corraoi.text import safe_name, safe_text

        from .recording import Plan, record_drill, refuse, up_to_date
        from .resolve import TRACE_READERS
        from .runs import Run

        which = check_which(which)  # the arguments checked before anything is done
        cells = arguments.names(cells, name="cells", empty=True, what="cells' labels")
        arguments.path(folder, name="folder", what="a folder's path")
        for name, value in (("force", force), ("kept_code", kept_code),
                            ("allow_changed_code", allow_changed_code)):  # fmt: skip
            arguments.flag(value, name=name)
        arguments.optional(arguments.callback, say, name="say")
        arguments.callback(warn, name="warn")
        drills = choose(self.folder, which, cells=tuple(cells), warn=warn,
                        kept_code=kept_code, allow_changed_code=allow_changed_code,
                        trace_readers=TRACE_READERS, words=words)  # fmt: skip
        plans = [Plan(d.config, Path(folder) / f"{safe_name(d.name)}.mcap", None, drill=d)
                 for d in drills]  # fmt: skip
        todo = [p for p in plans if not up_to_date(p)]
        refuse(todo, force=force, hint=words.force)
        set_workers(1)  # one run has nothing to spread over threads
        for p in todo:
            d = p.drill
            assert d is not None  # each plan is a drill's
            if say is not None:
                say(f"recording {safe_text(p.mcap)} ({safe_text(d.config.instance_name)} "
                    f"{safe_text(d.cell or d.config.label)}, run {d.run}, seed "
                    f"{d.config.seed}, {d.choice})")  # fmt: skip
            record_drill(d, p.mcap, overwrite=True)
        return [Run(p.mcap) for p in plans]

    def figure(self, path: str | os.PathLike[str], *, log_x: bool = False,
               log_y: bool = False) -> Path:  # fmt: skip
        """Draw the sweep figure (regret against t, a line and 95% band per policy) from the
        sweep log to ``path`` (its extension picks the format); the ``plot`` extra."""
        arguments.path(path, name="path", what="the figure's path")
        arguments.flag(log_x, name="log_x")
        arguments.flag(log_y, name="log_y")
        draw_sweep_figure(self.log_path, path, log_x=log_x, log_y=log_y, force=True)
        return Path(path)

    def recordings(self) -> list[Path]:
        """The sweep's Rerun recording (``sweep.rrd``); for a grid's folder, each group's.
        Raises :class:`~corraoi.errors.LogError` for a folder without one."""
        from corraoi.errors import LogError

        from .viewing import checked_rrd

        if self.rrd is not None:
            return [checked_rrd(self.rrd)]
        groups = sorted(self.folder.glob("*/sweep.rrd"))
        if groups:
            return [checked_rrd(p) for p in groups]
        raise LogError(f"{self.folder}: no Rerun recording (sweep.rrd) in this sweep folder")

    def show(self, **options: Any) -> Shown:
        """The sweep's :meth:`recordings` in the Rerun viewer: :func:`corraoi.show` with the
        same ``options`` (in Jupyter a widget, elsewhere a web viewer on 127.0.0.1)."""
        from .viewing import open_viewer

        return open_viewer(self.recordings, **options)


    def __repr__(self) -> str:
        return f"Sweep({str(self.folder)!r})"

    def _repr_html_(self) -> str:
        summary = self.summary or {}
        rows = []
        for name, p in (summary.get("policies") or {}).items():
            if not isinstance(p, dict):
                continue

            def num(key: str, fmt: str, p: dict[str, Any] = p) -> str:
                v = p.get(key)
                return format(v, fmt) if isinstance(v, (int, float)) else ""

            rows.append((name, num("regret_mean", ",.1f"), num("regret_ci95", ",.1f"),
                         num("estimator_mean", ",.1f"), num("best_arm_share", ".3f")))  # fmt: skip
        head = ("policy", "AoI regret at T", "95% +-", "paper's estimator", "best-arm share")
        instance = summary.get("instance", "")
        if isinstance(instance, dict):  # summary.json holds the whole instance
            instance = instance.get("name", "")
        title = (f"{instance}, {summary.get('runs', '')} runs, "
                 f"T = {summary.get('horizon', '')}: {self.folder}")  # fmt: skip
        cells = "".join(f"<th>{html.escape(h)}</th>" for h in head)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in r) + "</tr>"
                       for r in rows)  # fmt: skip
        return f"<p>{html.escape(title)}</p><table><tr>{cells}</tr>{body}</table>"


def draw_sweep_figure(
    sweep_log: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    log_x: bool = False,
    log_y: bool = False,
    dpi: int = 150,
    split: bool = False,
    policies: Sequence[str] | None = None,
    force: bool = False,
    warn: Callable[[str], None] | None = None,
) -> tuple[Any, list[str]]:
    """``corraoi figure``: the sweep figure of the sweep log ``sweep_log`` to ``output`` (its
    extension picks the format), ``policies`` (names or comma lists; None: every one) in that
    order. The output's name, ``dpi`` and an existing ``output`` (without ``force``) are
    refused before the log is read; a sweep that did not finish is drawn up to its last
    checkpoint, said through ``warn``. Returns the sweep log read and the policies drawn.
    Raises :class:`~corraoi.errors.UsageError` for a bad output or policy,
    :class:`~corraoi.errors.LogError` for a log that cannot be read."""
    from corraoi.recorder.sweeplog.read import read_sweep
    from corraoi.viewer.figure import check_dpi, check_policies, draw_figure, figure_format

    out = Path(output)
    if out.is_dir():
        raise UsageError(f"{out}: is a directory; give a file name for the figure")
    figure_format(out)  # before reading the log: a wrong name is the first thing said
    check_dpi(dpi)
    if out.exists() and not force:
        raise UsageError(f"{out}: already exists (use --force to overwrite it)")
    sweep = read_sweep(sweep_log)
    wanted = [n.strip() for v in policies or () for n in v.split(",") if n.strip()]
    names = check_policies(sweep, wanted or None)
    if not sweep.complete and warn is not None:
        warn(f"{sweep_log}: the sweep did not finish ({sweep.status}); drawing the "
             f"{sweep.messages} checkpoint(s) it holds")  # fmt: skip
    draw_figure(sweep, out, log_x=log_x, log_y=log_y, dpi=dpi, split=split, policies=names)
    return sweep, names


def record_each_from(folder: str | os.PathLike[str], run: str, *, cells: Sequence[str] = (),
                     force: bool = False, kept_code: bool = False,
                     allow_changed_code: bool = False, say: Callable[[str], None] | None = None,
                     warn: Callable[[str], None] = python_warn) -> list[Run]:  # fmt: skip
    """``corraoi compare --from``: :meth:`Sweep.record_each` of the sweep folder ``folder``
    with ``run`` and the refusals in the command line's words (``--run``, ``--cell``). Raises
    :class:`~corraoi.errors.UsageError` for a bad ``run`` before the folder is read."""
    from corraoi.experiments.drill import parse_run
    from corraoi.experiments.folder import CLI_WORDS

    parse_run(run)  # a bad --run in the command line's words
    return Sweep(folder).record_each(run, cells=cells, force=force, kept_code=kept_code,
                                     allow_changed_code=allow_changed_code, say=say,
                                     warn=warn, words=CLI_WORDS)  # fmt: skip


def kept_code(folder: str | os.PathLike[str]) -> AbstractContextManager[list[str]]:
    """A context in which the plug-ins of the sweep in ``folder`` load from its kept copies
    (``--resume --kept-code``), entered before the grid is built."""
    from corraoi.experiments.kept_code import use_kept_code

    return use_kept_code(Path(folder), pin=True)


def grid_from_options(
    experiment: str | os.PathLike[str] | None,
    options: Mapping[str, Any],
    *,
    params: Sequence[str] = (),
    scalars: Mapping[str, float | None] | None = None,
    warn: Callable[[str], None] | None = None,
) -> Grid:
    """``corraoi sweep``'s grid: the experiment file ``experiment`` (TOML, if any) with the
    command line's ``options`` over it (``instances``, ``policies``, ``horizons``, ``runs``,
    ``seed``, ... a None left out), ``params`` (``NAME=v1,v2`` words) and ``scalars`` (``c``,
    ``beta``); every cell checked. Raises :class:`~corraoi.errors.ConfigError` (an error in
    the file names it), :class:`~corraoi.errors.InstanceError`,
    :class:`~corraoi.errors.PolicyError`."""
    from corraoi import limits
    from corraoi.experiments.grid import build_grid, parse_param_lists, read_experiment

    from .resolve import TRACE_READERS

    spec: dict[str, Any] = read_experiment(experiment) if experiment is not None else {}
    given_params = parse_param_lists(params)
    for key, value in (scalars or {}).items():
        if value is not None:
            given_params[key] = [value]
    chosen = dict(options)
    if chosen.get("sources") is not None:  # --sources M[,M...]: integers, or one line
        from corraoi.experiments.grid import parse_sources

        chosen["sources"] = parse_sources(chosen["sources"])
    if chosen.get("seed") == 0 and "seed" in spec:
        chosen["seed"] = None  # the file's seed unless one is given
    spec.update({k: v for k, v in chosen.items() if v is not None})
    spec.setdefault("instances", ["I1"])
    spec.setdefault("policies", ["all"])
    spec.setdefault("horizons", [10_000])
    spec.setdefault("runs", 200)
    spec["params"] = {**spec.get("params", {}), **given_params}
    limits.check_seed(spec.get("seed", 0), runs=int(spec["runs"]), name="--seed")
    try:
        return build_grid(**spec, warn=warn, trace_readers=TRACE_READERS)
    except CorraoiError as exc:
        if experiment is None:
            raise
        raise type(exc)(f"{experiment}: {exc}") from None


def grid_notes(grid: Grid) -> list[str]:
    """What to know about the grid's instances before it runs (one line each, the instance
    named when there are several)."""
    from corraoi.experiments.summary import instance_notes

    seen: dict[str, list[str]] = {}
    for cell in grid.cells:
        if cell.instance.name not in seen:
            seen[cell.instance.name] = instance_notes(cell.instance)
    return [f"{name}: {n}" if len(seen) > 1 else n for name, notes in seen.items() for n in notes]


def wrote_line(out: Path, outcome: SweepOutcome) -> str:
    """What a sweep into ``out`` wrote, by name: ``wrote sw/: manifest.json, ...`` and, for a
    grid of several groups, their folders with the files each holds; then the chunks run."""
    from corraoi.experiments.folder import GROUP_FILES

    def n(count: int, what: str) -> str:
        return f"{count} {what}{'' if count == 1 else 's'}"

    done = n(outcome.chunks_run, "chunk") + " run"
    if outcome.chunks_skipped:
        done += f", {outcome.chunks_skipped} already done"
    names = [f for f in ("manifest.json", "results.parquet", "plugins") if (out / f).exists()]
    folders = [p for p in outcome.folders if p != out]
    group = outcome.folders[0] if outcome.folders else out
    files = [f for f in GROUP_FILES if (group / f).exists()]
    if folders:
        names += [f"{p.relative_to(out)}/" for p in folders]
        return (f"wrote {out}/: {', '.join(names)}, each group folder with "
                f"{', '.join(files)} ({done})")  # fmt: skip
    return f"wrote {out}/: {', '.join(names + files)} ({done})"


def device_name(grid: Grid) -> str | None:
    """The GPU that runs ``grid`` (None for the CPU backend)."""
    if grid.backend != "gpu":
        return None
    from corraoi.gpu import get_device

    return str(get_device().name)


def paper_grid(*, runs: int, horizon: int, seed: int, backend: str = "cpu") -> Grid:
    """``corraoi reproduce``'s grid: the paper's instances and twelve policies."""
    from corraoi.experiments.sweeps import paper_grid as grid_of

    return grid_of(runs=runs, horizon=horizon, seed=seed, backend=backend)


def decentralized_grid(*, runs: int, horizon: int, seed: int, backend: str = "cpu") -> Grid:
    """``corraoi reproduce decentralized``'s grid (docs/decentralized.md)."""
    from corraoi.experiments.sweeps import decentralized_grid as grid_of

    return grid_of(runs=runs, horizon=horizon, seed=seed, backend=backend)


def write_paper_summary(out: Path, summaries: Sequence[dict[str, Any]], *, runs: int,
                        horizon: int, seed: int) -> list[str]:  # fmt: skip
    """``corraoi reproduce``'s ``out/summary.md``: the ranked table of each instance's sweep
    (``summaries``, in order) side by side. Returns the paper's instances (``out``'s
    folders)."""
    from corraoi.experiments.folder import write_text
    from corraoi.experiments.summary import summary_markdown
    from corraoi.experiments.sweeps import PAPER_INSTANCES

    parts = [summary_markdown(s).replace("# Sweep:", "## Sweep:", 1) for s in summaries]
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
    return list(PAPER_INSTANCES)


def check_which(which: object) -> int | str:
    """``which`` of :meth:`Sweep.record` and :meth:`Sweep.record_each`: a run index or
    ``worst``, ``median``, ``best`` (:func:`corraoi.arguments.index_or_word`)."""
    from corraoi.experiments.notable import CHOICES

    return arguments.index_or_word(which, name="which", words=CHOICES)


def settle_backend(grid: Grid, warn: Callable[[str], None] | None = None) -> Grid:
    """The grid with ``auto`` resolved (a notice through ``warn`` when it falls back to the
    CPU) and ``gpu`` checked (:class:`~corraoi.errors.GpuUnavailable` says why not)."""
    if grid.backend == "cpu":
        return grid
    from corraoi.experiments.backends import settle

    return settle(grid, None, warn=warn)


def _settle_and_say(grid: Grid, *, warn: Callable[[str], None] | None = None,
                   say: Callable[[str], None] | None = None) -> Grid:  # fmt: skip
    """:func:`settle_backend`, then ``say`` hears the GPU's name when one runs it."""
    grid = settle_backend(grid, warn=warn)
    name = device_name(grid)
    if name is not None and say is not None:
        say(f"backend gpu: {name}")
    return grid


def check_grid(grid: Grid, out: Path | None, *, allow_huge: bool = False) -> str:
    """Refuse, before anything runs, a grid that cannot be simulated or would not fit in
    memory, or one too large without ``allow_huge``; returns its size in words."""
    from corraoi import limits
    from corraoi.engine.problem import check_instance

    for cell in grid.cells:
        check_instance(cell.instance)
    # the biggest cell's runs x checkpoints are held at once when its results are joined (a
    # GPU sweep keeps every run's final values only)
    per_run = out is not None and grid.backend == "cpu"
    limits.check_sweep_memory(grid.runs, max(c.instance.K for c in grid.cells), policies=1,
                              checkpoints=grid.checkpoints if per_run else 0)  # fmt: skip
    run_slots = sum(int(c.horizon) for c in grid.cells) * int(grid.runs)
    return limits.check_sweep_size(len(grid.cells), grid.runs, run_slots, allow=allow_huge)


def run_grid(
    grid: Grid,
    *,
    out: str | os.PathLike[str] | None,
    scheduler: str | Any = None,
    resume: bool = False,
    force: bool = False,
    workers: int | None = None,
    on_slots: Callable[[int], None] | None = None,
    on_chunk: Callable[[int, int], None] | None = None,
    warn: Callable[[str], None] | None = None,
    figure_worker: bool = True,
    words: Words | None = None,
) -> SweepOutcome:
    """Run ``grid`` (:func:`corraoi.experiments.sweeps.sweep`) with every output a sweep folder
    has: the sweep logs, recordings, ``results.parquet`` and figures
    (:class:`~corraoi.face.outputs.FolderOutputs`). ``scheduler``: ``local:N``,
    ``tcp://HOST:PORT`` or a ``dask.distributed.Client`` (the ``cluster`` extra). Into a
    folder in this process, the figures are drawn by a forked process that imports matplotlib
    while the sweep runs (``figure_worker``). A complete folder of the same sweep is read at
    once (:func:`corraoi.experiments.sweeps.saved_outcome`). ``words``: how refusals name
    the options (the command line's unless told)."""
    from corraoi.experiments.backends import GPU_NOT_ON_CLUSTER
    from corraoi.experiments.folder import CLI_WORDS
    from corraoi.experiments.sweeps import saved_outcome
    from corraoi.experiments.sweeps import sweep as run_sweep

    words = words or CLI_WORDS
    folder = Path(out) if out is not None else None
    if scheduler is not None and grid.backend == "gpu":  # before a cluster is started
        raise ConfigError(GPU_NOT_ON_CLUSTER)
    if folder is not None and not force:  # nothing to run: no worker, no cluster started
        saved = saved_outcome(folder, grid, resume=resume, words=words)
        if saved is not None:
            return saved
    with ExitStack() as stack:
        outputs = None
        if folder is not None:
            from .outputs import FolderOutputs

            figures = None
            if scheduler is None and figure_worker:
                # the figures are drawn by a process that imports matplotlib now, while this
                # one runs the sweep and then writes the Rerun recordings
                # (viewer/figure_worker.py)
                from corraoi.viewer.figure_worker import FigureWorker

                figures = FigureWorker.start()
                if figures is not None:
                    stack.enter_context(figures)
            outputs = FolderOutputs(figures)
        client = None
        if isinstance(scheduler, str):
            from corraoi.experiments.cluster import connect

            client = stack.enter_context(connect(scheduler))
        elif scheduler is not None:
            client = scheduler  # a dask.distributed.Client of the caller's
        return run_sweep(grid, out=folder, client=client, resume=resume, force=force,
                         workers=workers, on_chunk=on_chunk, on_slots=on_slots, warn=warn,
                         outputs=outputs, words=words)  # fmt: skip


#: From this many run-slots (about a minute here) a sweep states its size before it starts.
SAY_SIZE_FROM = 10**9


@dataclass
class SweepRun:
    """What :func:`sweep_from_options` did: the grid run and its outcome (None when it was
    interrupted), what it wrote (one line, with ``out``) and, when Ctrl-C stopped it, what
    was kept (one line)."""

    grid: Grid
    outcome: SweepOutcome | None = None
    wrote: str | None = None
    interrupted: str | None = None


def sweep_from_options(
    experiment: str | os.PathLike[str] | None,
    options: Mapping[str, Any],
    *,
    params: Sequence[str] = (),
    scalars: Mapping[str, float | None] | None = None,
    out: Path | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    force: bool = False,
    workers: int | None = None,
    allow_huge: bool = False,
    kept: bool = False,
    hold: Callable[[AbstractContextManager[Any]], Any] | None = None,
    warn: Callable[[str], None] | None = None,
    say: Callable[[str], None] | None = None,
    progress: Callable[[int, str], Any] | None = None,
    before_folder: Callable[[], None] | None = None,
    label: str = "sweep",
) -> SweepRun:
    """``corraoi sweep`` from its parsed options: with ``kept`` the plug-ins of the sweep in
    ``out`` loaded from its copies (:func:`kept_code`, held by ``hold``), the grid
    (:func:`grid_from_options`), its backend settled (:func:`settle_backend`; ``say`` hears
    the GPU's name), checked (:func:`check_grid`; ``say`` hears the size of a sweep of
    :data:`SAY_SIZE_FROM` run-slots or more), the instances' notes (``warn``), then run
    (:func:`run_grid`) with ``progress(total, label)`` as the bar; ``before_folder()`` runs
    first when the folder is written in this process. Ctrl-C keeps the finished chunks and
    is reported in :attr:`SweepRun.interrupted`."""
    with ExitStack() as stack:
        if kept and out is not None:
            # while the sweep runs, before the grid is built: its plug-ins load from the copies
            (hold or stack.enter_context)(kept_code(out))
        grid = grid_from_options(experiment, options, params=params, scalars=scalars,
                                 warn=warn)  # fmt: skip
        grid = _settle_and_say(grid, warn=warn, say=say)
        size = check_grid(grid, out, allow_huge=allow_huge)
        run_slots = sum(int(c.horizon) for c in grid.cells) * int(grid.runs)
        if run_slots >= SAY_SIZE_FROM and say is not None:
            say(f"corraoi: sweep of {size}; the progress bar shows the time left")
        for note in grid_notes(grid):
            if warn is not None:
                warn(note)
        done = run_with_progress(grid, out=out, scheduler=scheduler, resume=resume,
                                 force=force, workers=workers, warn=warn, progress=progress,
                                 before_folder=before_folder, label=label)  # fmt: skip
    if done.outcome is not None and out is not None:
        done.wrote = wrote_line(out, done.outcome)
    return done


@dataclass
class ReproduceRun:
    """What :func:`reproduce_from_options` did: the grid run, each sweep's summary (one per
    instance of the paper; the one of ``decentralized``), the files and folders it wrote
    beside the sweeps, and, when Ctrl-C stopped it, what was kept (one line)."""

    grid: Grid
    summaries: list[dict[str, Any]]
    wrote: list[str]
    interrupted: str | None = None


def reproduce_from_options(
    which: str,
    *,
    out: Path,
    runs: int | None = None,
    horizon: int = 10_000,
    seed: int = 0,
    workers: int | None = None,
    force: bool = False,
    backend: str | None = None,
    warn: Callable[[str], None] | None = None,
    say: Callable[[str], None] | None = None,
    progress: Callable[[int, str], Any] | None = None,
    before_folder: Callable[[], None] | None = None,
) -> ReproduceRun:
    """``corraoi reproduce [paper|decentralized]`` from its parsed options: the grid
    (:func:`paper_grid`, 200 runs unless told; :func:`decentralized_grid`, its own count),
    its backend settled (``say`` hears the GPU's name), run into ``out`` with
    ``progress(total, label)`` as the bar (:func:`run_with_progress`), then ``paper``'s
    ``out/summary.md`` (:func:`write_paper_summary`) or ``decentralized``'s figure and
    table (:func:`corraoi.face.decentralized.write_decentralized`)."""
    from corraoi import limits

    from .decentralized import RUNS as DECENTRALIZED_RUNS
    from .decentralized import write_decentralized

    if which not in ("paper", "decentralized"):
        raise UsageError(f"reproduce {which!r}: expected paper or decentralized")
    paper = which == "paper"
    runs = runs if runs is not None else 200 if paper else DECENTRALIZED_RUNS
    limits.check_seed(seed, runs=runs, name="--seed")
    make = paper_grid if paper else decentralized_grid
    grid = _settle_and_say(make(runs=runs, horizon=horizon, seed=seed, backend=backend or "cpu"),
                          warn=warn, say=say)  # fmt: skip
    if paper:
        limits.check_sweep_memory(runs, 4, policies=1,
                                  checkpoints=grid.checkpoints if grid.backend == "cpu" else 0)
    done = run_with_progress(grid, out=out, force=force, workers=workers, warn=warn,
                             progress=progress, before_folder=before_folder,
                             label="reproduce" if paper else "reproduce decentralized")  # fmt: skip
    if done.outcome is None:
        return ReproduceRun(grid, [], [], interrupted=done.interrupted)
    summaries = list(done.outcome.summaries)
    if paper:
        wrote = [f"{n}/" for n in write_paper_summary(out, summaries, runs=runs,
                                                      horizon=horizon, seed=seed)]  # fmt: skip
        wrote.append("summary.md")
    else:
        wrote = ["the sweep folder", *write_decentralized(
            out, summaries[0], grid, runs=runs, horizon=horizon, seed=seed, warn=warn)]  # fmt: skip
    return ReproduceRun(grid, summaries, wrote)


def run_with_progress(
    grid: Grid,
    *,
    out: Path | None,
    scheduler: str | None = None,
    resume: bool = False,
    force: bool = False,
    workers: int | None = None,
    warn: Callable[[str], None] | None = None,
    progress: Callable[[int, str], Any] | None = None,
    before_folder: Callable[[], None] | None = None,
    label: str = "sweep",
) -> SweepRun:
    """Run ``grid`` (:func:`run_grid`) with ``progress(total, label)`` as the bar (slots in
    this process, chunks on a cluster); Ctrl-C keeps the finished chunks and says so in
    :attr:`SweepRun.interrupted`."""
    from contextlib import nullcontext

    if out is not None and scheduler is None and before_folder is not None:
        before_folder()
    if scheduler is None:
        total = sum(c.horizon for c in grid.cells) * grid.runs // grid.chunk_runs
        bar = progress(max(total, 1), label) if progress is not None else None
    else:
        bar = (progress(sum(-(-grid.runs // grid.chunk_runs) for _ in grid.cells),
                        f"{label} (chunks)") if progress is not None else None)  # fmt: skip

    def on_chunk(done: int, total: int) -> None:
        if bar is not None:
            bar.update(1, note=f"{done}/{total} chunks")

    try:
        with bar if bar is not None else nullcontext():
            outcome = run_grid(grid, out=out, scheduler=scheduler, resume=resume, force=force,
                               workers=workers, warn=warn,
                               on_slots=bar.update if scheduler is None and bar is not None
                               else None,
                               on_chunk=on_chunk if scheduler is not None else None)  # fmt: skip
    except KeyboardInterrupt:
        where = f"; finished chunks are saved in {out}: --resume continues" if out else ""
        return SweepRun(grid, interrupted=f"interrupted{where}")
    return SweepRun(grid, outcome)


def _listed(value: Any) -> list[Any]:
    if isinstance(value, (str, os.PathLike)) or not isinstance(value, Sequence):
        return [value]
    return list(value)


def sweep(
    instances: str | os.PathLike[str] | Instance | Sequence[str | os.PathLike[str] | Instance]
    = "I1",
    policies: PolicyLike | Sequence[PolicyLike] = "all",
    *,
    runs: int = 200,
    horizon: int | Sequence[int] = 10_000,
    seed: int = 0,
    params: Mapping[str, Any] | None = None,
    out: str | os.PathLike[str] | None = None,
    backend: str = "cpu",
    scheduler: str | Any = None,
    channel: str | None = None,
    baseline: str | None = None,
    chunk: int = 0,
    checkpoints: int = 200,
    resume: bool = False,
    force: bool = False,
    workers: int | None = None,
    allow_huge: bool = False,
    on_slots: Callable[[int], None] | None = None,
    sources: int | Sequence[int] = 1,
) -> Sweep:
    """Run every policy over the same paired seeds (runs ``seed .. seed + runs - 1``) on every
    instance and horizon, as ``corraoi sweep -o DIR`` does; returns the :class:`Sweep`.

    ``instances``, ``policies``: one or a list (policies as for :func:`corraoi.record`;
    ``"all"`` is the paper's twelve); ``runs`` paired runs of ``horizon`` slots (a list of
    horizons makes a grid); ``seed``: the first run's. ``params``: ``{name: value or
    [values]}`` or ``{policy: {name: ...}}``; several values make a grid. ``channel``:
    ``iid``, ``markov`` or ``trace:PATH``; ``baseline``: a policy whose paired differences the
    others get; ``chunk``: runs per chunk (0: chosen for you); ``checkpoints``: slots at
    which every run's regret is kept.

    ``out``: the sweep folder (None: a temporary one, removed with the returned Sweep);
    ``resume``: continue or extend the sweep in ``out``; ``force``: replace another sweep
    there. ``backend``: ``cpu``, ``gpu`` or ``auto``; ``scheduler``: ``local:N``,
    ``tcp://HOST:PORT`` or a Dask ``Client`` (policies defined in your own session run in this
    process only); ``workers``: the engine's threads here. ``allow_huge``: run a grid over
    the size limit. ``on_slots(n)`` as runs advance. ``sources``: the number of sources
    sharing the channels, or a list of them (each a cell; several need a multi-source
    policy, ``rhorand-ucb`` say: docs/decentralized.md).

    Raises the errors of :func:`corraoi.record` for bad input,
    :class:`~corraoi.errors.GpuUnavailable`, :class:`~corraoi.errors.ConfigError` (a grid too
    large, a folder that holds another sweep) and :class:`~corraoi.errors.ClusterError`.
    Ctrl-C (KeyboardInterrupt) keeps the finished chunks: ``resume=True`` continues.
    """
    from corraoi import limits
    from corraoi.experiments.folder import PYTHON_WORDS
    from corraoi.experiments.grid import BACKENDS, build_grid

    from . import resolve

    # the arguments checked before anything is done (corraoi.arguments)
    if isinstance(instances, (list, tuple)) and not instances:
        raise arguments.wrong_value(InstanceError, "instances", instances,
                                    "at least one instance", "empty")  # fmt: skip
    if isinstance(horizon, (list, tuple)) and not horizon:
        raise arguments.wrong_value(ConfigError, "horizon", horizon, "at least one horizon",
                                    "empty")  # fmt: skip
    runs = limits.check_int(runs, name="runs", lo=1, hi=limits.MAX_RUNS, floats=True)
    horizon = [limits.check_horizon(h, name="horizon" if not isinstance(horizon, (list, tuple))
                                    else f"horizon[{i}]", floats=True)
               for i, h in enumerate(_listed(horizon))]  # fmt: skip
    seed = limits.check_seed(seed, runs=runs, floats=True)
    arguments.optional(arguments.path, out, name="out", what="the sweep folder's path")
    arguments.text(backend, name="backend", kind=ConfigError, choices=BACKENDS)
    if scheduler is not None and not (isinstance(scheduler, str) or hasattr(scheduler, "submit")):
        raise arguments.wrong_type(ConfigError, "scheduler", scheduler, "'local:N', "
                                   "'tcp://HOST:PORT', a dask.distributed.Client or None")
    arguments.optional(arguments.text, scheduler if isinstance(scheduler, str) else None,
                       name="scheduler", kind=ConfigError,
                       expected="'local:N', 'tcp://HOST:PORT', a dask.distributed.Client or None")
    resolve.channel_word(channel)
    arguments.optional(arguments.text, baseline, name="baseline", kind=PolicyError,
                       expected="the name of one of the swept policies")  # fmt: skip
    chunk = limits.check_int(chunk, name="chunk", lo=0, hi=limits.MAX_RUNS, floats=True,
                             why="runs per chunk; 0 chooses")  # fmt: skip
    checkpoints = limits.check_int(checkpoints, name="checkpoints", lo=2,
                                   hi=limits.MAX_CHECKPOINTS, floats=True)  # fmt: skip
    for name, value in (("resume", resume), ("force", force), ("allow_huge", allow_huge)):
        arguments.flag(value, name=name)
    workers = arguments.optional(limits.check_int, workers, name="workers", lo=1,
                                 hi=limits.MAX_WORKERS, floats=True)  # fmt: skip
    arguments.optional(arguments.callback, on_slots, name="on_slots")
    counts = [arguments.integer(m, name="sources" if not isinstance(sources, (list, tuple))
                                else f"sources[{i}]", lo=1, kind=ConfigError, floats=False,
                                why="at most the number of arms")
              for i, m in enumerate(_listed(sources))]  # fmt: skip
    insts = [resolve.instance(i) for i in _listed(instances)]
    words, scoped = resolve.policy_words(policies, params, "policies")
    horizons = [int(h) for h in _listed(horizon)]
    given = {k: v if isinstance(v, list) else [v]
             for k, v in {**scoped, **resolve.flat_params(params, several=True)}.items()}
    limits.check_seed(seed, runs=int(runs), name="seed")
    grid = build_grid(instances=insts, policies=words, horizons=horizons, params=given,
                      runs=runs, seed=seed, chunk=chunk, checkpoints=checkpoints,
                      channel=channel, trace_readers=resolve.TRACE_READERS, baseline=baseline,
                      backend=backend, sources=counts, warn=python_warn)  # fmt: skip
    grid = settle_backend(grid, warn=python_warn)
    temporary = out is None
    folder = Path(tempfile.mkdtemp(prefix="corraoi-sweep-")) if out is None else Path(out)
    check_grid(grid, folder, allow_huge=allow_huge)
    try:
        run_grid(grid, out=folder, scheduler=scheduler, resume=resume, force=force,
                 workers=workers, on_slots=on_slots, warn=python_warn,
                 words=PYTHON_WORDS)  # fmt: skip
    except BaseException:
        if temporary:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    result = Sweep(folder)
    if temporary:
        weakref.finalize(result, shutil.rmtree, str(folder), True)
    return result


__all__ = [
    "SAY_SIZE_FROM", "ReproduceRun", "Sweep", "SweepRun", "check_grid", "decentralized_grid",
    "device_name", "draw_sweep_figure", "grid_from_options", "grid_notes", "kept_code",
    "paper_grid", "record_each_from", "reproduce_from_options", "run_grid", "run_with_progress",
    "settle_backend", "sweep", "sweep_from_options", "write_paper_summary", "wrote_line",
]  # fmt: skip
