"""What the commands that read logs share (replay, compare, diff, info, recover): the log
argument and the progress bar.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

#: A log argument: a file or a folder; existence is checked by the reader.
LOG = click.Path(dir_okay=True, path_type=Path)


def progress(total: int, label: str) -> Any:
    from corraoi.progress import Progress

    return Progress(total, label)


__all__ = ["LOG", "progress"]
