"""The live-viewer options that record, replay and compare share: --spawn, --connect,
--serve-web (with --web-port), --foxglove and --pace; the viewer they choose is the face's
(:mod:`corraoi.face.live`), its notices on stderr."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import click

from corraoi.face.live import FoxgloveChoice, ViewerChoice

from .options import PORT

F = TypeVar("F", bound=Callable[..., Any])

#: Where --connect sends without a URL: a viewer started with plain `rerun`.
CONNECT_DEFAULT = "rerun+http://127.0.0.1:9876/proxy"


def viewer_options(func: F) -> F:
    """Add --spawn, --connect [URL], --serve-web and --web-port to a command."""
    func = click.option(
        "--web-port",
        type=PORT,
        default=9090,
        show_default=True,
        help="Port of --serve-web (another free one is taken if it is busy).",
    )(func)
    func = click.option(
        "--serve-web",
        is_flag=True,
        help="Serve the Rerun web viewer on 127.0.0.1 and stream to it; it keeps serving "
        "afterwards until Ctrl-C.",
    )(func)
    func = click.option(
        "--connect",
        metavar="URL",
        is_flag=False,
        flag_value=CONNECT_DEFAULT,
        default=None,
        help=f"Stream to a running Rerun viewer [URL default: {CONNECT_DEFAULT}; a port "
        "number also works].",
    )(func)
    func = click.option(
        "--spawn",
        is_flag=True,
        help="Start a local Rerun viewer and stream to it (needs a display).",
    )(func)
    return func


def foxglove_options(func: F) -> F:
    """Add --foxglove [[HOST:]PORT] and --pace SLOTS_PER_S (corraoi.recorder.live.foxglove)."""
    func = click.option(
        "--pace",
        type=click.FloatRange(min=0, min_open=True),
        default=None,
        metavar="SLOTS_PER_S",
        help="With --foxglove: at most this many slots per second, to watch [default: as "
        "fast as it runs; a client that cannot keep up misses the oldest slots].",
    )(func)
    func = click.option(
        "--foxglove",
        metavar="[HOST:]PORT",
        is_flag=False,
        flag_value="127.0.0.1:8765",
        default=None,
        help="Serve the slots live over the Foxglove WebSocket protocol [default "
        "127.0.0.1:8765; loopback unless a host is given]. Needs the foxglove extra.",
    )(func)
    return func


def notice(line: str) -> None:
    """A live viewer's notice: one line on stderr."""
    click.echo(line, err=True)


def viewer_choice(*, spawn: bool, connect: str | None, serve_web: bool,
                  web_port: int) -> ViewerChoice:  # fmt: skip
    """The Rerun viewer the options chose (:class:`corraoi.face.live.ViewerChoice`)."""
    return ViewerChoice(spawn=spawn, connect=connect, serve_web=serve_web, web_port=web_port,
                        say=notice)  # fmt: skip


def foxglove_choice(address: str | None, *, pace: float | None,
                    several: bool = False) -> FoxgloveChoice:  # fmt: skip
    """The Foxglove server the options chose (:class:`corraoi.face.live.FoxgloveChoice`)."""
    return FoxgloveChoice(address, pace=pace, several=several, say=notice)
