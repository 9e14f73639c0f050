"""Running ``corraoi record``'s plans one after another: each run into its files (through
corraoi.face.recording.record_run) with a progress bar, Ctrl-C/SIGTERM finishing the files at the
next block, and the summary printed (or its JSON) once they are done.
"""

from __future__ import annotations

import json
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

import click

from corraoi.text import safe_text

from .common import keep_pandas_out
from .record_plan import Plan


@dataclass(frozen=True)
class Outlets:
    """Where every run of one ``record`` goes besides its files, decided once by the command:
    the Rerun viewer's URL, whether files may be overwritten, the Foxglove server
    (``live.FoxgloveChoice``) and the forked Rerun worker (``recorder.rerun.worker``)."""

    viewer_url: str | None
    overwrite: bool
    live: Any = None
    rerun: Any = None


@dataclass
class Result:
    plan: Plan
    slots: int = 0
    wall: float = 0.0
    regret: int | None = None
    estimator: float | None = None
    pulls: list[int] = field(default_factory=list)
    mcap: Path | None = None
    rrd: Path | None = None
    #: seconds of the wall time spent compiling the kernels (first use only)
    compile_s: float = 0.0


class Stop:
    """SIGINT/SIGTERM/SIGHUP while recording: the first asks the loop to stop at the next block
    (the files are then finished with every slot simulated so far); a second one raises
    KeyboardInterrupt at once."""

    def __init__(self) -> None:
        self.signal: str | None = None
        self._old: dict[int, Any] = {}

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signal is not None:
            raise KeyboardInterrupt
        self.signal = signal.Signals(signum).name

    def __enter__(self) -> Stop:
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            try:
                self._old[sig] = signal.signal(sig, self._handle)
            except ValueError:  # not the main thread: keep the defaults
                pass
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()


def record_all(
    plans: list[Plan], outlets: Outlets
) -> tuple[list[Result], str | None, str | None]:
    """Run every plan in turn; returns (results, signal that stopped us, viewer problem)."""
    from corraoi.engine.threads import set_workers
    from corraoi.progress import Progress

    # One run has nothing to spread over threads, and idle numba workers compete with
    # Rerun's encoder threads for the cores: 2-3x slower on a 2-core machine.
    set_workers(1)
    if outlets.rerun is None and (
        outlets.viewer_url is not None or any(p.rrd is not None for p in plans)
    ):
        keep_pandas_out()  # Rerun's logging goes through pyarrow
    _prepare_kernels(plans)
    results: list[Result] = []
    viewer_problem: str | None = None
    total = sum(p.config.horizon for p in plans)
    with Stop() as stop, Progress(total, "record") as bar:
        for plan in plans:
            result = Result(plan)
            results.append(result)
            problem = _record_one(plan, result, outlets, stop, bar)
            viewer_problem = viewer_problem or problem
            if stop.signal:
                return results, stop.signal, viewer_problem
    return results, None, viewer_problem


def _prepare_kernels(plans: list[Plan]) -> None:
    """Several policy families to record for the first time: compile their record kernels
    at once, one worker process per core, before the first run starts."""
    from corraoi.engine import kernel_pool
    from corraoi.policies.api import CompiledPolicy

    classes = {}
    for plan in plans:
        if plan.config.streams != "cpu":  # a GPU sweep's run: the GPU kernel decides it
            continue
        cls = plan.config.policy.resolve()
        if isinstance(cls, type) and issubclass(cls, CompiledPolicy):
            classes[cls.name] = cls
    kernel_pool.prepare(classes.values(), record=True)


def _record_one(plan: Plan, result: Result, outlets: Outlets, stop: Stop, bar: Any) -> str | None:
    """Record one run into its files; returns a problem with the viewer, if any."""
    from corraoi.engine import kernels
    from corraoi.errors import PolicyRuntimeError

    start = time.perf_counter()
    compiled_before = kernels.compile_seconds  # compiling is not the run: left out of slots/s
    try:
        return _record_into(plan, result, outlets, stop, bar, start, compiled_before)
    except PolicyRuntimeError as exc:
        from corraoi.files.partial import partial_path

        where = partial_path(plan.mcap)
        left = (f"; the log is left as {where}, marked failed" if where.exists()
                else f"; no log written ({plan.mcap} would have held no slot)")
        raise type(exc)(f"{exc}{left}") from None


def _record_into(
    plan: Plan,
    result: Result,
    outlets: Outlets,
    stop: Stop,
    bar: Any,
    start: float,
    compiled_before: float,
) -> str | None:
    from corraoi.engine import kernels
    from corraoi.face.recording import record_run

    config = plan.config
    live = outlets.live
    # with --pace, the Foxglove sink's write is what slows the run
    fox = live.sink(config, lambda: stop.signal is not None) if live is not None else None

    def on_block(block: Any) -> None:
        result.slots = int(block.t[-1])
        result.regret = int(block.regret[-1])
        result.estimator = float(block.estimator[-1])
        result.pulls = [int(v) for v in block.pulls[-1]]
        bar.update(len(block), note=f"{config.label} slot {result.slots}")

    try:
        outcome = record_run(
            config, plan.mcap, rrd=plan.rrd, viewer_url=outlets.viewer_url,
            overwrite=outlets.overwrite,
            on_block=on_block, should_stop=lambda: stop.signal is not None, rerun=outlets.rerun,
            sinks=[fox] if fox is not None else [],
            expect=plan.drill.expect if plan.drill is not None else (),
            notes=plan.drill.notes if plan.drill is not None else (),
        )  # fmt: skip
    finally:
        result.wall = time.perf_counter() - start
        result.compile_s = kernels.compile_seconds - compiled_before
    result.mcap, result.rrd = outcome.mcap, outcome.rrd
    return outcome.viewer_problem


def report(results: list[Result], *, as_json: bool) -> None:
    from recorder.live.viewers import view_command

    rrds = [str(r.rrd) for r in results if r.rrd is not None]
    command = view_command(rrds) if rrds else None
    if as_json:
        out = {
            "runs": [
                {
                    "label": r.plan.config.label,
                    "policy": r.plan.config.policy.name,
                    "params": r.plan.config.policy.params,
                    "instance": r.plan.config.instance.name,
                    "seed": r.plan.config.seed,
                    "horizon": r.plan.config.horizon,
                    "slots": r.slots,
                    "complete": r.slots == r.plan.config.horizon,
                    "regret": r.regret,
                    "estimator": r.estimator,
                    "pulls": r.pulls,
                    "mcap": str(r.mcap) if r.mcap else None,
                    "rrd": str(r.rrd) if r.rrd else None,
                    "wall_s": round(r.wall, 4),
                    "compile_s": round(r.compile_s, 4),
                }
                for r in results
            ],
            "view": command,
        }
        click.echo(json.dumps(out, indent=2))
        return
    for r in results:
        c = r.plan.config
        params = ", ".join(f"{k}={v:g}" for k, v in c.policy.params.items())
        run_s = r.wall - r.compile_s
        rate = r.slots / run_s if run_s > 0 else 0.0
        compiled = f", after {r.compile_s:.1f} s compiling" if r.compile_s else ""
        done = "" if r.slots == c.horizon else " (interrupted)"
        click.echo(
            f"{safe_text(c.policy.name)}{f' ({params})' if params else ''} on "
            f"{safe_text(c.instance.name)}, seed "
            f"{c.seed}: {r.slots} of {c.horizon} slots{done} in {r.wall:.2f} s "
            f"({rate:,.0f} slots/s{compiled})"
        )
        if r.regret is not None and r.estimator is not None:
            click.echo(
                f"  AoI regret at slot {r.slots}: {r.regret} (pathwise), "
                f"{r.estimator:.1f} (paper's estimator sum aoi - t/mu*)"
            )
            pulls = "  ".join(f"{k + 1}: {n}" for k, n in enumerate(r.pulls))
            click.echo(f"  pulls per arm: {pulls}")
        click.echo(f"  MCAP log:        {safe_text(r.mcap)}")
        if r.rrd is not None:
            click.echo(f"  Rerun recording: {safe_text(r.rrd)}")
    if command:
        click.echo(f"open in the Rerun viewer:  {safe_text(command)}")


__all__ = ["Outlets", "Result", "Stop", "record_all", "report"]
