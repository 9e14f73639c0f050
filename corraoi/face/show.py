"""``corraoi.show``: a recorded run or sweep in the Rerun viewer, from its existing ``.rrd``
(nothing is simulated). What it is given is resolved here; the viewers are
:mod:`corraoi.face.viewing`'s, which ``Run.show`` and ``Sweep.show`` open too."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from corraoi import arguments
from corraoi.errors import LogError, UsageError

from .viewing import Shown, check_options, checked_rrd, open_viewer

if TYPE_CHECKING:
    from .runs import Run
    from .sweeps import Sweep

EXPECTED = ("a corraoi.Run, a corraoi.Sweep, or the path of a slot log (.mcap), a Rerun "
            "recording (.rrd) or a sweep folder")  # fmt: skip


def show(
    target: Run | Sweep | str | os.PathLike[str],
    *,
    spawn: bool = False,
    notebook: bool | None = None,
    web_port: int = 9090,
    width: int | str = "auto",
    height: int = 640,
) -> Shown:
    """Show a recorded run or sweep in the Rerun viewer, from its existing Rerun recording
    (nothing is simulated again).

    ``target``: a :class:`corraoi.Run`, a :class:`corraoi.Sweep`, or a path: a slot log
    (``.mcap``, or its ``.partial``; its ``.rrd`` beside it, else one is replayed from the
    log to that place, as ``corraoi replay`` does), a Rerun recording (``.rrd``), or a sweep
    folder or its ``sweep.mcap`` (its ``sweep.rrd``; a grid's folder, every group's).

    ``notebook``: the viewer as a Jupyter widget (``rerun-notebook``, the ``notebook``
    extra; its assets served on 127.0.0.1 by this kernel, so no network is needed; set
    ``RERUN_NOTEBOOK_ASSET`` yourself for a browser on another machine) sized ``width``
    (pixels or ``"auto"``: the cell's width) by ``height`` pixels. Default: when an IPython
    kernel runs this. Otherwise the Rerun web viewer is served on 127.0.0.1 (``web_port``, or
    a free port if it is taken) until :meth:`~corraoi.face.viewing.Shown.close`;
    ``spawn=True`` opens the native viewer instead, only where there is a display (DISPLAY
    or WAYLAND_DISPLAY).

    Returns a :class:`~corraoi.face.viewing.Shown` (``.url``, ``.recordings``, ``.close()``;
    a context manager) at once, without blocking.

    Raises :class:`~corraoi.errors.UsageError` for a ``target`` of another type,
    :class:`~corraoi.errors.LogError` for a missing or unreadable file or a folder without a
    recording, :class:`~corraoi.errors.MissingExtraError` in Jupyter without
    ``rerun-notebook`` (``pip install "corraoi[notebook]"``), and
    :class:`~corraoi.errors.ViewerError` when no viewer can be started (``spawn=True``
    without a display, a web server that does not start).
    """
    from .load import load
    from .runs import Run
    from .sweeps import Sweep

    check_options(spawn=spawn, notebook=notebook, web_port=web_port, width=width,
                  height=height)  # fmt: skip
    options = dict(spawn=spawn, notebook=notebook, web_port=web_port, width=width,
                   height=height)  # fmt: skip
    if isinstance(target, (Run, Sweep)):
        return target.show(**options)
    p = Path(arguments.path(target, name="target", kind=UsageError, what=EXPECTED))
    if not p.exists():
        raise LogError(f"{p}: no such file or folder (show expected {EXPECTED})")
    if p.suffix == ".rrd" and p.is_file():
        return open_viewer(lambda: [checked_rrd(p)], **options)  # type: ignore[arg-type]
    from corraoi.recorder.sweeplog.results import is_sweep_path

    if p.is_dir() and not is_sweep_path(p) and not any(p.glob("*/sweep.rrd")):
        raise LogError(f"{p}: a folder without a sweep (show expected {EXPECTED})")
    loaded = Sweep(p) if p.is_dir() else load(p)
    return loaded.show(**options)


__all__ = ["show"]
