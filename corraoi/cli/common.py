"""Pieces every CLI command shares: option decorators, parsing, and error reporting.

Kept free of heavy imports (no numba, rerun or mcap) so that ``corraoi --help`` is fast.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import click

from .. import limits
from ..errors import CorraoiError
from ..text import safe_text

F = TypeVar("F", bound=Callable[..., Any])


def keep_pandas_out() -> None:
    """Stop pyarrow from importing pandas (0.3 s) in a command that makes no DataFrame.

    pyarrow imports pandas on its first array conversion (``pa.array``, Rerun's logging,
    our Arrow batches) only to ask whether the values are pandas objects; they never are
    here. So, when pandas is not imported yet, let that one probe find it absent. pyarrow
    then treats pandas as not installed for the rest of this process (nothing here hands it
    a DataFrame); ``import pandas`` itself still works. Costs pyarrow's import, which these
    commands pay anyway.
    """
    if "pandas" in sys.modules:
        return
    sys.modules["pandas"] = None  # type: ignore[assignment]  # import pandas -> ImportError
    try:
        import pyarrow.lib

        _ = pyarrow.lib._pandas_api.have_pandas  # the probe, answered "no" and remembered
    except (ImportError, AttributeError):
        pass
    finally:
        del sys.modules["pandas"]


def fail(message: str, code: int = 1) -> None:
    """Print ``corraoi: error: <message>`` on stderr and exit with ``code``."""
    click.echo(f"corraoi: error: {safe_text(message)}", err=True)
    sys.exit(code)


def say(text: object) -> None:
    """Print program output on stdout with anything read from a file made terminal-safe
    (control codes escaped; the program's own newlines kept)."""
    click.echo(safe_text(text, newlines=True))


def warn(message: str) -> None:
    click.echo(f"corraoi: warning: {safe_text(message)}", err=True)


def errors_exit(code: int | None = None) -> Callable[[F], F]:
    """Turn corraoi errors, I/O errors and Ctrl-C into one line and an exit status.

    Errors exit with their own ``exit_code`` (I/O errors with 1), or all with ``code``
    when it is given (``diff`` exits 2 on any trouble, as diff(1)); Ctrl-C exits 130.
    """

    def deco(func: F) -> F:
        @functools.wraps(func)
        def wrapper(*args: Any, **kwargs: Any) -> Any:
            try:
                return func(*args, **kwargs)
            except CorraoiError as exc:
                fail(str(exc), code if code is not None else exc.exit_code)
            except OSError as exc:
                if isinstance(exc, BrokenPipeError) and _stdout_is_gone():
                    _leave_quietly()
                where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
                fail(f"{where}{exc.strerror or exc}", code if code is not None else 1)
            except KeyboardInterrupt:
                click.echo("corraoi: interrupted", err=True)
                sys.exit(130)

        return wrapper  # type: ignore[return-value]

    return deco


def _stdout_is_gone() -> bool:
    """Whether stdout's reader has gone (``corraoi policies | head -1``), rather than some
    other pipe or socket breaking: the write end of a pipe without a reader polls as an
    error (POSIX; elsewhere this says no and the error is reported as any other)."""
    import select

    try:
        poller = select.poll()
        poller.register(sys.stdout.fileno(), select.POLLOUT)
        events = poller.poll(0)
    except (AttributeError, OSError, ValueError):  # no poll(), no file descriptor
        return False
    return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in events)


def _leave_quietly() -> None:
    """The reader of our output stopped reading: not an error to report. Exit 141 (128 +
    SIGPIPE, what a shell shows for a tool that SIGPIPE ended), with stdout pointed at
    /dev/null so that the exit's flush does not fail again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    sys.exit(141)


#: The usual error handling of a command: each error's own exit status.
handle_errors = errors_exit()


class OneLineGroup(click.Group):
    """A click group whose usage errors are one line (``corraoi: error: ...``), exit 2.

    click's default prints the usage, a hint and the error on four lines; the message below
    keeps what and where (the option and the value) and points at ``--help``.
    """

    def main(self, *args: Any, standalone_mode: bool = True, **kwargs: Any) -> Any:
        base = super().main
        if not standalone_mode:
            return base(*args, standalone_mode=False, **kwargs)  # type: ignore[call-overload]
        from .. import _signals

        if not _signals.is_cli():  # in-process (tests, CliRunner): leave signals alone
            return self._main(base, args, kwargs)
        _signals.install()
        try:
            self._main(base, args, kwargs)
        except KeyboardInterrupt:  # between the handlers: still one line and 130
            _signals.quiet_exit()
        except SystemExit as done:
            _signals.finished()
            if done.code == _signals.INTERRUPTED:  # said so already: leave with exactly 130
                _signals.leave(_signals.INTERRUPTED)
            raise done from None

    def _main(self, base: Any, args: Any, kwargs: Any) -> None:
        try:
            code = base(*args, standalone_mode=False, **kwargs)
        except click.exceptions.NoArgsIsHelpError as exc:  # `corraoi` alone: the help
            click.echo(exc.format_message())
            sys.exit(0)
        except click.UsageError as exc:
            if exc.ctx is not None:
                where = exc.ctx.command_path
            else:  # raised while parsing, before the command's context exists
                where = self.command_path_of(kwargs.get("args", args[0] if args else None))
            fail(f"{exc.format_message()} (see '{where} --help')", exc.exit_code)
        except click.ClickException as exc:
            fail(exc.format_message(), exc.exit_code)
        except click.Abort:  # Ctrl-C where no command handled it
            click.echo("corraoi: interrupted", err=True)
            sys.exit(130)
        sys.exit(code if isinstance(code, int) else 0)

    def invoke(self, ctx: click.Context) -> Any:
        """The group's callback and the command, with a Ctrl-C that no command caught (the
        start-up imports) turned into click's Abort here: click would first print an
        empty line on stderr for a KeyboardInterrupt, before our one line."""
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt:
            raise click.Abort() from None

    def command_path_of(self, args: Any) -> str:
        """``corraoi record`` for ``["record", "-p", ...]``: the (sub)commands named."""
        words = list(sys.argv[1:] if args is None else args)
        path = [self.name or "corraoi"]
        cmd: click.Command = self
        for word in words:
            if isinstance(cmd, click.Group) and word in cmd.commands:
                cmd = cmd.commands[word]
                path.append(word)
            elif not word.startswith("-"):
                break
        return " ".join(path)


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
        metavar="NAME=VALUE",
        help="Set a policy parameter (repeatable); it applies to every listed policy that "
        "declares NAME and is checked against its range ('corraoi policies' lists them).",
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


def horizon_option(default: int) -> Callable[[F], F]:
    return click.option(
        "--horizon",
        "-T",
        type=HORIZON,
        default=default,
        show_default=True,
        help=f"Number of slots T (at most {limits.MAX_HORIZON:,}).",
    )


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
