"""Errors of the recorder: reading logs, choosing output paths, writing files.

Each carries a one-line message that names the file; the CLI prints it as
``corraoi: error: <message>`` and exits with ``exit_code``.
"""

from __future__ import annotations

from corraoi.errors import CorraoiError, OutputError, UsageError, WriteError

__all__ = ["LogError", "OutputError", "ViewerError", "WriteError"]


class LogError(UsageError):
    """A log that cannot be read: missing, not MCAP, not corraoi's, too new, or damaged."""


class ViewerError(CorraoiError):
    """A Rerun viewer that cannot be reached or started. The files are still written."""

    exit_code = 1
