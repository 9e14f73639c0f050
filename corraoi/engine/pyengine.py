"""The plain-Python tier's parts: the runs' random streams a :class:`corraoi.policies.Policy`
draws from (:class:`Streams`, the engine's side of :class:`~corraoi.policies.api.RunStreams`;
the rest of what it sees is :class:`~corraoi.policies.api.RunState`), the check of what it
returns, the bookkeeping of a slot, and its failures in one line.
:class:`corraoi.engine.simulation.Simulation` drives it slot by slot, vectorised over runs.

Each slot: the hidden states of every run (drawn in blocks from the runs' latent streams by
the same compiled function as the built-ins' kernel, so a plug-in run on seed s sees exactly
the path built-ins see on seed s), then ``policy.select(t, state)`` -> one arm per run,
checked (shape, integer, in range), then rewards, ages, regret and counts (numpy), then
``policy.update``. The policy sees the engine's arrays through read-only views
(:class:`~corraoi.policies.api.RunState`); a write into one is one line naming the field
(:func:`policy_raised`).

Random numbers for the policy come from :class:`Streams`: each run's own policy stream (the
one a built-in would use), so a run's decisions do not depend on which runs share the batch.
"""

from __future__ import annotations

import ast
import dis
import linecache
import textwrap
from inspect import getattr_static
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np
from numba import njit

from corraoi.errors import CorraoiError, PolicyRuntimeError
from corraoi.policies.api import Choice, RunState
from corraoi.rng import argmax_random, beta, integer, normal, uniform


@njit(cache=True)
def _uniforms(pol, out):
    for r in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[r, j] = uniform(pol[r])


@njit(cache=True)
def _integers(pol, high, out):
    for r in range(out.shape[0]):
        out[r] = integer(pol[r], high[r])


@njit(cache=True)
def _integers_scalar(pol, high, out):
    for r in range(out.shape[0]):
        out[r] = integer(pol[r], high)


@njit(cache=True)
def apply_slot(arms, x, Y, best, pulls, succ, mu, aoi, oaoi, regret, aoisum, rewards):
    """One slot of every run after the policy chose ``arms``: rewards, counts, empirical
    means, ages and regret (in one compiled call; the Python tier's bookkeeping)."""
    R, K = pulls.shape
    for r in range(R):
        a = arms[r]
        rew = Y[a, x[r]]
        rewards[r] = rew
        pulls[r, a] += 1
        succ[r, a] += rew
        mu[r, a] = succ[r, a] / pulls[r, a]
        aoi[r] = 1 if rew == 1 else aoi[r] + 1
        oaoi[r] = 1 if Y[best, x[r]] == 1 else oaoi[r] + 1
        regret[r] += aoi[r] - oaoi[r]
        aoisum[r] += aoi[r]


@njit(cache=True)
def apply_sources_slot(arms, x, Y, oracle, pulls, succ, mu, aoi, oaoi, regret, aoisum, coll,
                       collided, sensed):  # fmt: skip
    """One slot of every run of M sources after each chose its channel (``arms`` (M, R)):
    collisions (a channel two sources picked delivers to none), what each source senses (its
    channel's state, counted delivered or not), ages against the source's oracle channel
    ``oracle[m]``, regret and collision counts, per source (M, R[, K]) -- the plain-Python
    tier's bookkeeping of docs/model.md, "Many sources", as the kernel of many sources does
    it."""
    M, R, K = pulls.shape
    taken = np.zeros(K, dtype=np.int64)
    for r in range(R):
        for m in range(M):
            taken[arms[m, r]] += 1
        for m in range(M):
            a = arms[m, r]
            s = Y[a, x[r]]
            hit = taken[a] > 1
            sensed[m, r] = s
            collided[m, r] = hit
            pulls[m, r, a] += 1
            succ[m, r, a] += s
            mu[m, r, a] = succ[m, r, a] / pulls[m, r, a]
            if hit:
                coll[m, r] += 1
            aoi[m, r] = 1 if s == 1 and not hit else aoi[m, r] + 1
            oaoi[m, r] = 1 if Y[oracle[m], x[r]] == 1 else oaoi[m, r] + 1
            regret[m, r] += aoi[m, r] - oaoi[m, r]
            aoisum[m, r] += aoi[m, r]
        for m in range(M):
            taken[arms[m, r]] = 0


@njit(cache=True)
def _argmax_all(pol, vals, out):
    K = vals.shape[1]
    mask = np.ones(K, dtype=np.bool_)
    for r in range(vals.shape[0]):
        out[r] = argmax_random(vals[r], mask, pol[r], K)


@njit(cache=True)
def _normals(pol, cache, out):
    for r in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[r, j] = normal(pol[r], cache[r])


@njit(cache=True)
def _betas(pol, cache, a, b, out):
    for r in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[r, j] = beta(pol[r], cache[r], a[r, j], b[r, j])


@njit(cache=True)
def _argmax(pol, vals, mask, out):
    K = vals.shape[1]
    for r in range(vals.shape[0]):
        out[r] = argmax_random(vals[r], mask[r], pol[r], K)


class Streams:
    """The runs' own random streams, vectorised: every method returns one value (or row) per
    run, drawn from that run's stream only."""

    def __init__(self, pol: np.ndarray, cache: np.ndarray) -> None:
        self._pol = pol
        self._cache = cache

    @property
    def runs(self) -> int:
        return int(self._pol.shape[0])

    def random(self, size: int | None = None) -> np.ndarray:
        """Uniforms in [0, 1): shape (runs,) or (runs, size)."""
        out = np.empty((self._pol.shape[0], 1 if size is None else int(size)))
        _uniforms(self._pol, out)
        return out[:, 0] if size is None else out

    def integers(self, high: int | np.ndarray) -> np.ndarray:
        """A uniform integer in [0, high) per run (``high`` a scalar or (runs,), >= 1)."""
        out = np.empty(self._pol.shape[0], dtype=np.int64)
        if isinstance(high, (int, np.integer)):
            if high < 1:
                raise ValueError("integers: high must be >= 1")
            _integers_scalar(self._pol, int(high), out)
            return out
        h = np.broadcast_to(np.asarray(high, dtype=np.int64), out.shape)
        if (h < 1).any():
            raise ValueError("integers: high must be >= 1")
        _integers(self._pol, np.ascontiguousarray(h), out)
        return out

    def normal(self, size: int | None = None) -> np.ndarray:
        """Standard normals: shape (runs,) or (runs, size)."""
        out = np.empty((self.runs, 1 if size is None else int(size)))
        _normals(self._pol, self._cache, out)
        return out[:, 0] if size is None else out

    def beta(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Beta(a, b) samples of shape (runs, K) for shape parameters >= 1 of that shape."""
        a2 = np.ascontiguousarray(np.broadcast_to(a, np.broadcast(a, b).shape), dtype=np.float64)
        b2 = np.ascontiguousarray(np.broadcast_to(b, a2.shape), dtype=np.float64)
        if a2.ndim != 2 or a2.shape[0] != self.runs:
            raise ValueError(f"beta: expected shapes (runs, K), got {a2.shape}")
        if (a2 < 1).any() or (b2 < 1).any():
            raise ValueError("beta: shape parameters must be >= 1")
        out = np.empty_like(a2)
        _betas(self._pol, self._cache, a2, b2, out)
        return out

    def argmax(self, values: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Per run, the index of the largest value (among ``mask``), ties uniformly at random
        -- the rule the built-ins use."""
        vals = np.ascontiguousarray(values, dtype=np.float64)
        out = np.empty(vals.shape[0], dtype=np.int64)
        if mask is None:
            _argmax_all(self._pol, vals, out)
        else:
            _argmax(self._pol, vals, np.ascontiguousarray(mask, dtype=np.bool_), out)
        return out


def check_arms(
    out: Any, *, runs: int, arms: int, name: str, t: int, who: Any = None
) -> tuple[np.ndarray, Any, Any]:
    """(arms, candidates or None, scores or None) from ``select``'s return (arms, a pair
    (arms, candidates) or a :class:`~corraoi.policies.api.Choice`), or PolicyRuntimeError
    naming the policy, the slot and (``who(r)``, by default "run r") the run. Scores come
    back as float32 (runs, K), NaN outside the candidate set."""
    cand = scores = None
    if isinstance(out, Choice):
        out, cand, scores = out.arms, out.candidates, out.scores
    elif isinstance(out, tuple):
        if len(out) != 2:
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: select returned a tuple of {len(out)}; expected "
                "arms, (arms, candidates) or Choice(arms, candidates, scores)"
            )
        out, cand = out
    a = np.asarray(out)
    if a.shape != (runs,):
        raise PolicyRuntimeError(
            f"policy {name}, slot {t}: select returned shape {a.shape}; expected ({runs},) "
            "(one arm per run)"
        )
    if a.dtype.kind == "f":
        if not np.isfinite(a).all():
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: select returned NaN or infinity; expected arms "
                f"0..{arms - 1}"
            )
        if (a != np.round(a)).any():
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: select returned a non-integer arm "
                f"{a[a != np.round(a)][0]!r}"
            )
    elif a.dtype.kind not in "iub":
        raise PolicyRuntimeError(
            f"policy {name}, slot {t}: select returned {a.dtype} values; expected integer arms"
        )
    ai = a.astype(np.int64)
    bad = (ai < 0) | (ai >= arms)
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise PolicyRuntimeError(
            f"policy {name}, slot {t}: select returned arm {ai[r]} for "
            f"{who(r) if who is not None else f'run {r}'}; expected 0..{arms - 1} (0-based; "
            "arm k+1 in logs)"
        )
    if cand is not None:
        c = np.asarray(cand)
        if c.shape != (runs, arms) or c.dtype != np.bool_:
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: candidates must be a bool array of shape "
                f"({runs}, {arms}), got {c.dtype} {c.shape}"
            )
        if not c[np.arange(runs), ai].all():
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: a played arm is not among its candidates"
            )
    if scores is not None:
        v = np.asarray(scores)
        if v.shape != (runs, arms) or v.dtype.kind not in "iuf":
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: scores must be an array of numbers of shape "
                f"({runs}, {arms}), got {v.dtype} {v.shape}"
            )
        scores = v.astype(np.float32)
        if cand is not None:
            scores[~cand] = np.nan
        member = np.ones((runs, arms), dtype=bool) if cand is None else cand
        gap = np.isnan(scores) & member & ~np.isnan(scores).all(axis=1)[:, None]
        if gap.any():
            r, k = (int(i) for i in np.argwhere(gap)[0])
            raise PolicyRuntimeError(
                f"policy {name}, slot {t}: scores gave NaN to arm {k + 1}, a candidate, for "
                f"{who(r) if who is not None else f'run {r}'}; a run's scores are a number "
                "for every candidate (+inf is one), or NaN for all (not chosen by score)"
            )
    return ai, cand, scores


def not_by_score(scores: np.ndarray, arms: np.ndarray) -> np.ndarray:
    """Per run, whether the arm played was not chosen by the score: its score is NaN or
    below the highest (what ``forced`` logs for a plain-Python policy's slot)."""
    played = scores[np.arange(len(arms)), arms]
    with np.errstate(invalid="ignore"):
        top = np.where(np.isnan(scores), -np.inf, scores).max(axis=1)
    return np.isnan(played) | (played < top)


def hook_fault(name: str, t: int, what: int, value: int, K: int, who: str) -> PolicyRuntimeError:
    """A compiled hook's fault the kernel noted (``corraoi.engine._kernel``'s ``err``), in the
    plain-Python tier's words: one line naming the policy, the slot and the run."""
    from ._kernel import FAULT_ARM

    if what == FAULT_ARM:
        text = (f"its forced hook returned arm {value} for {who}; expected 0..{K - 1}, or a "
                "negative number for none (0-based; arm k+1 in logs)")  # fmt: skip
    else:
        text = (f"its score hook gave NaN to arm {value + 1}, a candidate, for {who}; a "
                "score must be a number (+inf is one)")  # fmt: skip
    return PolicyRuntimeError(f"policy {name}, slot {t}: {text}")


def hook_raised(name: str, first: int, last: int, exc: BaseException) -> PolicyRuntimeError:
    """A compiled hook that raised (numba's ``raise``) in slots ``first..last``."""
    detail = " ".join(str(exc).split())[:300]
    return PolicyRuntimeError(f"policy {name}, slots {first}..{last}: a compiled hook raised "
                              f"{type(exc).__name__}" + (f": {detail}" if detail else ""))


def counts_written(name: str, t0: int, arm: np.ndarray, success: np.ndarray, pulls: np.ndarray,
                   mu_hat: np.ndarray, pulls0: np.ndarray, succ0: np.ndarray,
                   who: Any) -> tuple[int, PolicyRuntimeError] | None:  # fmt: skip
    """The record path's check that a compiled plug-in's hooks left the engine's counts
    alone: the logged ``pulls`` and ``mu_hat`` (R, B, K) of slots ``t0 + 1..`` must follow
    the arms played and their successes from the counts ``pulls0``/``succ0`` (R, K) before
    (which this advances). None, or (slots before the first that does not, the
    PolicyRuntimeError naming it and ``who(r)``)."""
    first = np.full(arm.shape[0], arm.shape[1], dtype=np.int64)
    _first_off_count(arm, success, pulls, mu_hat, pulls0, succ0, first)
    r = int(first.argmin())
    if first[r] == arm.shape[1]:
        return None
    return int(first[r]), hook_wrote(name, f"slot {t0 + int(first[r]) + 1}", "npull or nsucc",
                                     who(r))  # fmt: skip


@njit(cache=True)
def _first_off_count(arm, success, pulls, muhat, n, s, first):
    for r in range(arm.shape[0]):
        for j in range(arm.shape[1]):
            a = arm[r, j]
            n[r, a] += 1
            s[r, a] += success[r, j]
            off = False
            for k in range(n.shape[1]):
                m = s[r, k] / n[r, k] if n[r, k] > 0 else 0.0
                off = off or pulls[r, j, k] != n[r, k] or muhat[r, j, k] != m
            if off:
                first[r] = j
                break


def hook_wrote(name: str, when: str, what: str, who: str = "") -> PolicyRuntimeError:
    """A compiled hook that wrote into an array it may only read, in one line."""
    return PolicyRuntimeError(f"policy {name}, {when}: a compiled hook wrote into {what}"
                              + (f" for {who}" if who else "") + "; hooks may write only "
                              "vals (score) and ps, and read the rest")  # fmt: skip


def construct(cls: Any, spec: Any) -> Any:
    """A plain-Python policy made with its parameters; whatever its ``__init__`` raises is
    one PolicyRuntimeError line naming the policy (before slot 1: no log is left)."""
    try:
        return cls(**spec.params)
    except (CorraoiError, KeyboardInterrupt):
        raise
    except BaseException as exc:  # noqa: BLE001 - sys.exit in __init__ is the plug-in's too
        detail = " ".join(str(exc).split())[:300]
        raise PolicyRuntimeError(f"policy {spec.name}: creating it ({cls.__name__}.__init__) "
                                 f"raised {type(exc).__name__}"
                                 + (f": {detail}" if detail else "")) from None  # fmt: skip


def call_policy(name: str, t: int, state: RunState, func: Any, *args: Any) -> Any:
    """Call a plug-in's method; any exception becomes one line naming the policy and slot
    (and the field of ``state`` for a write into it)."""
    try:
        return func(*args)
    except (CorraoiError, KeyboardInterrupt):
        raise
    except BaseException as exc:  # sys.exit in select is the plug-in's failure, not ours
        raise policy_raised(name, t, func, exc, state) from exc


def policy_raised(name: str, t: int, func: Any, exc: BaseException,
                  state: RunState) -> PolicyRuntimeError:  # fmt: skip
    """What a plain-Python policy's method raised, as one line naming the policy and the
    slot; a write into its read-only ``state`` names the field written."""
    what = getattr(func, "__name__", "policy")
    if isinstance(exc, AttributeError) and getattr(exc, "obj", None) is state:
        return PolicyRuntimeError(f"policy {name}, slot {t}: {what} set state.{exc.name}, "
                                  "which is read-only")  # fmt: skip
    field = written_field(exc, state) if isinstance(exc, ValueError) else None
    if field is not None:
        return PolicyRuntimeError(
            f"policy {name}, slot {t}: {what} wrote into state.{field}, which is read-only "
            f"(the engine's own; change a copy: state.{field}.copy())"
        )
    detail = " ".join(str(exc).split())
    return PolicyRuntimeError(f"policy {name}, slot {t}: {what} raised {type(exc).__name__}"
                              + (f": {detail}" if detail else ""))  # fmt: skip


#: The array fields of :class:`~corraoi.policies.api.RunState`.
ARRAY_FIELDS = ("pulls", "successes", "mu_hat", "aoi", "seeds", "collided")
_NUMPY_DIR = str(Path(np.__file__).parent)


def written_field(exc: BaseException, state: RunState) -> str | None:
    """The field of ``state`` whose read-only array the write that raised ``exc`` (numpy's
    "... is read-only") went to, or None. Read from the failing expression in the policy's
    source (the innermost frame outside numpy): the array it assigns into, its ``out=``,
    the array whose method it calls, then its arguments; each is looked up (names and
    attributes, no calls) and matched to a field by memory, so ``m = state.mu_hat;
    m[0] = 1`` names ``mu_hat`` too."""
    if "read-only" not in str(exc):
        return None
    frame, lasti = _policy_frame(exc)
    if frame is None:
        return None
    try:
        statement = ast.parse(textwrap.dedent(_segment(frame, lasti))).body[0]
    except (SyntaxError, IndexError, ValueError):  # no source (exec): the line's bytecode
        return _loaded_field(frame, lasti, state)
    for expr in _written(statement):
        field = _field_of(_lookup(expr, frame), state)
        if field is not None:
            return field
    return None


def _field_of(obj: Any, state: RunState) -> str | None:
    if isinstance(obj, np.ndarray):
        for field in ARRAY_FIELDS:
            if np.may_share_memory(obj, getattr(state, field)):
                return field
    return None


def _loaded_field(frame: FrameType, lasti: int, state: RunState) -> str | None:
    """The first field of ``state`` the failing line loads (an attribute of that name, or a
    variable holding a view of it), read from its bytecode."""
    code = list(dis.get_instructions(frame.f_code))
    end = max((i for i, ins in enumerate(code) if ins.offset <= lasti), default=0)
    start = max((i for i in range(end + 1) if code[i].starts_line), default=0)
    for ins in code[start : end + 1]:
        if ins.opname in ("LOAD_ATTR", "LOAD_METHOD") and ins.argval in ARRAY_FIELDS:
            return str(ins.argval)
        if ins.opname in ("LOAD_FAST", "LOAD_NAME", "LOAD_GLOBAL", "LOAD_DEREF"):
            field = _field_of(_lookup(ast.Name(id=str(ins.argval)), frame), state)
            if field is not None:
                return field
    return None


def _policy_frame(exc: BaseException) -> tuple[FrameType | None, int]:
    frame, lasti, tb = None, 0, exc.__traceback__
    while tb is not None:
        if not tb.tb_frame.f_code.co_filename.startswith(_NUMPY_DIR):
            frame, lasti = tb.tb_frame, tb.tb_lasti
        tb = tb.tb_next
    return frame, lasti


def _segment(frame: FrameType, lasti: int) -> str:
    """The source text of the instruction at ``lasti`` in ``frame`` ('' when unknown)."""
    code = frame.f_code
    first, last, col, end = next(
        (p for i, p in enumerate(code.co_positions()) if 2 * i == lasti), (None,) * 4
    )
    if first is None or last is None or col is None or end is None:
        return ""
    lines = [linecache.getline(code.co_filename, n, frame.f_globals).encode()
             for n in range(first, last + 1)]  # fmt: skip
    lines[-1] = lines[-1][:end]  # columns are UTF-8 byte offsets
    lines[0] = lines[0][col:]
    return b"".join(lines).decode(errors="replace")


def _written(node: ast.AST) -> list[ast.expr]:
    """The expressions a failing write may have gone to, the likeliest first."""
    if isinstance(node, ast.Expr):
        return _written(node.value)
    if isinstance(node, (ast.AugAssign, ast.AnnAssign)):
        return [node.target]
    if isinstance(node, ast.Assign):
        return list(node.targets)
    if isinstance(node, ast.Subscript):
        return [node.value]
    if isinstance(node, ast.Call):
        out = [kw.value for kw in node.keywords if kw.arg == "out"]
        out = [e for o in out for e in (o.elts if isinstance(o, ast.Tuple) else [o])]
        receiver = [node.func.value] if isinstance(node.func, ast.Attribute) else []
        return out + receiver + list(node.args)
    return []


def _lookup(expr: ast.expr, frame: FrameType) -> Any:
    """The object ``expr`` (a name, attribute or subscript of one) stands for in ``frame``,
    found without calling the policy's code; None when it is anything else."""
    if isinstance(expr, (ast.Subscript, ast.Starred)):
        return _lookup(expr.value, frame)
    if isinstance(expr, ast.Name):
        scope = frame.f_locals if expr.id in frame.f_locals else frame.f_globals
        return scope.get(expr.id)
    if isinstance(expr, ast.Attribute):
        base = _lookup(expr.value, frame)
        try:  # numpy's and RunState's attributes are plain; anything else: no code runs
            if isinstance(base, (np.ndarray, RunState)):
                return getattr(base, expr.attr)
            return getattr_static(base, expr.attr)
        except AttributeError:
            return None
    return None
