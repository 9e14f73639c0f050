"""Live in Foxglove: a Foxglove WebSocket server for a running (or replayed) run.

The server is the maintained ``foxglove-sdk`` package (the optional extra ``foxglove``),
imported only when ``--foxglove`` is asked for. What a client sees:

- ``/corraoi/slot``: one JSON message per slot, with the very schema
  (:func:`corraoi.recorder.slotlog.encode.slot_schema`) and the very bytes
  (:class:`corraoi.recorder.slotlog.encode.BlockEncoder`) of the MCAP log, ``log_time = t`` seconds
  as in the file, so a layout made for the file (``docs/foxglove-layout.json``) works live.
- ``/corraoi/run``: the ``corraoi.run`` metadata record of the MCAP log as one JSON object
  (flat strings). The WebSocket protocol keeps no message for a client that connects
  later, so it is sent again with every block of slots (every 1,000 slots).
- Several runs on one server (``record -p ucb,cucb``): one topic each,
  ``/corraoi/slot/<label>`` and ``/corraoi/run/<label>``.

Every client: the SDK speaks the protocol as ``foxglove.sdk.v1`` only; a
:class:`~corraoi.recorder.live.front.SubprotocolFront` on the address asked for admits clients
offering its older name, ``foxglove.websocket.v1``, too. With ``pace`` a slot sink waits
up to :data:`FIRST_CLIENT_WAIT` s for a subscriber before its first slot.

Slow clients. ``Channel.log`` never waits for a client: the SDK gives every client its own
queue of at most :data:`BACKLOG` messages and, when it is full, drops the *oldest* message
to make room (``send_lossy`` in foxglove-sdk's ``connected_client``). Memory is so bounded
by ``BACKLOG`` x the largest message per client (plus the sockets' buffers), and the run
never stalls on a client. The SDK keeps no count of what it dropped; every slot message
carries its ``t``, so a client counts what it missed as the gaps in ``t``
(:func:`missed`), and the server reports how many messages it published per topic.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from corraoi.engine.block import RunBlock, RunConfig, SourcesBlock
from corraoi.errors import FoxgloveError, MissingExtraError, UsageError
from corraoi.recorder.sink import Sink
from corraoi.recorder.slotlog.encode import BlockEncoder, run_metadata, schema_bytes
from corraoi.recorder.vocab import NS_PER_SLOT, RUN_METADATA, SWEEP_TOPIC, slot_topic
from corraoi.recorder.vocab import SLOT_SCHEMA_NAME as SCHEMA_NAME
from corraoi.recorder.vocab import SLOT_TOPIC as TOPIC

if TYPE_CHECKING:
    from corraoi.recorder.slotlog.reader import RunLog

#: What to install for ``--foxglove``.
EXTRA = 'pip install "corraoi[foxglove]"'
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: ``--foxglove`` without a value.
DEFAULT_ADDRESS = f"{DEFAULT_HOST}:{DEFAULT_PORT}"
#: Messages the SDK queues per client before it drops the oldest.
BACKLOG = 1024
#: Seconds of slots a paced stream that fell behind sends at once (Pacer).
CATCH_UP = 0.05
#: Topic of the run metadata record.
RUN_TOPIC = "/corraoi/run"
#: Seconds a paced stream waits for a first client before its first slot.
FIRST_CLIENT_WAIT = 5.0


@dataclass(frozen=True)
class Address:
    """Where the server listens: ``host:port`` (``port`` 0: a free port)."""

    host: str
    port: int

    def __str__(self) -> str:
        return f"{self.host}:{self.port}"


def parse_address(text: str) -> Address:
    """``[HOST:]PORT`` -> Address; a bad value is one UsageError naming it."""
    value = text.strip()
    host, sep, port = value.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]") or DEFAULT_HOST
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise UsageError(
            f"--foxglove {text}: not [HOST:]PORT, expected e.g. 8765 or 0.0.0.0:8765 "
            "(a port 0..65535)"
        )
    return Address(host, number)


def require_foxglove() -> Any:
    """The ``foxglove`` module, or a MissingExtraError naming the extra to install."""
    try:
        import foxglove
    except ImportError:
        raise MissingExtraError(
            f"foxglove-sdk is not installed: --foxglove needs the foxglove extra, {EXTRA}"
        ) from None
    return foxglove


def missed(ts: Iterable[int]) -> int:
    """Slots a client missed, from the ``t`` of the slot messages it received in order:
    the gaps between consecutive values."""
    out, last = 0, None
    for t in ts:
        if last is not None and t > last + 1:
            out += t - last - 1
        last = t
    return out


class Pacer:
    """Holds a stream to ``rate`` slots per second (None: as fast as it comes).

    ``wait(n)`` returns once ``n`` slots in all may have gone out; it sleeps in short
    steps and returns False at once when ``stop()`` says so. A stream that fell behind (the
    log's next block read, a busy machine) makes up at most :data:`CATCH_UP` s of it: a
    longer burst would overflow a client's backlog (:data:`BACKLOG` messages; a run of M
    sources sends M a slot), and the SDK would drop the oldest.
    """

    def __init__(self, rate: float | None, *, stop: Callable[[], bool] | None = None) -> None:
        if rate is not None and not rate > 0:
            raise UsageError(f"--pace {rate}: expected a positive number of slots per second")
        self.rate = rate
        self.stop = stop or (lambda: False)
        self._start: float | None = None

    def wait(self, n: int) -> bool:
        if self.rate is None:
            return not self.stop()
        now = time.monotonic()
        if self._start is None:
            self._start = now
        due = self._start + n / self.rate
        if now - due > CATCH_UP:  # behind: the time lost is not made up in one burst
            self._start += now - due - CATCH_UP
            due = now - CATCH_UP
        while now < due:
            if self.stop():
                return False
            time.sleep(min(due - now, 0.05))
            now = time.monotonic()
        return not self.stop()


class _Subscriptions:
    """The SDK's server listener: which topics a client has subscribed to."""

    def __init__(self) -> None:
        self.topics: set[str] = set()
        self.changed = threading.Condition()

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.changed:
            self.topics.add(channel.topic)
            self.changed.notify_all()

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        pass  # a paced stream that waited has started already


class FoxgloveServer:
    """A Foxglove WebSocket server on its own SDK context (its channels go to it only).

    ``with FoxgloveServer(Address("127.0.0.1", 8765)) as server: sink =
    server.slot_sink(config) ...``. The SDK listens on a loopback port, behind the front on
    ``address``. A port that is taken is one :class:`FoxgloveError` line.
    """

    def __init__(self, address: Address, *, name: str = "corraoi", backlog: int = BACKLOG):
        foxglove = require_foxglove()
        from .front import SubprotocolFront

        self.address, self._foxglove = address, foxglove
        self._context, self.subscriptions = foxglove.Context(), _Subscriptions()

        def refused(text: str) -> FoxgloveError:
            if "in use" in text:
                text = f"port {address.port} is in use (another server?); pick another " \
                       "with --foxglove PORT"  # fmt: skip
            return FoxgloveError(f"--foxglove {address}: cannot start the server: {text}")

        try:
            self._server = foxglove.start_server(
                name=name, host="127.0.0.1", port=0, context=self._context,
                message_backlog_size=backlog, server_listener=self.subscriptions,
            )  # fmt: skip
        except RuntimeError as exc:
            raise refused(str(exc).removeprefix("FoxgloveError: ")) from None
        try:
            self.front = SubprotocolFront(address.host, address.port, self._server.port)
        except OSError as exc:
            self._server.stop()
            raise refused((exc.strerror or str(exc)).lower()) from None
        self.port: int = self.front.port
        self.published: dict[str, int] = {}
        self._stopped = False

    def wait_for_subscriber(self, topic: str, timeout: float,
                            stop: Callable[[], bool] | None = None) -> bool:  # fmt: skip
        """Whether a client subscribed to ``topic`` within ``timeout`` s (or ``stop()``)."""
        end, subs = time.monotonic() + timeout, self.subscriptions
        with subs.changed:
            while topic not in subs.topics:
                left = end - time.monotonic()
                if left <= 0 or (stop is not None and stop()):
                    return False
                subs.changed.wait(min(left, 0.05))
        return True

    @property
    def url(self) -> str:
        host = self.address.host
        shown = f"[{host}]" if ":" in host else host
        return f"ws://{shown}:{self.port}"

    def hint(self, *, paced: bool = False) -> str:
        """How to open the stream in Foxglove (one line)."""
        wait = f"; waits up to {FIRST_CLIENT_WAIT:g} s for a client" if paced else ""
        return (
            f"foxglove: serving {self.url} -- in Foxglove: Open connection -> Foxglove "
            f"WebSocket -> {self.url} (layout: docs/foxglove-layout.json){wait}"
        )

    def channel(self, topic: str, schema: Any, *, metadata: dict[str, str] | None = None) -> Any:
        return self._foxglove.Channel(
            topic, schema=schema, message_encoding="json", context=self._context,
            metadata=metadata,
        )  # fmt: skip

    def slot_sink(
        self, config: RunConfig, *, label: str | None = None, pace: float | None = None,
        stop: Callable[[], bool] | None = None,
    ) -> FoxgloveSlotSink:  # fmt: skip
        """A sink for one run's slots; ``label``: the run's topics are
        ``/corraoi/slot/<label>`` and ``/corraoi/run/<label>`` (several runs on one server)."""
        return FoxgloveSlotSink(self, config, label=label, pace=pace, stop=stop)

    def stop(self) -> None:
        if not self._stopped:
            self._stopped = True
            if any(self.published.values()):
                self.front.settle()  # what the server queued reaches its clients first
            self._server.stop()  # closes its connections (through the front) properly
            self.front.close()

    def __enter__(self) -> FoxgloveServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class FoxgloveSlotSink(Sink[RunBlock]):
    """Streams a run's slot blocks to a :class:`FoxgloveServer`: ``write(block)``.

    The messages are :class:`corraoi.recorder.slotlog.encode.BlockEncoder`'s, the MCAP log's bytes;
    ``log_time`` is ``t`` seconds. ``pace``: at most that many slots per second (the
    writer waits); ``stop()`` true ends a paced ``write`` early (Ctrl-C). A run of M >= 2
    sources (:class:`SourcesBlock` s) goes out as its log holds it: source m's messages on
    ``/corraoi/slot/m`` (``/corraoi/slot/<label>/m`` with a label), the sources of a slot in
    order; :attr:`topic` is source 1's, :attr:`topics` all of them.
    """

    takes_sources = True  # a run of several sources too (Sink.takes_sources)

    def __init__(
        self, server: FoxgloveServer, config: RunConfig, *, label: str | None = None,
        pace: float | None = None, stop: Callable[[], bool] | None = None,
    ) -> None:  # fmt: skip
        from foxglove import Schema

        self.server = server
        suffix = f"/{label}" if label else ""
        M = config.sources
        #: the slots' topics, one per source (the log's channels: vocab.slot_topic)
        self.topics = [TOPIC + suffix + slot_topic(m, M).removeprefix(TOPIC)
                       for m in range(1, M + 1)]  # fmt: skip
        self.topic = self.topics[0]
        self.run_topic = RUN_TOPIC + suffix
        meta = run_metadata(config)
        schema = Schema(name=SCHEMA_NAME, encoding="jsonschema", data=schema_bytes(config))
        version = {"format_version": meta["format_version"]}
        self._channels = [
            server.channel(topic, schema,
                           metadata=version if M == 1 else {**version, "source": str(m)})
            for m, topic in enumerate(self.topics, 1)
        ]  # fmt: skip
        self._run = server.channel(self.run_topic, _run_schema(meta))
        self._run_message = json.dumps(meta).encode()
        self._encoder = BlockEncoder(config.K)
        self._pacer = Pacer(pace, stop=stop)
        self._waited = False
        self.sent = 0
        for topic in self.topics:
            server.published.setdefault(topic, 0)
        self._send_run(0)

    def _send_run(self, t: int) -> None:
        self._run.log(self._run_message, log_time=t * NS_PER_SLOT)

    def subscribed(self) -> bool:
        """Whether a client subscribes to the slots' topic now."""
        return bool(self._channels[0].has_sinks())

    def write(self, block: RunBlock) -> int:
        """Publish the block's slots; returns how many went out (fewer if stopped). A slot
        of several sources is its sources' messages, 1..M, each on its source's topic; the
        pace counts slots."""
        if len(block) == 0:
            return 0
        parts = block.sources if isinstance(block, SourcesBlock) else [block]
        per_source = [self._encoder.encode(part) for part in parts]
        ts = block.t.tolist()
        paced = self._pacer.rate is not None
        if paced and not self._waited:  # a client started with the run sees every slot
            self._waited = True
            self.server.wait_for_subscriber(self.topic, FIRST_CLIENT_WAIT, self._pacer.stop)
        self._send_run(ts[0])
        logs = [channel.log for channel in self._channels]
        done = 0
        for i, t in enumerate(ts):
            if paced and not self._pacer.wait(self.sent + 1):
                break
            at = t * NS_PER_SLOT
            for log, messages in zip(logs, per_source, strict=True):
                log(messages[i], log_time=at)
            self.sent += 1
            done += 1
        for topic in self.topics:
            self.server.published[topic] += done
        return done

    def stop_when(self, stop: Callable[[], bool]) -> None:
        """A paced ``write`` returns early once ``stop()`` is true (Ctrl-C)."""
        self._pacer.stop = stop

    def close(self) -> None:
        """Nothing is buffered here: the channels stay advertised until the server stops."""


def _run_schema(meta: dict[str, str]) -> dict[str, Any]:
    return {
        "title": RUN_METADATA,
        "description": f"the {RUN_METADATA} metadata record of the MCAP log (flat strings)",
        "type": "object",
        "properties": {key: {"type": "string"} for key in meta},
    }


class FoxgloveSweepSink(Sink[dict[str, Any]]):
    """Streams sweep points to ``/corraoi/sweep`` as each checkpoint finishes:
    ``write(point)`` with a JSON-able dict (one message; ``log_time`` its ``t`` seconds
    when it has one), ``close()``."""

    def __init__(self, server: FoxgloveServer, *, topic: str = SWEEP_TOPIC) -> None:
        self.server = server
        self.topic = topic
        self._channel = server.channel(topic, None)
        self.sent = 0
        server.published.setdefault(topic, 0)

    def subscribed(self) -> bool:
        """Whether a client subscribes to the sweep's topic now."""
        return bool(self._channel.has_sinks())

    def write(self, point: dict[str, Any]) -> None:
        t = point.get("t")
        log_time = int(t) * NS_PER_SLOT if isinstance(t, int) and t >= 0 else None
        self._channel.log(json.dumps(point, sort_keys=True).encode(), log_time=log_time)
        self.sent += 1
        self.server.published[self.topic] += 1

    def close(self) -> None:
        self._channel.close()


def stream_log(
    server: FoxgloveServer,
    log: RunLog,
    *,
    start: int = 1,
    pace: float | None = None,
    stop: Callable[[], bool] | None = None,
    on_block: Callable[[int], None] | None = None,
    sink: FoxgloveSlotSink | None = None,
) -> int:
    """Publish the slots ``start..`` of a recorded log (a
    :class:`corraoi.recorder.slotlog.reader.RunLog`), through ``sink`` if given (made
    beforehand for the log's config); returns the last slot sent (``start - 1`` if none)."""
    if not 1 <= start <= log.n_slots:
        raise UsageError(
            f"--start {start}: {log.path} holds slots 1..{log.n_slots}, expected a slot there"
        )
    if sink is None:
        sink = server.slot_sink(log.config, pace=pace, stop=stop)
    last = start - 1
    for block in log.window(start, log.n_slots):
        done = sink.write(block)
        last += done
        if on_block is not None:
            on_block(done)
        if done < len(block):
            break
    sink.close()
    return last


__all__ = [
    "Address",
    "BACKLOG",
    "DEFAULT_ADDRESS",
    "EXTRA",
    "FIRST_CLIENT_WAIT",
    "FoxgloveServer",
    "FoxgloveSlotSink",
    "FoxgloveSweepSink",
    "Pacer",
    "RUN_TOPIC",
    "missed",
    "parse_address",
    "require_foxglove",
    "stream_log",
]
