"""Hidden-state processes (channels): i.i.d., Markov, and a replayed trace.

* ``iid``: X_t ~ p independently (the paper's model; the default for instances without a
  ``transition`` matrix).
* ``markov``: X_1 ~ p, then X_t from row X_{t-1} of the instance's ``transition`` matrix, by
  one uniform per slot through the row's inverse CDF -- so a chain whose rows all equal ``p``
  draws exactly the i.i.d. path (the default for instances with a ``transition``).
* ``trace``: the states of a recorded hidden path (an array: :func:`trace_channel`), read from
  a text file of 1-based states (whitespace-separated, ``#`` comments) or a corraoi slot log
  (``.mcap``); every run of a batch replays the same path.

A channel is data (logged with the run); :meth:`Channel.kernel_arrays` is what the engine needs.
The core reads text traces only: a reader of any other file is handed in by the caller
(``readers``, by suffix), as the top floor hands the recorder's slot-log reader
(``corraoi/face/resolve.py``).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from corraoi.errors import ConfigError, ConfigValueError

from .instance import Instance

KINDS = ("iid", "markov", "trace")
#: Kernel codes (corraoi.engine._kernel.CHANNEL_CDF / CHANNEL_TRACE).
_CDF, _TRACE = 0, 1
#: A text trace larger than this is refused before reading.
MAX_TRACE_BYTES = 1 << 30
#: A reader of trace files that are not text: ``(path, instance, where) -> states`` (0-based
#: int64), raising ConfigError.
TraceReader = Callable[[Path, Instance, str], np.ndarray]


@dataclass(frozen=True, eq=False)
class Channel:
    """How the hidden state evolves. ``trace`` holds 0-based states for kind ``trace``."""

    kind: str = "iid"
    source: str = ""
    trace: np.ndarray | None = field(default=None, repr=False)
    digest: str = ""
    length: int = 0  # slots of the trace (kept when a log's channel comes without its states)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Channel):
            return NotImplemented
        return (self.kind, self.source, self.digest) == (other.kind, other.source, other.digest)

    def __hash__(self) -> int:
        return hash((self.kind, self.source, self.digest))

    @property
    def iid(self) -> bool:
        return self.kind == "iid"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind == "trace":
            length = int(self.trace.size) if self.trace is not None else self.length
            out.update(source=self.source, digest=self.digest, length=length)
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, where: str = "channel") -> Channel:
        kind = data.get("kind") if isinstance(data, Mapping) else None
        if kind not in KINDS:
            raise ConfigError(f"{where}: unknown channel kind {kind!r} (expected {KINDS})")
        if kind != "trace":
            return cls(kind=kind)
        # The states themselves are the log's x column; the config names where they came from.
        length = data.get("length", 0)
        return cls(kind="trace", source=str(data.get("source", "")),
                   digest=str(data.get("digest", "")),
                   length=length if isinstance(length, int) else 0)  # fmt: skip

    def describe(self) -> str:
        if self.kind == "trace":
            return f"trace from {self.source}"
        return self.kind

    def check(self, instance: Instance, horizon: int) -> None:
        """ConfigError when this channel cannot drive ``instance`` for ``horizon`` slots."""
        transition = getattr(instance, "transition", None)
        if self.kind == "markov" and transition is None:
            raise ConfigError(
                f"channel markov: instance {instance.name} has no transition matrix"
            )
        if self.kind == "trace":
            if self.trace is None:
                raise ConfigError(f"channel trace {self.source}: the trace itself is not loaded")
            if self.trace.size < horizon:
                raise ConfigError(
                    f"channel trace {self.source}: {self.trace.size} slots, shorter than the "
                    f"horizon {horizon} (use -T {self.trace.size} or a longer trace)"
                )
            top = int(self.trace.max()) if self.trace.size else -1
            if self.trace.size and (int(self.trace.min()) < 0 or top >= instance.n_states):
                bad = int(np.flatnonzero((self.trace < 0) | (self.trace >= instance.n_states))[0])
                raise ConfigError(
                    f"channel trace {self.source}: slot {bad + 1} has state "
                    f"{int(self.trace[bad]) + 1}, but instance {instance.name} has states "
                    f"1..{instance.n_states}"
                )

    def kernel_arrays(self, instance: Instance) -> tuple[np.ndarray, int, np.ndarray]:
        """(cdf_rows, kind code, trace) for the compiled kernel."""
        first = np.cumsum(instance.p)[None, :]
        if self.kind == "trace":
            assert self.trace is not None
            return first, _TRACE, np.ascontiguousarray(self.trace, dtype=np.int64)
        empty = np.zeros(1, dtype=np.int64)
        if self.kind == "markov":
            transition = np.asarray(instance.transition, dtype=np.float64)
            rows = np.vstack([first, np.cumsum(transition, axis=1)])
            return np.ascontiguousarray(rows), _CDF, empty
        return np.ascontiguousarray(first), _CDF, empty


def _digest(trace: np.ndarray) -> str:
    data = np.ascontiguousarray(trace, np.int64).tobytes()
    return "sha256:" + hashlib.sha256(data).hexdigest()[:16]


def default_channel(instance: Instance) -> Channel:
    """Markov for an instance with a transition matrix, else i.i.d."""
    return Channel("markov") if getattr(instance, "transition", None) is not None else Channel()


def parse_channel(
    spec: str | None, instance: Instance, *, readers: Mapping[str, TraceReader] | None = None
) -> Channel:
    """``--channel`` value: ``iid``, ``markov``, ``trace:PATH`` (or None for the default).
    ``readers``: readers of trace files that are not text, by suffix (``.mcap``)."""
    if spec is None or not spec.strip():
        return default_channel(instance)
    text = spec.strip()
    if text in ("iid", "markov"):
        ch = Channel(text)
        ch.check(instance, 1)
        return ch
    if text.startswith("trace:"):
        return load_trace(text[len("trace:") :], instance, readers=readers)
    raise ConfigValueError(
        f"--channel {spec!r}: expected iid, markov or trace:PATH (a .mcap slot log or a text "
        "file of 1-based states)"
    )


def trace_channel(states: Any, source: str, instance: Instance) -> Channel:
    """A trace channel replaying ``states`` (0-based), checked against ``instance``;
    ``source`` says where they came from (logged with the run)."""
    arr = np.asarray(states)
    if arr.size == 0:
        raise ConfigError(f"channel trace:{source}: the trace holds no state")
    if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer):
        raise ConfigError(f"channel trace:{source}: expected a 1-D array of integer states")
    arr = arr.astype(np.int64)
    ch = Channel(kind="trace", source=str(source), trace=arr, digest=_digest(arr))
    ch.check(instance, 1)
    return ch


def load_trace(
    path_text: str, instance: Instance, *, readers: Mapping[str, TraceReader] | None = None
) -> Channel:
    """A trace channel from a text file of 1-based states, or a file one of ``readers`` (by
    suffix) reads: a corraoi slot log where the caller hands the recorder's reader."""
    path = Path(path_text).expanduser()
    where = f"channel trace:{path_text}"
    if not path_text:
        raise ConfigError(f"{where}: empty path")
    if not path.exists():
        raise ConfigError(f"{where}: no such file")
    if not path.is_file():
        raise ConfigError(f"{where}: not a regular file")
    suffix = ".mcap" if path.name.endswith(".mcap.partial") else path.suffix
    reader = (readers or {}).get(suffix)
    if reader is not None:
        states = reader(path, instance, where)
    else:
        states = _text_states(path, instance, where)
    if len(states) == 0:
        raise ConfigError(f"{where}: the trace holds no state")
    return trace_channel(states, str(path_text), instance)


def _text_states(path: Path, instance: Instance, where: str) -> np.ndarray:
    if os.path.getsize(path) > MAX_TRACE_BYTES:
        raise ConfigError(f"{where}: larger than {MAX_TRACE_BYTES} bytes")
    values: list[int] = []
    try:
        with open(path, encoding="utf-8") as f:
            for lineno, line in enumerate(f, start=1):
                for tok in line.split("#", 1)[0].replace(",", " ").split():
                    try:
                        values.append(int(tok) - 1)
                    except ValueError:
                        raise ConfigError(
                            f"{where}:{lineno}: state {tok!r} is not an integer "
                            f"(expected 1..{instance.n_states})"
                        ) from None
    except UnicodeDecodeError:
        raise ConfigError(
            f"{where}: not a text file of 1-based states (a slot log is read by corraoi "
            "record, corraoi sweep and corraoi.record)"
        ) from None
    return np.asarray(values, dtype=np.int64)
