"""Correlated bandit instances: the distribution ``p`` of the hidden state and the 0/1 table ``Y``.

Internally arms and states are numbered from 0; everything a person or a file sees numbers
them from 1 (``arm_names`` default to ``"1".."K"``).

Two file formats are read:

* the community text format: line 1 is ``p`` (space-separated), then one line per arm with
  ``Y_k(x)`` as space-separated 0/1 (blank lines and ``#`` comments are ignored);
* JSON (``.json``) or TOML (``.toml``), self-describing::

      name = "I1"
      p = [0.2, 0.3, 0.3, 0.2]
      Y = [[1, 0, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [0, 0, 0, 1]]
      arms = ["los", "nlos-a", "nlos-b", "relay"]      # optional
      states = ["clear", "rain", "fog", "crowd"]      # optional
"""

from __future__ import annotations

import json
import math
import os
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from corraoi.errors import InstanceError, InstanceValueError

P_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class Instance:
    """A validated correlated bandit instance. ``Y`` has shape (K, n), ``p`` shape (n,)."""

    name: str
    p: np.ndarray
    Y: np.ndarray
    arm_names: tuple[str, ...] = field(default=())
    state_names: tuple[str, ...] = field(default=())
    #: Markov hidden state: the n x n transition matrix (p is then its stationary law).
    transition: np.ndarray | None = field(default=None)

    def __post_init__(self) -> None:
        p = np.asarray(self.p, dtype=np.float64)
        Y = np.asarray(self.Y)
        where = self.name
        if p.ndim != 1 or p.size == 0:
            raise InstanceError(f"{where}: p must be a non-empty vector, got shape {p.shape}")
        if Y.ndim != 2:
            raise InstanceError(f"{where}: Y must be a K x n table, got shape {Y.shape}")
        if not np.all(np.isfinite(p)) or np.any(p < 0):
            raise InstanceError(f"{where}: probabilities must be finite and >= 0, got {p.tolist()}")
        total = math.fsum(p)
        if abs(total - 1.0) > P_TOLERANCE:
            raise InstanceError(
                f"{where}: probabilities must sum to 1 (within {P_TOLERANCE:g}), "
                f"they sum to {total!r}"
            )
        if Y.shape[0] < 2:
            raise InstanceError(f"{where}: an instance needs at least 2 arms, got {Y.shape[0]}")
        if Y.shape[1] != p.size:
            raise InstanceError(
                f"{where}: each arm needs {p.size} rewards (one per state), got {Y.shape[1]}"
            )
        if not np.all((Y == 0) | (Y == 1)):
            raise InstanceError(f"{where}: rewards Y must be 0 or 1")
        if Y.shape[0] > MAX_ARMS or p.size > MAX_STATES:
            raise InstanceError(
                f"{where}: {Y.shape[0]} arms and {p.size} states; at most {MAX_ARMS} arms and "
                f"{MAX_STATES} states"
            )
        arms = tuple(self.arm_names) or tuple(str(k + 1) for k in range(Y.shape[0]))
        states = tuple(self.state_names) or tuple(f"x{x + 1}" for x in range(p.size))

        if len(arms) != Y.shape[0]:
            raise InstanceError(f"{where}: {len(arms)} arm names for {Y.shape[0]} arms")
        if len(states) != p.size:
            raise InstanceError(f"{where}: {len(states)} state names for {p.size} states")
        if self.transition is not None:
            from .markov import STATIONARY_TOL, check_chain, check_transition, stationary

            P = check_transition(self.transition, p.size, where)
            check_chain(P, where, states)
            pi = stationary(P)
            if np.max(np.abs(pi - p)) > STATIONARY_TOL:
                raise InstanceError(
                    f"{where}: p {p.tolist()} is not the stationary law of the transition matrix "
                    f"({[round(float(v), 9) for v in pi]}); leave p out or give that law"
                )
            object.__setattr__(self, "transition", P)
        p = p.copy()
        Yi = Y.astype(np.int8)
        p.setflags(write=False)
        Yi.setflags(write=False)
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "Y", Yi)
        object.__setattr__(self, "arm_names", arms)
        object.__setattr__(self, "state_names", states)
        if isinstance(self.name, str):  # one name, however its letters were composed
            object.__setattr__(self, "name", unicodedata.normalize("NFC", self.name))

    @property
    def K(self) -> int:  # noqa: N802 - the paper's notation
        return int(self.Y.shape[0])

    @property
    def n_states(self) -> int:
        return int(self.p.size)

    @property
    def mu(self) -> np.ndarray:
        """Mean reward of each arm, ``mu_k = sum_x p_x Y[k, x]`` (:func:`weighted_sums`)."""
        return weighted_sums(self.Y, self.p)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Instance):
            return NotImplemented
        return (
            self.name == other.name
            and np.array_equal(self.p, other.p)
            and np.array_equal(self.Y, other.Y)
            and self.arm_names == other.arm_names
            and self.state_names == other.state_names
            and _same_matrix(self.transition, other.transition)
        )

    def __hash__(self) -> int:
        return hash((self.name, self.p.tobytes(), self.Y.tobytes()))

    @property
    def is_iid(self) -> bool:
        """Whether the hidden state is drawn i.i.d. (no transition matrix)."""
        return self.transition is None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description; ``from_dict`` inverts it exactly (i.i.d. instances have no
        ``transition`` key, as before Markov instances existed)."""
        out: dict[str, Any] = {
            "name": self.name,
            "p": [float(v) for v in self.p],
            "Y": self.Y.astype(int).tolist(),
            "arms": list(self.arm_names),
            "states": list(self.state_names),
        }
        if self.transition is not None:
            out["transition"] = [[float(v) for v in row] for row in self.transition]
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], *, where: str = "instance") -> Instance:
        if not isinstance(data, dict):
            raise InstanceError(f"{where}: expected a table with keys p and Y")
        transition = data.get("transition")
        required = ("Y",) if transition is not None else ("p", "Y")
        missing = [k for k in required if k not in data]
        if missing:
            raise InstanceError(f"{where}: missing key(s) {', '.join(missing)} (expected p and Y)")
        if transition is not None:
            from .markov import check_chain, check_transition, stationary

            if not isinstance(transition, list) or not all(isinstance(r, list) for r in transition):
                raise InstanceError(f"{where}: transition must be a list of rows (n x n)")
            for i, row in enumerate(transition):
                bad = [v for v in row if not _is_number(v)]
                if bad:
                    raise InstanceError(
                        f"{where}: transition row {i + 1}: {bad[0]!r} is not a finite number"
                    )
            n_given = len(data["p"]) if isinstance(data.get("p"), list) else None
            P = check_transition(transition, n_given, where)
            if "p" not in data:
                states = data.get("states")
                names = None
                if isinstance(states, list) and len(states) == P.shape[0]:
                    names = [str(v) for v in states]
                check_chain(P, where, names)
                data = {**data, "p": [float(v) for v in stationary(P)]}
        p, Y = data["p"], data["Y"]
        if not isinstance(p, list) or not all(_is_number(v) for v in p):
            raise InstanceError(f"{where}: p must be a list of numbers")
        if not isinstance(Y, list) or not all(isinstance(r, list) for r in Y):
            raise InstanceError(f"{where}: Y must be a list of rows (one list per arm)")
        for k, row in enumerate(Y):
            if len(row) != len(p):
                raise InstanceError(
                    f"{where}: Y row {k + 1} has {len(row)} entries, expected {len(p)} "
                    "(one per state)"
                )
            bad = [v for v in row if not _is_number(v) or v not in (0, 1)]
            if bad:
                raise InstanceError(f"{where}: Y row {k + 1}: reward {bad[0]!r} is not 0 or 1")
        return cls(
            name=str(data.get("name", where)),
            p=np.array(p, dtype=np.float64),
            Y=np.array(Y, dtype=np.int64).reshape(len(Y), len(p)),
            arm_names=tuple(str(a) for a in data.get("arms", ()) or ()),
            state_names=tuple(str(s) for s in data.get("states", ()) or ()),
            transition=None if transition is None else np.array(transition, dtype=np.float64),
        )


def weighted_sums(M: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``sum_x p_x M[k, x]`` for every row k of a 0/1 table ``M``, correctly rounded: each
    sum by ``math.fsum``, so the result is the same bits on every machine (a matrix product
    goes through BLAS, whose order of additions, and so whose last bits, depend on the CPU).
    mu, mu* and phi are made by it; they are logged and decide the estimator."""
    rows = np.asarray(M) != 0
    return np.array([math.fsum(p[row]) for row in rows], dtype=np.float64).reshape(rows.shape[0])


def _same_matrix(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(np.array_equal(a, b))


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(float(v))


BUILTINS: dict[str, dict[str, Any]] = {
    "I1": {
        "name": "I1",
        "p": [0.2, 0.3, 0.3, 0.2],
        "Y": [[1, 0, 0, 0], [0, 1, 1, 0], [0, 0, 1, 1], [0, 0, 0, 1]],
    },
    "I2": {
        "name": "I2",
        "p": [0.1, 0.1, 0.5, 0.3],
        "Y": [[1, 0, 0, 0], [1, 1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]],
    },
    # Gilbert-Elliott: a bursty two-state channel (good -> bad w.p. 0.1, bad -> good w.p. 0.3,
    # stationary law 0.75 / 0.25); the direct link works in the good state, the fallback in
    # the bad one. Bursts of the bad state make the direct link's failures come in runs.
    "GE": {
        "name": "GE",
        "transition": [[0.9, 0.1], [0.3, 0.7]],
        "Y": [[1, 0], [0, 1]],
        "arms": ["direct", "fallback"],
        "states": ["good", "bad"],
    },
}


def load_instance(spec: str | os.PathLike[str] | Instance) -> Instance:
    """A built-in name (``I1``, ``I2``, case-insensitive) or a path to an instance file."""
    if isinstance(spec, Instance):
        return spec
    text = os.fspath(spec)
    if not text.strip():
        raise InstanceError(
            f"empty instance name (expected a built-in, {', '.join(BUILTINS)}, or a file path)"
        )
    for name, data in BUILTINS.items():
        if text.upper() == name:
            return Instance.from_dict(data, where=name)
    path = Path(text)
    if not path.exists():
        known = ", ".join(BUILTINS)
        raise InstanceValueError(f"{text}: no such instance file (built-in instances: {known})")
    if path.is_dir():
        raise InstanceError(f"{text}: is a directory, expected an instance file")
    raw = _read_regular(path, text)
    suffix = path.suffix.lower()
    if suffix == ".json":
        try:
            data = json.loads(raw)
        except json.JSONDecodeError as exc:
            raise InstanceError(f"{text}:{exc.lineno}: invalid JSON: {exc.msg}") from None
        except RecursionError:
            raise InstanceError(f"{text}: nested too deeply (expected p, Y, ...)") from None
        _check_depth(data, text)
        return _named(Instance.from_dict(data, where=text), data, path)
    if suffix == ".toml":
        try:
            import tomllib
        except ModuleNotFoundError:  # Python 3.10
            raise InstanceError(f"{text}: TOML instances need Python >= 3.11") from None
        try:
            data = tomllib.loads(raw)
        except tomllib.TOMLDecodeError as exc:
            raise InstanceError(f"{text}: invalid TOML: {exc}") from None
        except RecursionError:
            raise InstanceError(f"{text}: nested too deeply (expected p, Y, ...)") from None
        _check_depth(data, text)
        return _named(Instance.from_dict(data, where=text), data, path)
    return parse_text_instance(raw, where=text, name=path.stem)


#: Instance files larger than this are refused before they are read (a 1024 x 1024
#: transition matrix written out in full takes about 20 MiB of JSON).
MAX_FILE_BYTES = 64 << 20
#: Deepest nesting an instance file may use (Y and transition are lists of lists: 3).
MAX_DEPTH = 8
#: Most arms and hidden states (the engine's int32 columns and per-slot arrays stay sane).
MAX_ARMS = 4096
MAX_STATES = 1 << 20


def _read_regular(path: Path, where: str) -> str:
    """The text of a regular file of at most MAX_FILE_BYTES; FIFOs, devices and sockets are
    refused at once (opened non-blocking and checked before any read), so a FIFO never hangs
    and an endless device never fills memory."""
    import stat

    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        raise InstanceError(f"{where}: cannot read instance file: {exc.strerror}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InstanceError(
                f"{where}: not a regular file (a FIFO, device or socket); expected an "
                "instance file"
            )
        if st.st_size > MAX_FILE_BYTES:
            raise InstanceError(
                f"{where}: {st.st_size} bytes, larger than the limit of {MAX_FILE_BYTES} bytes"
            )
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(MAX_FILE_BYTES + 1)
    finally:
        os.close(fd)
    if len(data) > MAX_FILE_BYTES:
        raise InstanceError(f"{where}: larger than the limit of {MAX_FILE_BYTES} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InstanceError(f"{where}: not UTF-8 text (byte {exc.start})") from None


def _check_depth(data: object, where: str, depth: int = 0) -> None:
    if depth > MAX_DEPTH:
        raise InstanceError(f"{where}: nested deeper than {MAX_DEPTH} levels (expected p, Y, ...)")
    if isinstance(data, dict):
        for v in data.values():
            _check_depth(v, where, depth + 1)
    elif isinstance(data, list):
        for v in data:
            if isinstance(v, (list, dict)):
                _check_depth(v, where, depth + 1)


def _renamed(inst: Instance, name: str) -> Instance:
    return Instance(name, inst.p, inst.Y, inst.arm_names, inst.state_names, inst.transition)


def _named(inst: Instance, data: dict[str, Any], path: Path) -> Instance:
    if "name" in data:
        return inst
    return _renamed(inst, path.stem)


def parse_text_instance(raw: str, *, where: str = "<text>", name: str = "instance") -> Instance:
    """Parse the community text format, naming file and line in every error."""
    rows: list[tuple[int, list[str]]] = []
    for lineno, line in enumerate(raw.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if body:
            rows.append((lineno, body.replace(",", " ").split()))
    if not rows:
        raise InstanceError(f"{where}: empty instance file (expected p on line 1, then Y rows)")
    p_line, p_tokens = rows[0]
    p_vals: list[float] = []
    for tok in p_tokens:
        try:
            v = float(tok)
        except ValueError:
            raise InstanceError(f"{where}:{p_line}: probability {tok!r} is not a number") from None
        if not math.isfinite(v) or v < 0:
            raise InstanceError(f"{where}:{p_line}: probability {tok!r} must be >= 0")
        p_vals.append(v)
    total = math.fsum(p_vals)
    if abs(total - 1.0) > P_TOLERANCE:
        raise InstanceError(
            f"{where}:{p_line}: probabilities sum to {total!r}, expected 1 (within {P_TOLERANCE:g})"
        )
    if len(rows) < 3:
        raise InstanceError(
            f"{where}: {len(rows) - 1} arm row(s), an instance needs at least 2 arms"
        )
    Y: list[list[int]] = []
    for lineno, tokens in rows[1:]:
        if len(tokens) != len(p_vals):
            raise InstanceError(
                f"{where}:{lineno}: {len(tokens)} rewards, expected {len(p_vals)} "
                "(one per state, as many as probabilities on line "
                f"{p_line})"
            )
        row = []
        for tok in tokens:
            if tok not in ("0", "1"):
                raise InstanceError(f"{where}:{lineno}: reward {tok!r} is not 0 or 1")
            row.append(int(tok))
        Y.append(row)
    return Instance(name=name, p=np.array(p_vals), Y=np.array(Y, dtype=np.int64))


def format_text_instance(inst: Instance) -> str:
    """The community text format of an instance (round-trips through ``parse_text_instance``)."""
    lines = [" ".join(repr(float(v)) for v in inst.p)]
    lines += [" ".join(str(int(v)) for v in row) for row in inst.Y]
    return "\n".join(lines) + "\n"
