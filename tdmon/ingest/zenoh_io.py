"""Zenoh transport: session opening, a subscriber source bridged to asyncio, a publisher sink.

The source subscribes with a bounded zenoh FIFO channel and takes samples out of it on the
event loop itself (``try_recv``): zenoh's threads fill the channel without Python, so no other
thread competes with the pipeline for the GIL, message by message (a Python callback per sample
did, and the switches between the two threads cost the daemon about a third of its
throughput). Only when the channel is empty does one blocking ``recv`` wait in a worker thread,
and the loop takes nothing else meanwhile, so samples keep their order. When the channel is
full zenoh waits, which pushes back on the link and, with ``CongestionControl.BLOCK`` on the
publishing side, on the rig's publisher: nothing is dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque
from collections.abc import AsyncGenerator
from types import TracebackType
from typing import Any

import orjson
import zenoh

from tdmon.config.daemon import ZenohConfig, ZenohTlsConfig
from tdmon.errors import IngestError
from tdmon.ingest.types import RawMessage
from tdmon.record.batch import Batch
from tdmon.record.sink import Sink

#: Samples taken from zenoh's channel and handed to the daemon at once, at most.
BATCH = 256


def _tls_keys(tls: ZenohTlsConfig) -> list[tuple[str, Any]]:
    """zenoh's ``transport/link/tls`` keys of our ``[...zenoh.tls]`` table."""
    keys: list[tuple[str, Any]] = [("enable_mtls", tls.mutual),
                                   ("verify_name_on_connect", tls.verify_name)]
    if tls.ca_file is not None:
        keys.append(("root_ca_certificate", str(tls.ca_file)))
    if tls.cert_file is not None and tls.key_file is not None:
        for side in ("listen", "connect"):
            keys += [(f"{side}_certificate", str(tls.cert_file)),
                     (f"{side}_private_key", str(tls.key_file))]
    return [(f"transport/link/tls/{key}", value) for key, value in keys]


def zenoh_config(config: ZenohConfig) -> zenoh.Config:
    """A zenoh.Config from ours; scouting off means only the explicit endpoints are used; TLS
    and access control as docs/configuration.md ("Zenoh TLS and access control") describes."""
    conf = zenoh.Config()
    keys: list[tuple[str, Any]] = [
        ("mode", config.mode), ("listen/endpoints", config.listen),
        ("connect/endpoints", config.connect), ("scouting/multicast/enabled", config.scouting),
        ("scouting/gossip/enabled", config.scouting)]
    if config.tls is not None:
        keys += _tls_keys(config.tls)
    if config.access_control is not None:
        keys.append(("access_control", config.access_control))
    for key, value in keys:
        try:
            conf.insert_json5(key, orjson.dumps(value).decode())
        except zenoh.ZError as exc:
            raise IngestError(f"zenoh configuration rejected ({key}): {exc}") from exc
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
    """Subscribe on an open session and yield RawMessages (an async context manager).

    ``max_buffer`` samples wait in zenoh's channel at most; ``receive_time`` is when the
    daemon took a sample from it.
    """

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
        self._subscriber: Any = None
        self._handler: Any = None
        self._batches: AsyncGenerator[list[RawMessage], None] | None = None
        self._held: deque[RawMessage] = deque()

    async def __aenter__(self) -> ZenohSource:
        try:
            # remote origin only: the daemon's own results, put on the same session, would
            # otherwise come back here and, once the channel is full, block put() on the
            # event loop thread, the only one emptying the channel
            self._subscriber = self.session.declare_subscriber(
                self.key_expr, zenoh.handlers.FifoChannel(self.max_buffer),
                allowed_origin=zenoh.Locality.REMOTE)
        except zenoh.ZError as exc:
            raise IngestError(f"zenoh: cannot subscribe to '{self.key_expr}': {exc}") from exc
        # the handler, not the subscriber, is what a waiting thread holds: undeclaring the
        # subscriber closes the channel and ends that wait
        self._handler = self._subscriber.handler
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._subscriber is not None:
            # the session may already be closed: then there is nothing to undeclare
            with contextlib.suppress(zenoh.ZError):
                await asyncio.to_thread(self._subscriber.undeclare)
            self._subscriber = None
        if self._batches is not None:
            # __anext__'s generator; still running only in a task that was cancelled mid-wait
            with contextlib.suppress(RuntimeError):
                await self._batches.aclose()
            self._batches = None

    def __aiter__(self) -> ZenohSource:
        return self

    async def batches(self) -> AsyncGenerator[list[RawMessage], None]:
        """What waits in zenoh's channel, up to ``BATCH`` samples at a time (the daemon queues
        a list as one entry); when nothing waits, the next sample as it comes."""
        handler = self._handler
        assert handler is not None, "not entered"
        ignore = self.ignore_prefixes
        while True:
            batch: list[RawMessage] = []
            try:
                sample = handler.try_recv()
                if sample is None:
                    # nothing waiting: block in a worker thread (recv releases the GIL)
                    sample = await asyncio.to_thread(handler.recv)
                while sample is not None:
                    topic = str(sample.key_expr)
                    if not topic.startswith(ignore):  # else our own results, another session
                        batch.append(RawMessage("zenoh", topic, sample.payload.to_bytes(),
                                                time.time()))
                    if len(batch) >= BATCH:
                        break
                    sample = handler.try_recv()
            except zenoh.ZError as exc:  # the channel was closed under us (session closed)
                if batch:
                    yield batch
                raise IngestError(f"zenoh: subscription to '{self.key_expr}' ended: {exc}"
                                  ) from exc
            if batch:
                yield batch

    async def __anext__(self) -> RawMessage:
        # one at a time out of `batches` (what waits in zenoh's channel, taken in one go)
        if not self._held:
            if self._batches is None:
                self._batches = self.batches()
            self._held.extend(await anext(self._batches))
        return self._held.popleft()


class ZenohPublisher(Sink):
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

    def write_batch(self, batch: Batch) -> None:
        name = batch.topic.rsplit("/", 1)[-1]
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
            for data in batch.encoded().datas:
                publisher.put(data)
                self.published += 1
        except zenoh.ZError as exc:
            raise IngestError(f"zenoh: cannot publish '{name}': {exc}") from exc

    def close(self) -> None:
        self._closed = True
        for publisher in self._publishers.values():
            with contextlib.suppress(zenoh.ZError):  # session already gone
                publisher.undeclare()
        self._publishers.clear()
