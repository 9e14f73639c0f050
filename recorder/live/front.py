"""A loopback front for the Foxglove server that also admits ``foxglove.websocket.v1`` clients.

foxglove-sdk 0.30's WebSocket server speaks the Foxglove WebSocket protocol under the
subprotocol name ``foxglove.sdk.v1`` only (``SUBPROTOCOL`` in its ``handshake.rs``; no
option changes it) and answers HTTP 400 to a client that offers the older name alone:
the ``@foxglove/ws-protocol`` client (0.8), the open-source Foxglove Studio core built on
it (``@foxglove/studio-base`` 1.48) and their forks. The two names stand for the same
protocol (Foxglove's own clients accept both), so the front listens where the user asked,
passes every connection byte for byte to the SDK's server on a loopback port, and changes
one header line in each direction of a handshake that offers ``foxglove.websocket.v1``
without ``foxglove.sdk.v1``: the request's ``Sec-WebSocket-Protocol`` says
``foxglove.sdk.v1`` to the SDK, the SDK's answer says ``foxglove.websocket.v1`` back. A
client offering ``foxglove.sdk.v1`` is passed through unchanged; after the handshake the
front only copies bytes (two threads a connection, blocking calls that let the GIL go).

Why a front rather than a second server: the SDK keeps doing what it does (channels,
subscriptions, the per-client queue that drops the oldest message for a slow client),
and this is the one place that knows about the older name. What the hop costs
(``benchmarks/bench_foxglove.py --slots 100000``, two runs each, before the front and with
it, on the loaded 2-core machine): with a client reading in the same process 157-171k
against 145-178k slots/s, and that client got 60% of the slots before against 95-99% with
the front (its socket buffers hold more); without a client the front does nothing.
"""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable
from functools import partial

#: The subprotocol the SDK's server speaks, and the older name of the same protocol.
SDK_PROTOCOL = "foxglove.sdk.v1"
LEGACY_PROTOCOL = "foxglove.websocket.v1"
#: The largest handshake the front reads (the SDK's own limit is of this order).
MAX_HEAD = 64 << 10
#: Bytes copied at a time.
CHUNK = 256 << 10
#: ``settle``: the server's queue counts as sent once nothing has flowed for QUIET s, and
#: the front waits at most SETTLE_LIMIT s for that.
QUIET = 0.2
SETTLE_LIMIT = 2.0


def offered(head: bytes) -> list[str]:
    """The subprotocols a handshake request offers (every ``Sec-WebSocket-Protocol`` line,
    comma-separated values)."""
    out: list[str] = []
    for line in head.split(b"\r\n")[1:]:
        name, sep, value = line.partition(b":")
        if sep and name.strip().lower() == b"sec-websocket-protocol":
            out += [v.strip().decode("latin-1") for v in value.split(b",") if v.strip()]
    return out


def set_protocol(head: bytes, protocol: str) -> bytes:
    """``head`` with its ``Sec-WebSocket-Protocol`` lines replaced by one naming
    ``protocol`` (the other lines and their order unchanged)."""
    lines = head.split(b"\r\n")
    out, done = [], False
    for line in lines:
        name, sep, _ = line.partition(b":")
        if sep and name.strip().lower() == b"sec-websocket-protocol":
            if not done:
                out.append(b"Sec-WebSocket-Protocol: " + protocol.encode("latin-1"))
                done = True
            continue
        out.append(line)
    return b"\r\n".join(out)


def _read_head(sock: socket.socket) -> tuple[bytes, bytes]:
    """The HTTP head (up to the blank line, without it) and what came after it."""
    data = b""
    while b"\r\n\r\n" not in data:
        if len(data) > MAX_HEAD:
            raise ConnectionError("handshake too large")
        chunk = sock.recv(8192)
        if not chunk:
            raise ConnectionError("closed during the handshake")
        data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    return head, rest


class SubprotocolFront:
    """Listens on ``host:port`` (port 0: a free one, in :attr:`port`) and passes every
    connection to ``127.0.0.1:backend_port``, naming the subprotocol as the SDK wants it
    (module docstring). ``close()`` stops listening and ends every connection."""

    def __init__(self, host: str, port: int, backend_port: int) -> None:
        self.backend = ("127.0.0.1", backend_port)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            self._listener.bind((host, port))
            self._listener.listen(64)
        except OSError:
            self._listener.close()
            raise
        self.port: int = self._listener.getsockname()[1]
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closed = False
        #: handshakes the front renamed (``foxglove.websocket.v1`` clients), for the tests
        self.renamed = 0
        #: when bytes last went through (time.monotonic)
        self.last_flow = time.monotonic()
        self._thread = threading.Thread(target=self._accept, name="foxglove-front", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except OSError:  # closed
                return
            self._start(partial(self._connection, client))

    @staticmethod
    def _start(target: Callable[[], None]) -> None:
        threading.Thread(target=target, name="foxglove-front-conn", daemon=True).start()

    def _track(self, *socks: socket.socket) -> bool:
        with self._lock:
            if self._closed:
                return False
            self._open.update(socks)
            return True

    def _connection(self, client: socket.socket) -> None:
        backend = None
        try:
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            head, rest = _read_head(client)
            protocols = offered(head)
            rename = LEGACY_PROTOCOL in protocols and SDK_PROTOCOL not in protocols
            if rename:
                head = set_protocol(head, SDK_PROTOCOL)
            backend = socket.create_connection(self.backend, timeout=10)
            backend.settimeout(None)
            backend.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            if not self._track(client, backend):
                raise ConnectionError("closed")
            backend.sendall(head + b"\r\n\r\n" + rest)
            answer, more = _read_head(backend)
            if rename and b" 101 " in answer.split(b"\r\n", 1)[0]:
                answer = set_protocol(answer, LEGACY_PROTOCOL)
                self.renamed += 1
            client.sendall(answer + b"\r\n\r\n" + more)
        except (OSError, ConnectionError):
            for s in (client, backend):
                if s is not None:
                    self._close(s)
            return
        done = threading.Semaphore(0)
        self._start(lambda: self._pump(backend, client, done))
        self._pump(client, backend, done)

    def _pump(self, source: socket.socket, sink: socket.socket, done: threading.Semaphore) -> None:
        """Copy ``source`` to ``sink``. At the end of ``source`` the end is passed on
        (``sink`` half-closed, so the other side can still finish its closing handshake);
        the second direction to end closes both sockets, and a broken one closes both at
        once."""
        buffer = bytearray(CHUNK)
        view = memoryview(buffer)
        try:
            while True:
                n = source.recv_into(buffer)
                if not n:
                    break
                sink.sendall(view[:n])
                self.last_flow = time.monotonic()
            sink.shutdown(socket.SHUT_WR)
        except OSError:  # reset, or closed by close(): end both
            self._close(source)
            self._close(sink)
            return
        if done.acquire(blocking=False):  # the other direction ended first
            self._close(source)
            self._close(sink)
        else:
            done.release()

    def _close(self, sock: socket.socket) -> None:
        with self._lock:
            self._open.discard(sock)
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        sock.close()

    def settle(self, quiet: float = QUIET, limit: float = SETTLE_LIMIT) -> None:
        """Wait, while a client is connected, until nothing has gone through for ``quiet``
        s (at most ``limit`` s): what the server had queued for its clients has then
        reached them. Stopping the SDK's server drops what its queues still hold: a client
        of a run that just ended missed its last slots."""
        end = time.monotonic() + limit
        while True:
            with self._lock:
                connected = bool(self._open)
            now = time.monotonic()
            if not connected or now - self.last_flow >= quiet or now >= end:
                return
            time.sleep(min(quiet - (now - self.last_flow), end - now, 0.05))

    def close(self) -> None:
        """Stop listening and end every connection (safe twice)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            socks = list(self._open)
        try:
            self._listener.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._listener.close()
        for s in socks:
            self._close(s)
        self._thread.join(2.0)


__all__ = ["LEGACY_PROTOCOL", "SDK_PROTOCOL", "SubprotocolFront", "offered", "set_protocol"]
