"""The live viewers a command streams to while it runs: a Rerun viewer (spawned, reached at a
URL, or served on the web) and a Foxglove server, chosen by ``corraoi record``, ``replay`` and
``compare``'s options; their notices go through ``say`` (stderr by default).

corraoi.recorder.live.viewers (and so rerun) is imported only when a viewer is asked for.
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable, Sequence
from types import FrameType
from typing import TYPE_CHECKING, Any

from corraoi.errors import UsageError

if TYPE_CHECKING:
    from corraoi.engine.block import RunConfig
    from corraoi.recorder.live.foxglove import Address, FoxgloveServer, FoxgloveSlotSink
    from corraoi.recorder.live.viewers import WebViewer


def to_stderr(line: str) -> None:
    """A notice, on its own line of stderr."""
    print(line, file=sys.stderr, flush=True)


def _interrupt(signum: int, frame: FrameType | None) -> None:
    raise KeyboardInterrupt


class ViewerChoice:
    """The viewer a command streams to (--spawn, --connect or --serve-web), if any."""

    def __init__(self, *, spawn: bool, connect: str | None, serve_web: bool, web_port: int,
                 say: Callable[[str], None] = to_stderr):  # fmt: skip
        self.say = say
        options = (("--spawn", spawn), ("--connect", connect), ("--serve-web", serve_web))
        asked = [name for name, on in options if on]
        if len(asked) > 1:
            raise UsageError(f"{' and '.join(asked)}: choose one way to reach a viewer")
        self.spawn, self.connect, self.serve_web = spawn, connect, serve_web
        self.web_port = web_port
        self.url: str | None = None
        self.web: WebViewer | None = None
        #: Why the viewer could not be reached (``start(tolerant=True)`` only).
        self.problem: str | None = None
        if connect is not None:
            from corraoi.recorder.live.viewers import normalize_url

            self.connect = normalize_url(connect)  # a bad URL is a usage error: say it now

    @property
    def asked(self) -> bool:
        return bool(self.spawn or self.connect or self.serve_web)

    def start(self, *, tolerant: bool = False) -> str | None:
        """Reach the viewer; returns the gRPC URL to stream to.

        A viewer that cannot be reached raises ViewerError, or with ``tolerant`` prints one
        error line, keeps the reason in :attr:`problem` and returns None (``record`` then
        writes its files and exits 1).
        """
        if not self.asked:
            return None
        from corraoi.errors import ViewerError
        from corraoi.recorder.live import viewers as live

        os.environ.setdefault("RUST_LOG", "off")  # Rerun's own log lines: we report problems
        try:
            if self.connect is not None:
                problem = live.probe(self.connect)
                if problem:
                    raise ViewerError(
                        f"--connect {self.connect}: no Rerun viewer there ({problem})"
                    )
                self.url = self.connect
            elif self.spawn:
                self.url = live.spawn_viewer()
            elif self.serve_web:
                self.web = live.WebViewer(web_port=self.web_port).start()
                self.url = self.web.grpc_url
                self.say(f"web viewer: {self.web.web_url}")
        except ViewerError as exc:
            if not tolerant:
                raise
            self.problem = str(exc)
            self.say(f"corraoi: error: {exc}; writing the files only")
            return None
        return self.url

    def serve_until_stopped(self) -> None:
        """With --serve-web, keep serving until Ctrl-C or SIGTERM, then stop the server."""
        if self.web is None:
            return
        old: dict[int, Any] = {}
        try:
            for sig in (signal.SIGINT, signal.SIGTERM):
                try:
                    old[sig] = signal.signal(sig, _interrupt)
                except ValueError:  # not the main thread
                    pass
            self.say(f"serving the web viewer at {self.web.web_url} (Ctrl-C to stop)")
            self.web.wait()
        except KeyboardInterrupt:
            pass
        finally:
            self.stop()
            for signum, handler in old.items():
                signal.signal(signum, handler)

    def stop(self) -> None:
        web, self.web = self.web, None
        if web is not None:
            web.stop()  # the server's whole process group


class FoxgloveChoice:
    """The Foxglove server a command streams to (--foxglove), if any."""

    def __init__(self, address: str | None, *, pace: float | None, several: bool = False,
                 say: Callable[[str], None] = to_stderr):  # fmt: skip
        self.say = say
        if pace is not None and address is None:
            raise UsageError("--pace: only with --foxglove")
        self.pace, self.several = pace, several
        self.server: FoxgloveServer | None = None
        self.sinks: dict[str, FoxgloveSlotSink] = {}
        self.problem: str | None = None
        self.address: Address | None = None
        if address is not None:
            from corraoi.recorder.live.foxglove import parse_address, require_foxglove

            self.address = parse_address(address)  # a bad value: one line, exit 2
            require_foxglove()  # no extra: name it before anything runs

    def start(
        self, configs: Sequence[RunConfig], *, tolerant: bool = False
    ) -> FoxgloveServer | None:
        """Start the server with a channel per run of ``configs`` and say where it is; with
        ``tolerant`` a server that cannot start is one error line (kept in :attr:`problem`)
        and None. The channels exist before the URL is printed: the SDK (0.30) may refuse a
        subscription to a channel added while the client was connecting."""
        if self.address is None:
            return None
        from corraoi.errors import FoxgloveError
        from corraoi.recorder.live.foxglove import FoxgloveServer

        try:
            self.server = FoxgloveServer(self.address)
        except FoxgloveError as exc:
            if not tolerant:
                raise
            self.problem = str(exc)
            self.say(f"corraoi: error: {exc}; writing the files only")
            return None
        for config in configs:
            label = config.label if self.several else None
            self.sinks[config.label] = self.server.slot_sink(config, label=label, pace=self.pace)
        self.say(self.server.hint(paced=self.pace is not None))
        return self.server

    def sink(self, config: RunConfig, stop: Callable[[], bool]) -> FoxgloveSlotSink | None:
        """A slot sink for one run (None without a server)."""
        sink = self.sinks.get(config.label) if self.server is not None else None
        if sink is not None:
            sink.stop_when(stop)
        return sink

    def stop(self) -> None:
        server, self.server = self.server, None
        if server is not None:
            server.stop()
            sent = ", ".join(f"{n} on {topic}" for topic, n in server.published.items())
            self.say(f"foxglove: stopped {server.url} after publishing {sent or 'nothing'}")


def open_command(recordings: list[str]) -> str:
    """The shell command that opens ``recordings`` in the Rerun viewer."""
    from corraoi.recorder.live.viewers import view_command

    return view_command(recordings)


__all__ = ["FoxgloveChoice", "ViewerChoice", "open_command", "to_stderr"]
