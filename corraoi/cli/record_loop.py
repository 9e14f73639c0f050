"""Running ``corraoi record``'s plans (:func:`corraoi.face.recording.record_plans`) with a
progress bar, Ctrl-C/SIGTERM finishing the files at the next block, and the summary printed
(or its JSON) once they are done.
"""

from __future__ import annotations

import json
import signal
from types import FrameType
from typing import TYPE_CHECKING, Any

import click

from corraoi.text import safe_text

from .common import keep_pandas_out

if TYPE_CHECKING:  # the face imports the recorder: `corraoi --help` must not
    from corraoi.face.recording import Outlets, Plan, Recorded


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
) -> tuple[list[Recorded], str | None, str | None]:
    """Run every plan in turn (:func:`corraoi.face.recording.record_plans`) with a progress bar,
    the first Ctrl-C/SIGTERM/SIGHUP finishing the files at the next block; returns (results,
    the signal that stopped us, a viewer's problem)."""
    from corraoi.face.recording import record_plans
    from corraoi.progress import Progress

    if outlets.rerun is None and (
        outlets.viewer_url is not None or any(p.rrd is not None for p in plans)
    ):
        keep_pandas_out()  # Rerun's logging goes through pyarrow
    total = sum(p.config.horizon for p in plans)
    with Stop() as stop, Progress(total, "record") as bar:

        def on_block(plan: Plan, block: Any) -> None:
            bar.update(len(block), note=f"{plan.config.label} slot {int(block.t[-1])}")

        results = record_plans(plans, outlets, on_block=on_block,
                               should_stop=lambda: stop.signal is not None)  # fmt: skip
    problem = next((r.viewer_problem for r in results if r.viewer_problem), None)
    return results, stop.signal, problem


def report(results: list[Recorded], *, as_json: bool) -> None:
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


__all__ = ["Stop", "record_all", "report"]
