"""Ctrl-C, SIGTERM and SIGHUP in the command line: exit 130 with one line, no traceback.

Installed by the CLI only (a library user's signal handling is left alone): from the
import of ``corraoi`` on when the process is the ``corraoi`` command, and again when the
command group starts. SIGTERM and SIGHUP (a closed terminal) raise KeyboardInterrupt like
Ctrl-C, so all take the same way out: the commands finish what they wrote (a record's log
is finished and marked interrupted) and exit 130, whichever the signal. A KeyboardInterrupt
that reaches the top (start-up, before any handler) prints ``corraoi: interrupted`` and
exits 130.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType, TracebackType

INTERRUPTED = 130
_installed = False
#: The signal that asked the command to stop, once one has (never reset): the
#: KeyboardInterrupt a handler raises can land where Python swallows it (a weakref callback
#: inside an import: "Exception ignored in ..."); such a one is sent again (``_unraisable``),
#: and the engine also asks here between its pieces of work (:func:`raise_if_asked`). An
#: interrupt is never lost.
asked: int | None = None


def _terminate(signum: int, frame: FrameType | None) -> None:
    global asked
    asked = signum
    raise KeyboardInterrupt


def raise_if_asked() -> None:
    """Raise KeyboardInterrupt if a signal asked the command to stop (see :data:`asked`)."""
    if asked is not None:
        raise KeyboardInterrupt


def _hook(kind: type[BaseException], exc: BaseException, tb: TracebackType | None) -> None:
    if issubclass(kind, KeyboardInterrupt):
        quiet_exit()
    _previous_hook(kind, exc, tb)


_previous_hook = sys.excepthook


def _unraisable(info: sys.UnraisableHookArgs) -> None:
    """A KeyboardInterrupt the handler raised where Python can only print it and go on (a
    finaliser, a weakref callback, a fork's hooks) is sent again: the signal is sent anew,
    and its handler runs once that code has returned, where the interrupt is an exception
    the command handles. Printing "Exception ignored ... Traceback" and going on would have
    broken the one-line promise and lost the interrupt (a replay ran to its end, exit 0)."""
    if asked is not None and isinstance(info.exc_value, KeyboardInterrupt):
        # from another thread, a moment later: raised here, or at once, the handler would
        # run inside this hook again (where it is swallowed too)
        again = threading.Timer(0.01, os.kill, args=(os.getpid(), asked))
        again.daemon = True
        again.start()
        return
    _previous_unraisable(info)


_previous_unraisable = sys.unraisablehook


def quiet_exit(code: int = INTERRUPTED) -> None:
    """Say ``corraoi: interrupted`` on stderr and leave at once with ``code``."""
    try:
        sys.stderr.write("corraoi: interrupted\n")
    except (OSError, ValueError):
        pass
    leave(code)


def leave(code: int) -> None:
    """Flush stdout and stderr and exit with exactly ``code``, skipping the interpreter's
    shutdown: after an interrupt, a KeyboardInterrupt seen anywhere earlier can make
    CPython end the process by re-raising SIGINT (status -2 instead of 130). The commands
    have finished or discarded their files before they get here."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(code)


def install() -> None:
    """SIGTERM as Ctrl-C, and no traceback for a Ctrl-C that nothing caught (main thread)."""
    global _installed
    if _installed:
        return
    try:
        for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
            if sig is not None and signal.getsignal(sig) in (signal.SIG_DFL, None):
                signal.signal(sig, _terminate)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _terminate)  # the same, and remembered
        # started in the background with SIGINT ignored: keep it so
    except ValueError:  # not the main thread
        return
    sys.excepthook = _hook
    sys.unraisablehook = _unraisable
    _installed = True


def is_cli() -> bool:
    """Whether this process is the ``corraoi`` command (console script or ``-m corraoi``)."""
    argv0 = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    if argv0 == "corraoi":
        return True
    orig = list(getattr(sys, "orig_argv", []))
    for i, word in enumerate(orig[:-1]):
        if word == "-m":
            return orig[i + 1] in ("corraoi", "corraoi.cli")
    return False


def finished() -> None:
    """The command is done and about to exit: ignore further Ctrl-C/SIGTERM, so that the
    interpreter's shutdown is never interrupted into a traceback."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    except ValueError:
        pass
