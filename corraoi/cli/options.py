"""The options commands share (instance, policy, parameters, channel, backend, horizon, seed,
``-o/--output``) and the range-checked integer type of every numeric option.

Kept free of heavy imports (no numba, rerun or mcap) so that ``corraoi --help`` is fast.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from corraoi import limits
from corraoi.text import safe_text

F = TypeVar("F", bound=Callable[..., Any])


def instance_option(func: F) -> F:
    return click.option(
        "--instance",
        "-i",
        "instance",
        default="I1",
        show_default=True,
        metavar="NAME|PATH",
        help="Built-in instance (I1, I2) or an instance file (.txt community format, "
        ".json, .toml).",
    )(func)


def policy_option(
    default: tuple[str, ...] | None = None, *, required: bool | None = None
) -> Callable[[F], F]:
    def deco(func: F) -> F:
        return click.option(
            "--policy",
            "-p",
            "policy",
            multiple=True,
            default=default,
            required=default is None if required is None else required,
            metavar="NAME[,NAME...]",
            help="Policy: a built-in (ucb, ts, ts-gauss, cucb, cts, cts-gauss, aoi-aware-<any>, "
            "q-ucb, q-ts, sw-ucb, d-ts, ...: see 'corraoi policies'), a plug-in FILE.py:Class or "
            "package.module:Class, or an entry-point name; a comma list, the flag repeated, or "
            "'all' (the paper's twelve).",
        )(func)

    return deco


def param_options(func: F) -> F:
    func = click.option(
        "--param",
        "param",
        multiple=True,
        metavar="[POLICY.]NAME=VALUE",
        help="Set a policy parameter (repeatable): NAME=VALUE applies to every listed policy "
        "that declares NAME (a warning when that is more than one), POLICY.NAME=VALUE to that "
        "policy only; checked against its range ('corraoi policies' lists them).",
    )(func)
    func = click.option(
        "--beta",
        type=float,
        default=None,
        help="Gaussian TS variance scale for ts-gauss/cts-gauss: N(mu_hat, beta/(n+1)) "
        "[default: 1].",
    )(func)
    func = click.option(
        "--c",
        "c",
        type=float,
        default=None,
        help="UCB exploration constant for ucb/cucb: mu_hat + sqrt(c ln t / n) [default: 2].",
    )(func)
    return func


def channel_option(func: F) -> F:
    return click.option(
        "--channel",
        "channel",
        default=None,
        metavar="iid|markov|trace:PATH",
        help="Hidden-state process: iid (X_t ~ p), markov (the instance's transition matrix), "
        "or trace:PATH (replay the hidden path of a .mcap slot log or a text file of 1-based "
        "states) [default: markov for instances with a transition matrix, else iid].",
    )(func)


def backend_option(help: str) -> Callable[[F], F]:
    """``--backend cpu|gpu|auto`` (docs/gpu.md); None when not given."""
    return click.option("--backend", type=click.Choice(["cpu", "gpu", "auto"]), default=None,
                        help=help)  # fmt: skip


class Bounded(click.ParamType):
    """An integer option in ``lo..hi``: anything else (a float, 1e30, a value beyond int64)
    is one line naming the option, the value and the range, before anything is allocated.
    """

    name = "integer"

    def __init__(self, lo: int, hi: int, why: str = "") -> None:
        self.lo, self.hi, self.why = lo, hi, why

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return "INTEGER"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> int:
        because = f" ({self.why})" if self.why else ""
        if isinstance(value, int) and not isinstance(value, bool):
            number = value
        else:
            text = str(value).strip().replace("_", "")
            try:
                number = int(text, 10)
            except ValueError:
                self.fail(
                    f"{safe_text(str(value))!r} is not a valid integer; expected "
                    f"{self.lo}..{self.hi}{because}",
                    param,
                    ctx,
                )
        if not self.lo <= number <= self.hi:
            shown = str(number) if len(str(number)) <= 30 else f"{str(number)[:20]}..."
            rng = f"{self.lo}..{self.hi}{because}"
            self.fail(f"{shown} is not in the range {rng}", param, ctx)
        return number


#: The range types of the shared numeric options (corraoi.limits holds the numbers).
HORIZON = Bounded(1, limits.MAX_HORIZON, "the AoI sums must fit in 64 bits")
SEED = Bounded(0, limits.MAX_SEED, "seeds are 64-bit")
RUNS = Bounded(1, limits.MAX_RUNS)
WORKERS = Bounded(1, limits.MAX_WORKERS)
CHECKPOINTS = Bounded(2, limits.MAX_CHECKPOINTS)
PORT = Bounded(limits.MIN_PORT, limits.MAX_PORT, "a TCP port")
#: Sources: at most the most arms an instance may have (corraoi.model.instance.MAX_ARMS, not
#: imported here: it brings numpy); the instance's own K is checked where it is known.
SOURCES = Bounded(1, 4096, "at most the instance's arms")


def horizon_option(default: int) -> Callable[[F], F]:
    return click.option(
        "--horizon",
        "-T",
        type=HORIZON,
        default=default,
        show_default=True,
        help=f"Number of slots T (at most {limits.MAX_HORIZON:,}).",
    )


def sources_option(func: F) -> F:
    return click.option(
        "--sources",
        type=SOURCES,
        default=1,
        show_default=True,
        help="Number of sources M sharing the channels (1..K): each picks a channel a slot; "
        "two on one channel collide and neither delivers (docs/model.md).",
    )(func)


def seed_option(func: F) -> F:
    return click.option(
        "--seed",
        "-s",
        type=SEED,
        default=0,
        show_default=True,
        help="Integer seed. Run i of a batch uses seed+i; the hidden path depends only on "
        "(instance, seed), so runs of different policies are paired.",
    )(func)


_OUTPUT_KEY = "corraoi.output"


def output_option(
    *,
    metavar: str,
    help: str,
    aliases: tuple[str, ...] = ("--out",),
    default: Any = None,
    path: bool = True,
    show_default: bool = False,
) -> Callable[[F], F]:
    """``-o/--output``: the primary output of a command, passed as ``output``.

    The spellings earlier versions used (``--out``, ``--rrd``, ...) stay accepted as
    hidden aliases; giving two of them is one usage error.
    """
    kind: Any = click.Path(path_type=Path) if path else None

    def take(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        seen = ctx.meta.get(_OUTPUT_KEY)
        source = ctx.get_parameter_source(param.name or "")
        given = source is not None and source.name == "COMMANDLINE"
        if param.name == "output":
            if seen is not None:
                if given:
                    raise click.UsageError(f"-o/--output and {seen[0]}: give the output once")
                return seen[1]
            return value
        if given:  # a hidden alias
            if ctx.params.get("output") is not None and ctx.meta.get("corraoi.output.given"):
                raise click.UsageError(f"-o/--output and {param.opts[0]}: give the output once")
            ctx.meta[_OUTPUT_KEY] = (param.opts[0], value)
            ctx.params["output"] = value
        return None

    def mark(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        source = ctx.get_parameter_source(param.name or "")
        if source is not None and source.name == "COMMANDLINE":
            ctx.meta["corraoi.output.given"] = True
        return take(ctx, param, value)

    def deco(func: F) -> F:
        for alias in reversed(aliases):
            func = click.option(
                alias,
                f"_alias_{alias.lstrip('-').replace('-', '_')}",
                type=kind,
                default=None,
                hidden=True,
                expose_value=False,
                callback=take,
            )(func)
        return click.option(
            "-o",
            "--output",
            "output",
            type=kind,
            default=default,
            show_default=show_default,
            metavar=metavar,
            help=help,
            callback=mark,
        )(func)

    return deco


def code_options(func: F) -> F:
    """``--kept-code`` and ``--allow-changed-code``: what runs when a plug-in's source is not
    the one the sweep ran (corraoi.experiments.kept_code); without either, that is refused."""
    func = click.option(
        "--allow-changed-code", "allow_changed_code", is_flag=True,
        help="With --from: record a plug-in whose source changed since the sweep with its "
        "current code (the log names that code and says so; its regret is not checked "
        "against the sweep's).",
    )(func)  # fmt: skip
    return click.option(
        "--kept-code", "kept_code", is_flag=True,
        help="Run the copy of each plug-in's source the sweep folder kept (plugins/), "
        "whatever the file holds now.",
    )(func)  # fmt: skip


def from_only(run: Any, cell: Any, kept_code: bool, allow_changed_code: bool) -> str:
    """The option that was given without ``--from`` (for its one-line refusal)."""
    if run is not None:
        return "--run"
    if cell:
        return "--cell"
    return "--kept-code" if kept_code else "--allow-changed-code"
