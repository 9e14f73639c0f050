"""What the commands that read logs share (replay, compare, diff, info, recover): the log
argument, the refusal of an output path that is one of the inputs, and the progress bar.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import click

from corraoi.errors import UsageError

#: A log argument: a file or a folder; existence is checked by the reader.
LOG = click.Path(dir_okay=True, path_type=Path)


def not_an_input(out: Path, inputs: tuple[Path, ...] | list[Path]) -> None:
    """Refuse an output path that is one of the logs being read (even with --force)."""
    for log in inputs:
        try:
            same = out.exists() and log.exists() and os.path.samefile(out, log)
        except OSError:
            same = False
        if same:
            raise UsageError(f"{out}: is one of the logs being read; give another output path")


def progress(total: int, label: str) -> Any:
    from corraoi.progress import Progress

    return Progress(total, label)


__all__ = ["LOG", "not_an_input", "progress"]
