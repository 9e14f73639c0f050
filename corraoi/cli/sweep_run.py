"""What ``corraoi sweep`` and ``corraoi reproduce`` do with a sweep the face ran
(:func:`corraoi.face.sweeps.sweep_from_options`, ``reproduce_from_options``) that Ctrl-C
stopped: say what is saved and exit with status 130 (:func:`interrupted_or`).
"""

from __future__ import annotations

import sys
from typing import Any

import click


def interrupted_or(done: Any) -> Any:
    """The run the face made (:class:`corraoi.face.sweeps.SweepRun` or ``ReproduceRun``);
    one that Ctrl-C stopped says what is saved and exits with status 130."""
    if done.interrupted is not None:
        click.echo(f"corraoi: {done.interrupted}", err=True)
        sys.exit(130)
    return done


__all__ = ["interrupted_or"]
