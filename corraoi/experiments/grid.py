"""Grids of experiments: cells (instance x policy x parameters x horizon), runs and chunks.

A **cell** is one (instance, policy with its parameter values, horizon, channel). Every cell
runs the same seeds ``seed .. seed + runs - 1`` (run i uses seed + i, exactly what
``corraoi record --seed`` would take), so all policies and parameter values at one instance
see the same hidden paths. A cell's runs are split into **chunks** of consecutive runs, the
unit of work that runs anywhere (in this process or on a Dask worker) and is saved as soon as
it finishes.

A grid comes from the command line (comma lists) or from an experiment file (TOML or JSON)
with the same keys::

    instances = ["I1", "I2", "my-instance.toml"]
    policies = ["ucb", "cucb", "sw-ucb"]
    horizons = [10000]
    runs = 200
    seed = 0
    chunk = 50            # runs per chunk (default: all runs of a cell in one chunk)
    checkpoints = 200     # about this many checkpoint slots per curve
    channel = "iid"       # optional: iid, markov or trace:PATH
    baseline = "ucb"      # optional: paired differences against this policy
    sources = [1, 2, 3]   # optional: sources sharing the channels, each a cell (multi-source
                          # policies only, e.g. rhorand-ucb; docs/model.md, "Many sources")

    [params]              # each list is swept; a value goes to the policies declaring it
    c = [1.0, 2.0]
    window = [100, 500]
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import os
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from corraoi.errors import ConfigError, CorraoiError
from corraoi.limits import check_horizon, check_seed
from corraoi.model.channels import Channel, TraceReader, parse_channel
from corraoi.model.instance import Instance, load_instance
from corraoi.policies import PolicySpec, make_policy, parse_policy_names, resolve
from corraoi.policies.spec import assign_params, check_sources, param_key
from corraoi.text import split_list

#: Keys an experiment file may hold.
FILE_KEYS = ("instances", "policies", "horizons", "runs", "seed", "chunk", "checkpoints",
             "channel", "baseline", "backend", "sources", "params")  # fmt: skip
#: Where a grid's cells can run (``backend``; docs/gpu.md).
BACKENDS = ("cpu", "gpu", "auto")
#: An experiment file larger than this is refused before it is read.
MAX_FILE_BYTES = 4 << 20
#: The most cells one grid may hold.
MAX_CELLS = 100_000


@dataclass(frozen=True, eq=False)
class Cell:
    """One instance x policy (with its parameter values) x horizon x channel x number of
    sources sharing the channels (1: today's single source)."""

    instance: Instance
    policy: PolicySpec
    horizon: int
    channel: Channel = field(default_factory=Channel)
    sources: int = 1

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "instance": self.instance.to_dict(),
            "policy": self.policy.to_dict(),
            "horizon": int(self.horizon),
        }
        if not self.channel.iid:
            out["channel"] = self.channel.to_dict()
        if self.sources != 1:  # a single source's cell (and its key) as before
            out["sources"] = int(self.sources)
        return out

    @property
    def many(self) -> bool:
        """Whether the cell runs in the engine of many sources: several sources, or a
        multi-source policy (one source of it is its base policy, run for run)."""
        return self.sources > 1 or bool(getattr(self.policy.resolve(), "multi_source", None))

    @property
    def key(self) -> str:
        """A stable identifier of the cell (a hash of what determines its runs; a plug-in's
        full sha256 is left out, so that folders swept before it was recorded keep their
        keys: its version holds the first 16 digits)."""
        d = self.to_dict()
        d["policy"].get("plugin", {}).pop("sha256", None)
        text = json.dumps(d, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    @property
    def params_json(self) -> str:
        return json.dumps({k: float(v) for k, v in self.policy.params.items()}, sort_keys=True)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Cell) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)


@dataclass(frozen=True)
class Chunk:
    """Runs ``start .. stop - 1`` of one cell (seeds ``seed + start ..``)."""

    cell: str  # Cell.key
    start: int
    stop: int

    @property
    def name(self) -> str:
        return f"{self.cell}-{self.start:09d}-{self.stop:09d}"


@dataclass(frozen=True, eq=False)
class Grid:
    """Cells and the runs they share."""

    cells: tuple[Cell, ...]
    runs: int
    seed: int = 0
    chunk: int = 0  # runs per chunk; 0: all runs of a cell in one chunk
    checkpoints: int = 200
    baseline: str | None = None
    #: Where the cells run: "cpu" (the engine), "gpu" (corraoi.gpu), or "auto" (resolved to
    #: one of them by :func:`corraoi.experiments.backends.settle` before the sweep starts).
    backend: str = "cpu"

    def __post_init__(self) -> None:
        if not self.cells:
            raise ConfigError("the grid has no cell (expected at least one instance and policy)")
        if len(self.cells) > MAX_CELLS:
            raise ConfigError(f"the grid has {len(self.cells)} cells; at most {MAX_CELLS}")
        if len({c.key for c in self.cells}) != len(self.cells):
            raise ConfigError("the grid names the same cell twice")
        if not isinstance(self.runs, int) or self.runs < 1:
            raise ConfigError(f"runs must be an integer >= 1, got {self.runs!r}")
        check_seed(self.seed, runs=self.runs)
        if not isinstance(self.chunk, int) or self.chunk < 0:
            raise ConfigError(f"chunk must be an integer >= 1 (runs per chunk), got {self.chunk!r}")
        if self.checkpoints < 2:
            raise ConfigError(f"checkpoints must be >= 2, got {self.checkpoints}")
        if self.backend not in BACKENDS:
            raise ConfigError(
                f"backend {self.backend!r}: expected one of {', '.join(BACKENDS)}"
            )

    @property
    def chunk_runs(self) -> int:
        return self.chunk or self.runs

    def groups(self) -> dict[tuple[str, int], list[Cell]]:
        """Cells by (instance name, horizon), in grid order: one sweep log and figure each."""
        out: dict[tuple[str, int], list[Cell]] = {}
        for c in self.cells:
            out.setdefault((c.instance.name, c.horizon), []).append(c)
        return out

    def chunks(self, cell: Cell, *, covered: Iterable[tuple[int, int]] = ()) -> list[Chunk]:
        """The chunks of ``cell`` that cover its runs not in ``covered`` (run ranges done)."""
        done = sorted(covered)
        out: list[Chunk] = []
        start = 0
        size = self.chunk_runs
        for lo, hi in [*done, (self.runs, self.runs)]:
            while start < min(lo, self.runs):
                stop = min(start + size, lo, self.runs)
                out.append(Chunk(cell.key, start, stop))
                start = stop
            start = max(start, hi)
        return out

    def labels(self) -> dict[str, str]:
        """A display label per cell key, unique within its group: the policy name, with its
        parameter values when one policy runs with several in the group, and the start of
        the cell's key when two cells still read alike (one name from two files, say)."""
        out: dict[str, str] = {}
        for cells in self.groups().values():
            # a policy's parameter values when it runs with several; the number of sources
            # (M=3) when a cell of the group has several
            counts = Counter((c.policy.name, c.sources) for c in cells)
            shown_m = any(c.sources > 1 for c in cells)
            for c in cells:
                ps, name = ",".join(f"{k}={v:g}" for k, v in c.policy.params.items()), c.policy.name
                words = [ps] if counts[name, c.sources] > 1 else []
                words += [f"M={c.sources}"] if shown_m else []
                out[c.key] = f"{name}({','.join(words)})" if words else name
            alike = Counter(out[c.key] for c in cells)
            for c in cells:
                if alike[out[c.key]] > 1:
                    out[c.key] += f"@{c.key[:8]}"
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "cells": [c.to_dict() for c in self.cells],
            "runs": self.runs,
            "seed": self.seed,
            "chunk": self.chunk,
            "checkpoints": self.checkpoints,
            "baseline": self.baseline,
            # only when not the CPU: folders swept before backends existed read the same
            **({"backend": self.backend} if self.backend != "cpu" else {}),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "manifest") -> Grid:
        from corraoi.engine.block import RunConfig

        try:
            cells = []
            for d in data["cells"]:
                cfg = RunConfig.from_dict({**d, "seed": 0})
                assert cfg.channel is not None
                cells.append(Cell(cfg.model, cfg.policy, cfg.horizon, cfg.channel,
                                  cfg.sources))
            return cls(
                cells=tuple(cells), runs=int(data["runs"]), seed=int(data["seed"]),
                chunk=int(data.get("chunk", 0)), checkpoints=int(data.get("checkpoints", 200)),
                baseline=data.get("baseline"), backend=str(data.get("backend", "cpu")),
            )  # fmt: skip
        except CorraoiError:  # typed already (a policy, an instance, a setting): as it is
            raise
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(
                f"{where}: not a corraoi grid ({type(exc).__name__}: {exc})"
            ) from None


def parse_param_lists(items: Iterable[str]) -> dict[str, list[float]]:
    """``--param NAME=v1,v2`` words into NAME -> values (the grid sweeps each list)."""
    out: dict[str, list[float]] = {}
    for item in items:
        name, sep, text = str(item).partition("=")
        if not sep:
            raise ConfigError(f"--param {item!r}: expected NAME=VALUE[,VALUE...] (e.g. c=1,2)")
        name = param_key(str(item), name, "c=1,2")
        values = []
        for tok in text.split(","):
            try:
                v = float(tok)
            except ValueError:
                raise ConfigError(f"--param {item!r}: {tok.strip()!r} is not a number") from None
            values.append(v)
        out[name] = values
    return out


def build_grid(
    *,
    instances: Sequence[str | Instance],
    policies: Sequence[str],
    horizons: Sequence[int],
    params: Mapping[str, Sequence[float]] | None = None,
    runs: int,
    seed: int = 0,
    chunk: int = 0,
    checkpoints: int = 200,
    channel: str | None = None,
    trace_readers: Mapping[str, TraceReader] | None = None,
    baseline: str | None = None,
    backend: str = "cpu",
    sources: Sequence[int] | None = None,
    warn: Callable[[str], None] | None = None,
) -> Grid:
    """The grid of every instance x policy x parameter combination x horizon x number of
    sources (``sources``: each M in 1..K a cell; a single-source policy with M > 1 is
    refused, one line naming its multi-source forms).

    Each parameter list goes to every policy that declares the parameter, or to one policy
    for ``POLICY.NAME`` (:func:`~corraoi.policies.spec.assign_params`; the product over the
    parameters a policy takes); a parameter that no listed policy declares is an error, as
    is a value outside its declared range.
    """
    if not instances:
        raise ConfigError("no instance given (expected a name, a file, or a comma list)")
    if not horizons:
        raise ConfigError("no horizon given")
    for h in horizons:
        check_horizon(h)
    params = {k: list(v) for k, v in (params or {}).items()}
    for name, values in params.items():
        if not values:
            raise ConfigError(f"parameter {name}: no value given")
    tokens = parse_policy_names(policies)
    classes = {t: resolve(t).cls for t in tokens}
    each = assign_params(tokens, classes, params, warn=warn)  # NAME or POLICY.NAME
    specs: list[PolicySpec] = []
    for t in tokens:
        declared = list(each[t])
        for combo in itertools.product(*(each[t][p] for p in declared)):
            specs.append(make_policy(t, **dict(zip(declared, combo, strict=True))))
    counts = list(dict.fromkeys(check_sources_list(sources)))
    for spec in specs:
        for m in counts:
            check_sources(spec, m, spec.resolve())
    cells = []
    for spec_text in instances:
        inst = load_instance(spec_text)
        chan = parse_channel(channel, inst, readers=trace_readers)
        for m in counts:
            if m > inst.K:
                raise ConfigError(f"sources {m}: expected an integer from 1 to the number of "
                                  f"arms of {inst.name}, {inst.K}")  # fmt: skip
        for h in horizons:
            chan.check(inst, int(h))
            for spec in specs:
                for m in counts:
                    cells.append(Cell(inst, spec, int(h), chan, m))
    # a value given twice (-i I1,I1, horizons [50, 50], one instance by two spellings) is one
    # cell, as a policy or a number of sources given twice already were
    first: dict[str, Cell] = {}
    for c in cells:
        first.setdefault(c.key, c)
    cells = list(first.values())
    if baseline is not None and baseline not in {s.name for s in specs}:
        raise ConfigError(
            f"--baseline {baseline}: not one of the swept policies "
            f"({', '.join(dict.fromkeys(s.name for s in specs))}); expected one of them"
        )
    return Grid(tuple(cells), runs=int(runs), seed=int(seed), chunk=int(chunk),
                checkpoints=int(checkpoints), baseline=baseline, backend=backend)  # fmt: skip


def check_sources_list(values: Sequence[Any] | None) -> list[int]:
    """The numbers of sources of a grid (``--sources``, the file's ``sources``): integers
    >= 1, else a ConfigError naming the value (None: one source)."""
    if values is None:
        return [1]
    out = []
    for v in values:
        if type(v) is not int or v < 1:
            raise ConfigError(f"sources {v!r}: expected an integer from 1 to the number of arms")
        out.append(v)
    if not out:
        raise ConfigError("sources: no value given (expected integers from 1 to the number "
                          "of arms)")  # fmt: skip
    return out


def parse_sources(words: Iterable[str]) -> list[int] | None:
    """``--sources M[,M...]`` words as integers (None: none given), else a ConfigError naming
    the word."""
    words = list(words)
    out: list[int] = []
    for word in split_list(words):
        try:
            out.append(int(word))
        except ValueError:
            raise ConfigError(f"--sources {word!r}: expected an integer from 1 to the number "
                              "of arms (a comma list sweeps each)") from None  # fmt: skip
    if words and not out:  # --sources '' (an empty shell variable): never the default
        raise ConfigError(f"--sources {','.join(words)!r}: no value given (expected an "
                          "integer from 1 to the number of arms; a comma list sweeps each)")
    return out or None


def read_experiment(path: str | os.PathLike[str]) -> dict[str, Any]:
    """An experiment file (TOML or JSON) as a dict of the :data:`FILE_KEYS`, checked."""
    p = Path(path)
    where = str(path)
    if not p.exists():
        raise ConfigError(f"{where}: no such experiment file")
    if not p.is_file():
        raise ConfigError(f"{where}: not a regular file (expected a .toml or .json experiment)")
    if p.stat().st_size > MAX_FILE_BYTES:
        raise ConfigError(f"{where}: larger than {MAX_FILE_BYTES} bytes")
    try:
        raw = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{where}: cannot read the experiment file: {exc}") from None
    try:
        if p.suffix.lower() == ".json":
            data = json.loads(raw)
        else:
            import tomllib

            data = tomllib.loads(raw)
    except RecursionError:
        raise ConfigError(f"{where}: nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError and TOMLDecodeError are ValueErrors
        raise ConfigError(f"{where}: invalid {p.suffix.lstrip('.').upper() or 'TOML'}: "
                          f"{exc}") from None  # fmt: skip
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a table of keys ({', '.join(FILE_KEYS)})")
    unknown = sorted(set(data) - set(FILE_KEYS))
    if unknown:
        raise ConfigError(
            f"{where}: unknown key {unknown[0]!r} (expected: {', '.join(FILE_KEYS)})"
        )

    def strings(key: str) -> list[str]:
        v = data.get(key)
        if isinstance(v, str):
            return split_list([v])
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise ConfigError(f"{where}: {key} must be a list of strings")
        return split_list(v)

    def integer(key: str, default: int | None) -> int:
        v = data.get(key, default)
        if not isinstance(v, int) or isinstance(v, bool):
            raise ConfigError(f"{where}: {key} must be an integer, got {v!r}")
        return v

    out: dict[str, Any] = {}
    for key in ("instances", "policies"):
        if key not in data:
            raise ConfigError(f"{where}: missing key {key!r}")
        out[key] = strings(key)
    hs = data.get("horizons", [10_000])
    hs = [hs] if isinstance(hs, int) and not isinstance(hs, bool) else hs
    if not isinstance(hs, list) or not all(isinstance(h, int) and not isinstance(h, bool)
                                           for h in hs):  # fmt: skip
        raise ConfigError(f"{where}: horizons must be a list of integers")
    out["horizons"] = hs
    out["runs"] = integer("runs", 200)
    out["seed"] = integer("seed", 0)
    out["chunk"] = integer("chunk", 0)
    out["checkpoints"] = integer("checkpoints", 200)
    if "sources" in data:
        m = data["sources"]
        try:
            out["sources"] = check_sources_list([m] if not isinstance(m, list) else m)
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
    for key in ("channel", "baseline", "backend"):
        v = data.get(key)
        if v is not None and not isinstance(v, str):
            raise ConfigError(f"{where}: {key} must be a string")
        out[key] = v
    if out["backend"] is None:
        del out["backend"]
    params = data.get("params", {})
    if not isinstance(params, dict):
        raise ConfigError(f"{where}: params must be a table of name = [values]")
    clean: dict[str, list[float]] = {}
    for name, values in params.items():
        vals = values if isinstance(values, list) else [values]
        if not vals or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in vals
        ):
            raise ConfigError(f"{where}: params.{name} must be a number or a list of numbers")
        clean[str(name)] = [float(v) for v in vals]
    out["params"] = clean
    return out


def grid_from_file(path: str | os.PathLike[str], **overrides: Any) -> Grid:
    """The grid of an experiment file (``overrides``: values the command line gives)."""
    spec = read_experiment(path)
    spec.update({k: v for k, v in overrides.items() if v is not None})
    return build_grid(**spec)
