"""Zenoh transport: session opening, a subscriber source bridged to asyncio, a publisher sink.

The zenoh Python API is synchronous and calls subscriber callbacks on its own threads. The
bridge copies each payload inside the callback into a bounded buffer and wakes the event loop
once per batch (``call_soon_threadsafe`` per message would cap throughput at a third). When the
buffer is full the callback waits, which pushes back on zenoh and, with
``CongestionControl.BLOCK`` on the publishing side, on the rig's publisher: nothing is dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections import deque
from types import TracebackType
from typing import Any

import zenoh

from tdmon.config.daemon import ZenohConfig
from tdmon.errors import IngestError
from tdmon.ingest.types import RawMessage


def zenoh_config(config: ZenohConfig) -> zenoh.Config:
    """A zenoh.Config from ours; scouting off means only the explicit endpoints are used."""
    conf = zenoh.Config()
    try:
        conf.insert_json5("mode", json.dumps(config.mode))
        conf.insert_json5("listen/endpoints", json.dumps(config.listen))
        conf.insert_json5("connect/endpoints", json.dumps(config.connect))
        conf.insert_json5("scouting/multicast/enabled", json.dumps(config.scouting))
        conf.insert_json5("scouting/gossip/enabled", json.dumps(config.scouting))
    except zenoh.ZError as exc:
        raise IngestError(f"zenoh configuration rejected: {exc}") from exc
    return conf


def open_session(config: ZenohConfig) -> zenoh.Session:
    """Open a session (blocking: call it in a thread from async code)."""
    try:
        return zenoh.open(zenoh_config(config))
    except zenoh.ZError as exc:
        where = ", ".join(config.listen + config.connect) or "default endpoints"
        raise IngestError(f"zenoh ({config.mode}, {where}): cannot open session: {exc}") from exc


def key_expr_for(topic_prefix: str) -> str:
    """Zenoh key expression for everything under an MQTT-style prefix."""
    return f"{topic_prefix.strip('/')}/**"


class ZenohSource:
    """Subscribe on an open session and yield RawMessages (an async context manager)."""

    name = "zenoh"

    def __init__(
        self,
        session: zenoh.Session,
        key_expr: str,
        ignore_prefixes: tuple[str, ...] = (),
        max_buffer: int = 10_000,
    ) -> None:
        self.session = session
        self.key_expr = key_expr
        self.ignore_prefixes = ignore_prefixes
        self.max_buffer = max_buffer
        self._buffer: deque[RawMessage] = deque()
        self._wake_pending = False
        self._closed = False
        self._event = asyncio.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._subscriber: Any = None

    async def __aenter__(self) -> ZenohSource:
        self._loop = asyncio.get_running_loop()
        self._closed = False
        try:
            # remote origin only: the daemon's own results, put on the same session, would
            # otherwise be delivered here synchronously inside put(), on the event loop
            # thread, and deadlock once the bridge buffer is full
            self._subscriber = self.session.declare_subscriber(
                self.key_expr, self._on_sample, allowed_origin=zenoh.Locality.REMOTE)
        except zenoh.ZError as exc:
            raise IngestError(f"zenoh: cannot subscribe to '{self.key_expr}': {exc}") from exc
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._closed = True  # releases a callback waiting for room
        if self._subscriber is not None:
            # the session may already be closed: then there is nothing to undeclare
            with contextlib.suppress(zenoh.ZError):
                await asyncio.to_thread(self._subscriber.undeclare)
            self._subscriber = None

    def _on_sample(self, sample: zenoh.Sample) -> None:
        # runs on a zenoh thread: copy out of zenoh's buffers before returning. No lock per
        # message: deque.append/popleft are atomic, and the wake-up flag is re-checked by the
        # consumer after it resets it (see __anext__), so no wake-up can be missed.
        topic = str(sample.key_expr)
        if topic.startswith(self.ignore_prefixes):
            return  # our own results published on the same prefix by another session
        buffer = self._buffer
        while len(buffer) >= self.max_buffer and not self._closed:
            time.sleep(0.001)  # full: hold zenoh back (backpressure) until the loop catches up
        if self._closed:
            return
        buffer.append(RawMessage("zenoh", topic, sample.payload.to_bytes(), time.time()))
        if not self._wake_pending:
            self._wake_pending = True
            if self._loop is not None:
                with contextlib.suppress(RuntimeError):  # loop closed during shutdown
                    self._loop.call_soon_threadsafe(self._event.set)

    def __aiter__(self) -> ZenohSource:
        return self

    async def __anext__(self) -> RawMessage:
        buffer = self._buffer
        while True:
            if buffer:
                return buffer.popleft()
            self._event.clear()
            self._wake_pending = False
            if buffer:
                continue  # appended while the flag was still set: no wake-up is coming
            await self._event.wait()


class ZenohPublisher:
    """Sink putting result messages as JSON on ``<prefix>/tdmon/<name>``.

    zenoh queues internally and ``put`` returns at once unless the link is congested; with
    ``CongestionControl.BLOCK`` a congested link slows the daemon instead of losing results.
    """

    def __init__(self, session: zenoh.Session, prefix: str, names: list[str]) -> None:
        self.session = session
        self.prefix = prefix.strip("/")
        self.names = frozenset(names)
        #: the pipeline routes only these topics here (see tdmon.daemon.pipeline)
        self.topics = frozenset(f"/tdmon/{name}" for name in names)
        self._publishers: dict[str, Any] = {}
        self.published = 0
        self._closed = False

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        name = topic.rsplit("/", 1)[-1]
        if name not in self.names or self._closed:
            return
        publisher = self._publishers.get(name)
        try:
            if publisher is None:
                publisher = self.session.declare_publisher(
                    f"{self.prefix}/tdmon/{name}",
                    congestion_control=zenoh.CongestionControl.BLOCK,
                )
                self._publishers[name] = publisher
            publisher.put(json.dumps(message).encode())
        except zenoh.ZError as exc:
            raise IngestError(f"zenoh: cannot publish '{name}': {exc}") from exc
        self.published += 1

    def close(self) -> None:
        self._closed = True
        for publisher in self._publishers.values():
            with contextlib.suppress(zenoh.ZError):  # session already gone
                publisher.undeclare()
        self._publishers.clear()
