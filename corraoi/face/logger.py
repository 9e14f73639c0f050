""":class:`Logger`: a slot log (and, if asked, its Rerun recording) written from any loop --
a testbed, a network simulator, an agent of another library -- one slot or a block of slots
at a time, into the same files :func:`corraoi.record` writes.

The caller gives what its loop knows: the arm tried and whether it delivered, and when it
knows them the hidden state ``x`` and the policy's own per-slot fields. The Logger computes
what the model defines from those: the age, the pulls and empirical means, the paper's
estimator (with the instance's ``mu*``), and with ``x`` the oracle's age and the pathwise
regret. What is neither given nor computable is left absent from the log (a field the slot
record says may be absent; ``SlotBlock.absent``); every reader and view leaves it out.

The slots become :class:`~corraoi.engine.block.SlotBlock` s, as the engine's do, and go to
the sinks ``record_run`` feeds: the MCAP log (:class:`~corraoi.recorder.slotlog.sink.McapSink`,
written as ``.partial`` and published when closed, a chunk flushed every 1,000 slots), the
Rerun recording and any further :class:`~corraoi.recorder.sink.Sink`.
"""

from __future__ import annotations

import operator
import os
from collections.abc import Mapping, Sequence
from contextlib import ExitStack
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from corraoi._version import __version__
from corraoi.engine.block import ARM_FIELDS, FIELDS, RunConfig, SlotBlock, absent_column
from corraoi.engine.slot_record import BY_NAME, REQUIRED
from corraoi.errors import ConfigError, CorraoiError, PolicyError, SlotError, UsageError
from corraoi.provenance import Provenance, versions
from corraoi.recorder.sink import RunRecording, Sink
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.recorder.vocab import SLOT_FLUSH_EVERY

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from typing_extensions import Self

    from corraoi.model.instance import Instance

#: The qualified name a policy logged by a Logger is given (it is no class corraoi can import).
EXTERNAL_PREFIX = "external:"
#: What the hidden state ``x`` makes computable: without it these are absent.
NEEDS_X = ("x", "oracle_aoi", "regret")
#: What the Logger computes from the arms and successes (the estimator with the instance's
#: mu*), given or not: the slot record's required fields and these.
COMPUTED = (*REQUIRED, "estimator", "mu_hat", "pulls")
#: The per-slot fields a caller may give besides arm, success and x, as ``SlotBlock``
#: names them: those of the block's columns the slot record says may be absent, but the
#: ones ``x`` gives and the estimator.
GIVEN_FIELDS = tuple(f for f in FIELDS if BY_NAME[f].may_be_absent and f not in NEEDS_X
                     and f != "estimator")  # fmt: skip


class Logger:
    """Write one run's slot log from slots given one at a time or in blocks.

    ::

        with corraoi.Logger("testbed.mcap", instance="I1", horizon=10_000,
                            policy="my-scheduler", source="testbed-v2") as log:
            for t in range(1, 10_001):
                log.slot(arm=2, success=True)          # arms and states numbered from 1
            log.slots(arm=[...], success=[...], x=[...])   # or many at once

        with corraoi.Logger("testbed.mcap", arms=4, policy="my-scheduler",
                            instance=None) as log:     # no p, Y known: no x, oracle, regret
            log.slot(arm=2, success=True)

    ``path``: the slot log (written as ``<path>.partial``, renamed when closed); ``rrd``: a
    Rerun recording beside it (a path, or True for the log's name with ``.rrd``).
    ``instance``: what :func:`corraoi.record` takes (a built-in name, a file or an
    :class:`~corraoi.Instance`); ``arms``, if given, must be its number of arms. With
    ``instance=None`` (a testbed whose ``p`` and ``Y`` nobody knows) ``arms`` is required:
    the log then has no hidden state, oracle, regret or estimator (they need the instance;
    ``x`` is refused) and its run configuration records the arms only.
    ``horizon``: the slots the run is meant to have (closing earlier marks the log
    interrupted); None (the default) for a stream of unknown length: the log's horizon is
    the longest a log holds, and closing it marks it complete (Ctrl-C: interrupted).
    ``policy``: the name the run is logged under (with ``params``); ``seed``: the seed of
    its hidden path, when it is corraoi's (:mod:`corraoi.gym`), so that it is paired with
    corraoi's own runs of that seed. ``channel``: as ``corraoi.record``'s.
    ``source`` and ``version``: what wrote the slots (your program and its version), kept
    in the log's provenance with corraoi's own versions.

    Each slot: ``arm`` (1..K) and ``success`` (a bool) always; ``x`` (the hidden state,
    1..n), then ``success`` must equal ``Y[arm, x]`` and the oracle's age and the regret are
    logged; ``mu_hat``, ``pulls`` (computed from the arms and successes when not given),
    ``candidates`` (the arms chosen from) and ``override`` may be given. The first slot
    decides which are given; every later one must give the same. Bad input raises
    :class:`~corraoi.errors.SlotError` naming the argument and the slot; the log is then
    finished with the slots before it, marked failed, at its ``.partial`` name.

    Leaving the ``with`` normally closes the log (complete at the horizon, interrupted
    before); Ctrl-C closes it with the slots so far (interrupted); another exception marks
    it failed with that error. A process killed outright loses at most the slots since the
    last multiple of 1,000 (``corraoi recover`` finishes the rest).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        instance: str | os.PathLike[str] | Instance | None,
        horizon: int | None = None,
        policy: str = "external",
        arms: int | None = None,
        params: Mapping[str, float] | None = None,
        seed: int = 0,
        channel: str | None = None,
        rrd: str | os.PathLike[str] | bool | None = None,
        source: str = "",
        version: str = "",
        overwrite: bool = False,
        sinks: Sequence[Sink[SlotBlock]] = (),
    ) -> None:
        from corraoi import arguments
        from corraoi.files.partial import check_target
        from corraoi.limits import MAX_HORIZON, check_horizon, check_seed
        from corraoi.policies.spec import PolicySpec

        from . import resolve
        from .recording import SINK_METHODS
        from .runs import rrd_beside

        arguments.path(path, name="path", what="the slot log's path (a str or a pathlib.Path)")
        channel = resolve.channel_word(channel)
        if instance is None:
            K = arguments.integer(
                arms,
                name="arms",
                lo=1,
                kind=ConfigError,
                why="a log without an instance needs its number of arms",
            )
            if channel is not None:
                raise arguments.wrong_value(
                    ConfigError,
                    "channel",
                    channel,
                    "None (a log without an instance has no hidden states)",
                )
            inst = None
        else:
            inst = resolve.instance(instance)
            given = arguments.optional(arguments.integer, arms, name="arms", kind=ConfigError)
            if given is not None and given != inst.K:
                raise arguments.wrong_value(
                    ConfigError, "arms", arms, f"{inst.K}, the arms of instance {inst.name}"
                )
            K = inst.K
        self.open_ended = horizon is None
        horizon = MAX_HORIZON if horizon is None else check_horizon(horizon, floats=True)
        seed = check_seed(seed, name="seed", floats=True)
        arguments.text(policy, name="policy", kind=PolicyError,
                       expected="the name the run is logged under")  # fmt: skip
        arguments.text(source, name="source", empty=True)
        arguments.text(version, name="version", empty=True)
        arguments.path_or_flag(rrd, name="rrd", what="the Rerun recording's path")
        arguments.flag(overwrite, name="overwrite")
        arguments.objects(sinks, name="sinks", has=SINK_METHODS,
                          what="a corraoi.recorder.sink.Sink")  # fmt: skip
        if params is not None and not isinstance(params, Mapping):
            raise arguments.wrong_type(PolicyError, "params", params, "a dict of numbers")
        params = {k: arguments.number(v, name=f"params[{k!r}]", kind=PolicyError)
                  for k, v in (params or {}).items()}  # fmt: skip
        if inst is not None:
            chan = resolve.channel(channel, inst)
            chan.check(inst, int(horizon))
        self.spec = PolicySpec(name=policy, params=dict(params),
                               qualname=EXTERNAL_PREFIX + policy, version=version,
                               tier="external")  # fmt: skip
        self._base = RunConfig(inst, self.spec, int(seed), int(horizon),
                               channel=None if inst is None else chan,
                               arms=K if inst is None else None)  # fmt: skip
        self.path = check_target(path, overwrite=overwrite, what="MCAP log")
        if rrd is True:
            rrd = rrd_beside(self.path)
        self.rrd: Path | None = None if rrd is None or rrd is False else Path(rrd)
        if self.rrd is not None:
            check_target(self.rrd, overwrite=overwrite, what="Rerun recording")
        self.overwrite = overwrite
        self.source, self.version = source, version
        self._sinks = tuple(sinks)
        self.K, self.n_states = K, self._base.n_states
        self.horizon = int(horizon)
        theory = self._base.theory  # None without an instance: no oracle, regret, estimator
        self._best = None if theory is None else theory.best_arm
        self._mu_star = None if theory is None else theory.mu_star
        self._Y = None if inst is None else np.asarray(inst.Y, dtype=bool)
        self._Y_rows = None if self._Y is None else self._Y.tolist()
        #: the run's configuration once the first slot said which fields are given
        self.config: RunConfig | None = None
        self._stack: ExitStack | None = None
        self._log: McapSink | None = None
        self._every: list[Sink[SlotBlock]] = []
        #: slots written so far (to the sinks and pending)
        self.t = 0
        self._given: tuple[bool, ...] | None = None  # (x, *GIVEN_FIELDS) given?
        #: the columns of FIELDS the log lacks (decided by the first slot)
        self._absent: tuple[str, ...] = ()
        self._pending: dict[str, list[Any]] = {}
        self._written = 0
        # the carried state of the run after the last slot handed to the sinks
        self._aoi = 1
        self._oracle_aoi = 1
        self._regret = 0
        self._aoisum = 0
        self._pulls = np.zeros(self.K, dtype=np.int64)
        self._succ = np.zeros(self.K, dtype=np.int64)
        self.closed = False
        #: the file the log ended in (the final name, or ``.partial`` when it failed)
        self.result: Path | None = None

    # ------------------------------------------------------------------ the slots

    def slot(
        self,
        arm: int,
        success: bool,
        *,
        x: int | None = None,
        t: int | None = None,
        mu_hat: Sequence[float] | None = None,
        pulls: Sequence[int] | None = None,
        candidates: Sequence[int] | Sequence[bool] | None = None,
        override: bool | None = None,
    ) -> None:
        """Log the next slot (``t``, if given, must be it): ``arm`` 1..K, ``success`` a
        bool, and the optional fields (class docstring)."""
        n = self.t + 1
        if self.closed:
            raise UsageError(f"slot {n}: the log {self.path} is closed")
        try:
            if t is not None and t != n:
                self._bad_t(t, n)
            if n > self.horizon:
                raise SlotError(f"slot {n}: past the horizon {self.horizon} of the log")
            if arm.__class__ is not int:
                arm = self._integer(arm, "arm", n)
            if not 1 <= arm <= self.K:
                raise SlotError(f"slot {n}: arm {arm}: expected an arm in 1..{self.K}")
            if success is not True and success is not False:
                success = self._boolean(success, "success", n)
            if x is not None and self._Y_rows is None:
                self._no_instance_x(n)
            given = (x is not None, override is not None, mu_hat is not None,
                     pulls is not None, candidates is not None)  # fmt: skip
            if given != self._given:
                self._fields_given(given, n)
            if x is not None:
                if self._Y_rows is None or self.n_states is None:
                    self._no_instance_x(n)
                if x.__class__ is not int:
                    x = self._integer(x, "x", n)
                if not 1 <= x <= self.n_states:
                    raise SlotError(f"slot {n}: x {x}: expected a state in 1..{self.n_states}")
                if self._Y_rows[arm - 1][x - 1] is not success:
                    raise SlotError(
                        f"slot {n}: success {success} but the instance's Y[arm {arm}, x {x}] "
                        f"is {int(self._Y_rows[arm - 1][x - 1])}; expected them to agree"
                    )
            if given[1:] != (False,) * len(GIVEN_FIELDS):
                extra = {  # checked before any is kept: a bad slot leaves nothing pending
                    "override": override if override is None else
                    self._boolean(override, "override", n),
                    "mu_hat": mu_hat if mu_hat is None else self._row(mu_hat, "mu_hat", n, float),
                    "pulls": pulls if pulls is None else self._row(pulls, "pulls", n, int),
                    "candidates": candidates if candidates is None else
                    self._candidate_row(candidates, n),
                }  # fmt: skip
                for name, value in extra.items():
                    if value is not None:
                        self._pending[name].append(value)
        except SlotError as exc:
            self._fail(exc)
            raise
        pending = self._pending
        if x is not None:
            pending["x"].append(x - 1)
        pending["arm"].append(arm - 1)
        pending["success"].append(success)
        self.t = n
        if n % SLOT_FLUSH_EVERY == 0:
            self._flush()

    def slots(
        self,
        arm: Sequence[int] | np.ndarray,
        success: Sequence[bool] | np.ndarray,
        *,
        x: Sequence[int] | np.ndarray | None = None,
        t: Sequence[int] | np.ndarray | None = None,
        mu_hat: np.ndarray | None = None,
        pulls: np.ndarray | None = None,
        candidates: np.ndarray | None = None,
        override: Sequence[bool] | np.ndarray | None = None,
    ) -> None:
        """Log the next slots at once, each field an array with one entry (or, for
        ``mu_hat``, ``pulls`` and ``candidates``, one row of K) per slot; ``candidates``
        as a (B, K) bool mask. The same fields as :meth:`slot`, all of one length."""
        first = self.t + 1
        if self.closed:
            raise UsageError(f"slot {first}: the log {self.path} is closed")
        self._flush()  # the single slots before it come first
        try:
            block = self._block(arm, success, x=x, t=t, mu_hat=mu_hat, pulls=pulls,
                                candidates=candidates, override=override)  # fmt: skip
        except SlotError as exc:
            self._fail(exc)
            raise
        self._write(block)

    # ------------------------------------------------------------------ closing

    def close(self) -> Path:
        """Write the slots still pending and finish every file; returns the log's path."""
        return self._close(interrupted=False)

    def _close(self, *, interrupted: bool) -> Path:
        if self.closed:
            assert self.result is not None
            return self.result
        self._flush()
        self._open()
        assert self._stack is not None and self._log is not None
        self.closed = True
        if self.open_ended:  # no horizon: complete when closed, interrupted on Ctrl-C
            try:
                self._log.close(complete=not interrupted)
            except BaseException:
                self._stack.close()
                raise
        self._stack.close()
        self.result = self._log.path if self._log.finished else self._log.partial_path
        return self.result

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self.closed:
            return
        if exc_type is None or issubclass(exc_type, (KeyboardInterrupt, SystemExit)):
            self._close(interrupted=exc_type is not None)  # Ctrl-C: the slots so far
        elif exc is not None:
            text = " ".join(str(exc).split()) or type(exc).__name__
            self._fail(exc if isinstance(exc, CorraoiError) else
                       CorraoiError(f"{type(exc).__name__}: {text}"))  # fmt: skip

    def __repr__(self) -> str:
        state = "closed" if self.closed else "open"
        of = "" if self.open_ended else f"/{self.horizon}"
        return f"Logger({str(self.path)!r}, {self.t}{of} slots, {state})"

    # ------------------------------------------------------------------ internals

    def _fields_given(self, given: tuple[bool, ...], n: int) -> None:
        """The first slot fixes which optional fields the log holds; later ones match it."""
        names = ("x", *GIVEN_FIELDS)
        if self._given is None:
            self._given = given
            self._pending = {f: [] for f in ("arm", "success")}
            self._pending.update({f: [] for f, g in zip(names, given, strict=True) if g})
            held = {*COMPUTED, *(f for f, g in zip(names, given, strict=True) if g)}
            if given[0]:
                held.update(NEEDS_X)
            if self._mu_star is None:  # the estimator needs the instance's mu*
                held.discard("estimator")
            self._absent = tuple(f for f in FIELDS if f not in held)
            return
        for name, now, before in zip(names, given, self._given, strict=True):
            if now != before:
                said = "gives" if before else "does not give"
                raise SlotError(f"slot {n}: {name} {'missing' if before else 'given'}, but the "
                                f"log {said} it (its first slot decided)")  # fmt: skip

    def _open(self) -> None:
        """Open the sinks, once the first slot said which fields the log holds."""
        if self._stack is not None:
            return
        from corraoi.recorder.rerun.sink import LocalRecording

        self.config = self._base
        wrote = f"slots given to corraoi.Logger by {self.source or 'an unnamed program'}"
        if self.version:
            wrote += f" version {self.version}"
        provenance = Provenance(versions(), "external", (), (f"{wrote} (corraoi {__version__})",))
        stack = ExitStack()
        try:
            recording: RunRecording | None = None
            if self.rrd is not None:
                recording = stack.enter_context(
                    LocalRecording(self.config, rrd_path=self.rrd, overwrite=self.overwrite)
                )
            self._log = stack.enter_context(
                # each chunk written before the next slot is taken: slots that cannot be
                # run again are lost to a kill only after the last multiple of flush_every
                McapSink(self.path, self.config, overwrite=self.overwrite, provenance=provenance,
                         background=False)  # fmt: skip
            )
            self._every = [self._log, *([recording] if recording is not None else []),
                           *(stack.enter_context(s) for s in self._sinks)]  # fmt: skip
        except BaseException:
            stack.close()
            raise
        self._stack = stack

    def _flush(self) -> None:
        """Hand the pending single slots to the sinks as one block."""
        pending = self._pending
        if not pending or not pending["arm"]:
            return
        arrays = {f: np.asarray(v) for f, v in pending.items()}
        for v in pending.values():
            v.clear()
        self._write(self._compute(arrays))

    def _write(self, block: SlotBlock) -> None:
        self._open()
        for sink in self._every:
            sink.write(block)
        self._written = int(block.t[-1])

    def _compute(self, given: dict[str, np.ndarray]) -> SlotBlock:
        """The block of the next slots from the arrays given (0-based arms and states):
        the age, counts, means, estimator, and with ``x`` the oracle's age and regret,
        carried on from the slots before."""
        arm = given["arm"].astype(np.int64, copy=False)
        success = given["success"].astype(bool, copy=False)
        B, K = arm.size, self.K
        first = self._written + 1
        t = np.arange(first, first + B, dtype=np.int64)
        aoi = _ages(success, self._aoi)
        self._aoi = int(aoi[-1])
        aoisum = self._aoisum + np.cumsum(aoi)
        self._aoisum = int(aoisum[-1])
        cols: dict[str, Any] = {"t": t, "arm": arm, "success": success, "aoi": aoi}
        if self._mu_star is not None:
            cols["estimator"] = aoisum - t / self._mu_star
        onehot = np.zeros((B, K), dtype=np.int64)
        onehot[np.arange(B), arm] = 1
        pulls = self._pulls + np.cumsum(onehot, axis=0)
        succ = self._succ + np.cumsum(onehot * success[:, None], axis=0)
        self._pulls, self._succ = pulls[-1].copy(), succ[-1].copy()
        with np.errstate(invalid="ignore", divide="ignore"):
            mu = np.where(pulls > 0, succ / np.maximum(pulls, 1), 0.0)
        cols["mu_hat"], cols["pulls"] = mu, pulls
        if "x" in given and self._Y is not None and self._best is not None:
            x = given["x"].astype(np.int64, copy=False)
            oracle = _ages(self._Y[self._best, x], self._oracle_aoi)
            self._oracle_aoi = int(oracle[-1])
            regret = self._regret + np.cumsum(aoi - oracle)
            self._regret = int(regret[-1])
            cols.update(x=x, oracle_aoi=oracle, regret=regret)
        for f in GIVEN_FIELDS:
            if f in given:
                cols[f] = given[f].astype(BY_NAME[f].dtype, copy=False)
        for f in self._absent:
            cols[f] = absent_column(f, B, K)
        return SlotBlock(**cols, absent=self._absent)

    def _block(self, arm: ArrayLike, success: ArrayLike, **fields: ArrayLike | None) -> SlotBlock:
        """Check a block's arrays (one SlotError naming the argument and the slot) and
        compute its slots."""
        first = self.t + 1
        a = _array(arm, "arm", first)
        B = a.shape[0]
        if B == 0:
            raise SlotError(f"slot {first}: arm: an empty block")
        arrays: dict[str, np.ndarray] = {"arm": a}
        for name, value in (("success", success), *fields.items()):
            if value is None:
                continue
            arr = _array(value, name, first, 2 if name in ARM_FIELDS else 1)
            if arr.shape[0] != B:
                raise SlotError(f"slots {first}..: {name} has {arr.shape[0]} entries but arm "
                                f"has {B}; expected one per slot")  # fmt: skip
            if name in ARM_FIELDS and arr.shape[1] != self.K:
                raise SlotError(f"slots {first}..: {name} has {arr.shape[1]} columns; expected "
                                f"one per arm ({self.K})")  # fmt: skip
            arrays[name] = arr
        if "success" not in arrays:
            raise SlotError(f"slots {first}..: success: missing")
        if "t" in arrays:
            t = arrays.pop("t")
            want = np.arange(first, first + B)
            if t.dtype.kind not in "iu" or not np.array_equal(t, want):
                i = int(np.argmax(t != want)) if t.shape == want.shape else 0
                self._bad_t(t[i].item(), first + i)
        if first + B - 1 > self.horizon:
            raise SlotError(f"slot {self.horizon + 1}: past the horizon {self.horizon} of the log")
        self._check_ints(arrays["arm"], "arm", first, 1, self.K)
        self._check_bools(arrays, first)
        if "x" in arrays and self._Y is None:
            self._no_instance_x(first)
        given = (*(f in arrays for f in ("x", *GIVEN_FIELDS)),)
        if given != self._given:
            self._fields_given(given, first)
        if "x" in arrays:
            self._check_ints(arrays["x"], "x", first, 1, self.n_states)
            arrays["x"] = arrays["x"].astype(np.int64) - 1
        arrays["arm"] = arrays["arm"].astype(np.int64) - 1
        if "x" in arrays and self._Y is not None:
            want = self._Y[arrays["arm"], arrays["x"]]
            wrong = want != arrays["success"]
            if wrong.any():
                i = int(np.argmax(wrong))
                raise SlotError(
                    f"slot {first + i}: success {bool(arrays['success'][i])} but the instance's "
                    f"Y[arm {int(arrays['arm'][i]) + 1}, x {int(arrays['x'][i]) + 1}] is "
                    f"{int(want[i])}; expected them to agree"
                )
        if "mu_hat" in arrays:
            mu = arrays["mu_hat"]
            bad = ~((mu >= 0) & (mu <= 1)) if mu.dtype.kind in "iuf" else None
            if bad is None or bad.any():
                i = 0 if bad is None else int(np.argmax(bad.any(axis=1)))
                raise SlotError(f"slot {first + i}: mu_hat: expected K numbers in [0, 1]")
            arrays["mu_hat"] = mu.astype(np.float64)
        if "pulls" in arrays:
            self._check_ints(arrays["pulls"], "pulls", first, 0, None)
        if "candidates" in arrays and arrays["candidates"].dtype != bool:
            raise SlotError(f"slots {first}..: candidates: expected a (slots, K) bool mask")
        self.t = first + B - 1
        return self._compute(arrays)

    def _check_ints(self, arr: np.ndarray, name: str, first: int, lo: int,
                    hi: int | None) -> None:  # fmt: skip
        if arr.dtype.kind not in "iu":
            raise SlotError(f"slots {first}..: {name}: expected integers, got {arr.dtype}")
        bad = (arr < lo) | (arr > hi) if hi is not None else arr < lo
        if bad.any():
            i = int(np.argmax(bad.reshape(bad.shape[0], -1).any(axis=1)))
            want = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
            value = arr[i].tolist()
            raise SlotError(f"slot {first + i}: {name} {value}: expected {want}")

    @staticmethod
    def _check_bools(arrays: dict[str, np.ndarray], first: int) -> None:
        for name in ("success", "override"):
            if name in arrays and arrays[name].dtype != bool:
                raise SlotError(f"slots {first}..: {name}: expected bools, got "
                                f"{arrays[name].dtype}")  # fmt: skip

    def _no_instance_x(self, n: int) -> NoReturn:
        raise SlotError(
            f"slot {n}: x given, but the log has no instance (instance=None): a hidden state "
            "is one of an instance's states; give instance= the slots were played on, or "
            "leave x out"
        )

    @staticmethod
    def _bad_t(t: object, n: int) -> None:
        word = "goes backwards" if isinstance(t, int) and t < n else "skips slots"
        if not isinstance(t, int) or isinstance(t, bool):
            raise SlotError(f"slot {n}: t {t!r}: expected the slot number {n}")
        raise SlotError(f"slot {n}: t {t} {word}; expected the slot number {n}")

    @staticmethod
    def _integer(value: Any, name: str, n: int) -> int:
        if isinstance(value, (bool, np.bool_)):
            raise SlotError(f"slot {n}: {name} {value!r}: expected an integer, not a bool")
        try:
            return operator.index(value)
        except TypeError:
            raise SlotError(f"slot {n}: {name} {value!r}: expected an integer") from None

    @staticmethod
    def _boolean(value: object, name: str, n: int) -> bool:
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        raise SlotError(f"slot {n}: {name} {value!r}: expected a bool (True or False)")

    def _row(self, value: Any, name: str, n: int, kind: type) -> list[Any]:
        row = list(value) if not isinstance(value, (str, bytes)) else None
        if row is None or len(row) != self.K:
            raise SlotError(f"slot {n}: {name}: expected {self.K} numbers, one per arm")
        arr = np.asarray(row)
        if kind is int:
            if arr.dtype.kind not in "iu" or (arr < 0).any():
                raise SlotError(f"slot {n}: pulls {row}: expected {self.K} integers >= 0")
        elif arr.dtype.kind not in "iuf" or not ((arr >= 0) & (arr <= 1)).all():
            raise SlotError(f"slot {n}: mu_hat {row}: expected {self.K} numbers in [0, 1]")
        return row

    def _candidate_row(self, value: ArrayLike, n: int) -> np.ndarray:
        arr = np.asarray(value)
        if arr.dtype == bool and arr.shape == (self.K,):
            return arr
        if arr.ndim == 1 and arr.dtype.kind in "iu" and arr.size and (
                (arr >= 1) & (arr <= self.K)).all():  # fmt: skip
            mask = np.zeros(self.K, dtype=bool)
            mask[arr - 1] = True
            return mask
        raise SlotError(f"slot {n}: candidates {value!r}: expected arms in 1..{self.K} or a "
                        f"mask of {self.K} bools")  # fmt: skip

    def _fail(self, exc: BaseException) -> None:
        """The run stopped on ``exc``: the good slots written, the log finished as failed at
        its ``.partial`` name, the other sinks aborted."""
        if self.closed:
            return
        self.closed = True
        try:
            self._flush()
        except CorraoiError:
            pass
        if self._stack is None:  # nothing was written: no file
            return
        assert self._log is not None
        self.result = self._log.fail(str(exc))
        try:
            self._stack.__exit__(type(exc), exc, exc.__traceback__)
        except CorraoiError:
            pass


def _ages(success: np.ndarray, before: int) -> np.ndarray:
    """The age after each slot: 1 after a success, one more than before otherwise."""
    idx = np.arange(success.size, dtype=np.int64)
    last = np.maximum.accumulate(np.where(success, idx, -1))
    return np.where(last >= 0, idx - last + 1, before + idx + 1)


def _array(value: ArrayLike, name: str, first: int, ndim: int = 1) -> np.ndarray:
    arr = np.asarray(value)
    if arr.ndim != ndim or arr.dtype == object:
        shape = "one entry per slot" if ndim == 1 else "one row of K per slot"
        raise SlotError(f"slots {first}..: {name} has shape {arr.shape}; expected {shape}")
    return arr


__all__ = ["EXTERNAL_PREFIX", "Logger"]
