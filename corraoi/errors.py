"""Typed errors. Each says what was expected and what came; the CLI prints one line."""

from __future__ import annotations

from pathlib import Path
from typing import Any


class CorraoiError(Exception):
    """Base class of every error corraoi raises on purpose.

    ``exit_code`` is what the CLI exits with: 2 for usage errors (bad input named on the
    command line), 1 for failures while working.
    """

    exit_code = 1


class CorraoiWarning(UserWarning):
    """What corraoi warns a Python caller about (a parameter that changes several policies,
    a viewer that could not be reached while the files were written)."""


class UsageError(CorraoiError):
    """A bad argument, option value or input file."""

    exit_code = 2


class InstanceError(UsageError):
    """A malformed instance (file or arrays)."""


class PolicyError(UsageError):
    """An unknown policy or a bad policy parameter."""


class ConfigError(UsageError):
    """A bad run setting (horizon, runs, seed, ...)."""


class MissingExtraError(CorraoiError):
    """An optional dependency is not installed; the message names the extra to install."""


class OutputError(UsageError):
    """An output path that cannot be used: it exists (without --force), is a directory, is
    being written by another process, ..."""


# A wrong argument of a Python call (corraoi.arguments checks them at the door) raises the
# error of its kind that is also Python's TypeError (a wrong type) or ValueError (a value out
# of range, a word not among those accepted), so that ``except TypeError`` catches it too.


class ArgumentTypeError(UsageError, TypeError):
    """An argument of the wrong type (a UsageError and a TypeError)."""


class ArgumentValueError(UsageError, ValueError):
    """An argument of the right type but a value that is not accepted (a UsageError and a
    ValueError)."""


class PolicyTypeError(PolicyError, ArgumentTypeError):
    """A policy, a ``Param`` or a ``params`` table of the wrong type."""


class PolicyValueError(PolicyError, ArgumentValueError):
    """A policy, a ``Param`` or a ``params`` table with a value that is not accepted."""


class InstanceTypeError(InstanceError, ArgumentTypeError):
    """An ``instance`` argument of the wrong type."""


class InstanceValueError(InstanceError, ArgumentValueError):
    """An ``instance`` argument with a value that is not accepted (an empty list)."""


class ConfigTypeError(ConfigError, ArgumentTypeError):
    """A run setting (horizon, seed, runs, channel, workers, ...) of the wrong type."""


class ConfigValueError(ConfigError, ArgumentValueError):
    """A run setting out of its range (a horizon of 0, 2.5 runs, ...)."""


class OutputTypeError(OutputError, ArgumentTypeError):
    """An output path argument of the wrong type."""


class OutputValueError(OutputError, ArgumentValueError):
    """An output path argument that names no file (empty, a NUL byte)."""


class WriteError(CorraoiError):
    """An I/O failure while writing a file (disk full, file too large, device gone, ...)."""

    exit_code = 1


class CodeChanged(PolicyError):
    """A plug-in file whose bytes are not those a run or sweep recorded (its sha256 differs):
    never run under the old hash. ``path``, ``expected`` and ``found`` (hex digests)."""

    def __init__(self, path: str, expected: str, found: str, way_out: str = "") -> None:
        self.path, self.expected, self.found = path, expected, found
        text = (f"{path}: the plug-in's code has changed (sha256:{expected[:16]} recorded, "
                f"sha256:{found[:16]} now)")  # fmt: skip
        super().__init__(text + (f"; {way_out}" if way_out else ""))

    def with_way_out(self, way_out: str) -> CodeChanged:
        return CodeChanged(self.path, self.expected, self.found, way_out)


class LogError(UsageError):
    """A log that cannot be read: missing, not MCAP, not corraoi's, too new, or damaged."""


class ViewerError(CorraoiError):
    """A Rerun viewer that cannot be reached or started. The files are still written."""

    exit_code = 1


class SweepMismatch(CorraoiError):
    """A run recorded again from a sweep whose regret differs from the sweep's row (the
    engine or the code changed since the sweep): the log is finished as failed, saying so."""

    exit_code = 1


class ResultsError(LogError):
    """A results file that cannot be read (missing, not Parquet, not ours, newer)."""


class SweepLogError(LogError):
    """A sweep log that cannot be read (missing, not MCAP, not a sweep log, damaged)."""


class PolicyRuntimeError(CorraoiError):
    """A policy that failed or returned something that is not one valid arm per run.

    ``done``: slots completed before the failure; ``partial``: their columns (when recording).
    """

    exit_code = 1

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.done = 0
        self.partial: Any = None


class KernelError(CorraoiError):
    """A compiled policy whose hooks cannot be composed into a kernel."""

    exit_code = 2


class ClusterError(CorraoiError):
    """The cluster cannot run the sweep (unreachable, version mismatch, chunk failed)."""

    exit_code = 1


class DamagedPart(ConfigError):
    """A part file that cannot be counted (its chunk is not finished)."""

    def __init__(self, path: Path, why: str) -> None:
        super().__init__(f"{path}: a damaged part file ({why})")
        self.path = path


class GpuUnavailable(CorraoiError):
    """No device can run the GPU backend here (the message says why and what to do)."""

    exit_code = 2


class FoxgloveError(CorraoiError):
    """The Foxglove server cannot be started (port taken, host unknown, ...)."""

    exit_code = 1


class FigureUnavailable(CorraoiError):
    """matplotlib is not installed: the figure cannot be drawn (the logs are fine)."""

    exit_code = 1


class SlotError(UsageError):
    """A slot handed to :class:`corraoi.Logger` (or an environment's ``step``) that cannot be
    logged: an arm or state out of range, a success that is not a bool or contradicts the
    instance, a slot number out of order, a field of the wrong shape. The message names the
    argument and the slot; the log is left readable up to the last good slot, marked
    failed."""
