"""Typed errors. Each says what was expected and what came; the CLI prints one line."""

from __future__ import annotations


class CorraoiError(Exception):
    """Base class of every error corraoi raises on purpose.

    ``exit_code`` is what the CLI exits with: 2 for usage errors (bad input named on the
    command line), 1 for failures while working.
    """

    exit_code = 1


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
