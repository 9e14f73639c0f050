"""How every command reports: its output, warnings and errors, each one line, and its exit
status (``corraoi: error: ...``), and the group that makes click's usage errors one line too.

The shared options are in :mod:`corraoi.cli.options`.
Kept free of heavy imports (no numba, rerun or mcap) so that ``corraoi --help`` is fast.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

from corraoi.errors import CorraoiError
from corraoi.text import safe_text

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
    """Turn corraoi errors, I/O errors, a package that is not installed (the line naming it
    and the pip command) and Ctrl-C into one line and an exit status.

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
            except ModuleNotFoundError as exc:  # a package corraoi needs is not installed
                from corraoi.extras import missing_package

                ctx = click.get_current_context(silent=True)
                missing = missing_package(exc, ctx.command_path if ctx else "corraoi")
                if missing is None:
                    raise
                fail(str(missing), code if code is not None else missing.exit_code)
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
        from corraoi import _signals

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


__all__ = [
    "OneLineGroup",
    "errors_exit",
    "fail",
    "handle_errors",
    "keep_pandas_out",
    "say",
    "warn",
]
