"""MQTT transport (aiomqtt): a source of raw messages and a publisher sink for results.

Reconnecting is not done here: a source or publisher connection is an async context manager
that raises :class:`tdmon.errors.IngestError` when it cannot connect or loses the broker, and
the daemon's supervisor decides when to try again.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import math
import socket
import ssl
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from itertools import islice
from pathlib import Path
from types import TracebackType
from typing import Any, cast

import aiomqtt
import paho.mqtt.client as mqtt
from aiomqtt.exceptions import MqttConnectError
from paho.mqtt.reasoncodes import ReasonCode

from tdmon.config.daemon import MqttConfig
from tdmon.errors import IngestError
from tdmon.ingest.types import RawMessage
from tdmon.record.batch import Batch
from tdmon.record.sink import Sink

log = logging.getLogger(__name__)

#: Messages the source hands to the daemon at once, at most (:meth:`MqttSource.batches`).
BATCH = 256
#: Results handed to paho at once, at most (:meth:`MqttPublisher.pump`).
PUBLISH_BATCH = 64
#: Seconds the broker has to acknowledge a batch of results (QoS 1/2) before the publisher
#: gives up on the connection, opens a new one and sends the batch again.
ACK_TIMEOUT = 10.0


def tls_context(config: MqttConfig, base: Path | None = None) -> ssl.SSLContext | None:
    """An SSL context from the config's TLS block (paths relative to ``base``)."""
    if config.tls is None:
        return None

    def resolve(path: Path) -> str:
        return str(path if path.is_absolute() or base is None else base / path)

    tls = config.tls
    # each file is loaded on its own, so that the error names the key and the file at fault
    step = f"tls.ca_file {resolve(tls.ca_file)}" if tls.ca_file else "system CA certificates"
    try:
        context = ssl.create_default_context(
            cafile=resolve(tls.ca_file) if tls.ca_file else None
        )
        if tls.cert_file is not None:
            step = f"tls.cert_file {resolve(tls.cert_file)}"
            if tls.key_file is not None:
                step += f" / tls.key_file {resolve(tls.key_file)}"
            context.load_cert_chain(
                resolve(tls.cert_file),
                resolve(tls.key_file) if tls.key_file else None,
            )
    except (OSError, ssl.SSLError) as exc:
        reason = "no such file" if isinstance(exc, FileNotFoundError) else str(exc)
        raise IngestError(f"TLS {step}: {reason}") from exc
    if config.tls.insecure:
        context.check_hostname = False
    return context


def make_client(config: MqttConfig, client_id: str, base: Path | None = None,
                queue_type: type[asyncio.Queue[aiomqtt.Message]] | None = None
                ) -> aiomqtt.Client:
    """An aiomqtt client for ``config`` (must be called inside the running loop); incoming
    messages wait in a ``queue_type`` (default asyncio.Queue)."""
    return aiomqtt.Client(
        config.host,
        config.port,
        identifier=client_id,
        username=config.username,
        password=config.resolved_password(),
        clean_session=config.clean_session,
        keepalive=config.keepalive,
        tls_context=tls_context(config, base),
        protocol=aiomqtt.ProtocolVersion.V311,
        timeout=10.0,
        # small messages: without NODELAY, Nagle and delayed ACKs add ~40 ms now and then
        socket_options=[(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)],
        queue_type=queue_type,
    )


def describe(config: MqttConfig) -> str:
    return f"mqtt {config.host}:{config.port}"


#: MQTT 5 reason codes of a CONNACK refused for the credentials: 0x86 "Bad user name or
#: password", 0x87 "Not authorized" (paho reports an MQTT 3.1.1 refusal with these too)
AUTH_REASON_CODES = frozenset({0x86, 0x87})

#: MQTT 3.1.1 CONNACK return codes for the same: 4 bad user name or password, 5 not authorised
AUTH_CONNACK_CODES = frozenset({4, 5})


def is_auth_failure(exc: BaseException) -> bool:
    """Whether the broker refused us for our credentials, from the error's reason code."""
    if not isinstance(exc, aiomqtt.MqttCodeError):
        return False
    if isinstance(exc.rc, ReasonCode):
        return exc.rc.value in AUTH_REASON_CODES
    # an integer is a 3.1.1 return code only in a refused connection; elsewhere it is paho's
    # own error number (MQTTErrorCode), where 4 and 5 mean something else
    return isinstance(exc, MqttConnectError) and exc.rc in AUTH_CONNACK_CODES


def _translate(config: MqttConfig, what: str, exc: BaseException) -> IngestError:
    text = str(exc) or type(exc).__name__
    if is_auth_failure(exc):
        text += " (check username and password)"
    return IngestError(f"{describe(config)}: {what}: {text}")


def connect_error(config: MqttConfig, exc: BaseException) -> IngestError:
    """The one-line error for a failed connection (naming bad credentials as such)."""
    return _translate(config, "cannot connect", exc)


class _Inbox(asyncio.Queue[aiomqtt.Message]):
    """The queue aiomqtt puts incoming messages in, with an event set by the first one.

    Bounded for QoS 0: a QoS 0 message that finds ``limit`` messages waiting is dropped and
    counted through ``on_drop`` (the broker keeps nothing of it anyway). A QoS 1/2 message is
    always kept: the broker sends no more of them unacknowledged than its in-flight window
    (``max_inflight_messages``), so they are bounded already, and dropping one would leave it
    unacknowledged, holding a slot of that window until the next connection. aiomqtt's own
    bound (``max_queued_incoming_messages``) is not used: it drops QoS 1 messages too and logs
    a line per message dropped.
    """

    def __init__(self, maxsize: int = 0, limit: int = 0,
                 on_drop: Callable[[int], None] | None = None) -> None:
        super().__init__(maxsize)
        self.arrived = asyncio.Event()
        self.limit = limit
        self.on_drop = on_drop
        self.dropped = 0

    def put_nowait(self, item: aiomqtt.Message) -> None:
        if self.limit and item.qos == 0 and self.qsize() >= self.limit:
            self.dropped += 1
            if self.on_drop is not None:
                self.on_drop(1)
            return
        super().put_nowait(item)
        self.arrived.set()


def _inbox_class(made: list[_Inbox], limit: int = 0,
                 on_drop: Callable[[int], None] | None = None
                 ) -> type[asyncio.Queue[aiomqtt.Message]]:
    """A queue class for aiomqtt's ``queue_type`` whose instance, once aiomqtt has made it,
    is in ``made``: the source takes what waits there without aiomqtt's message iterator,
    which makes a task per message (:meth:`MqttSource.batches`). ``limit`` and ``on_drop``:
    see :class:`_Inbox` (0: unbounded)."""

    class Inbox(_Inbox):
        def __init__(self, maxsize: int = 0) -> None:
            super().__init__(maxsize, limit, on_drop)
            made.append(self)

    return Inbox


class ManualAcks:
    """Acknowledge QoS 1/2 messages only when told to: the adapter for the two calls aiomqtt
    2.5 lacks (aiomqtt issue 345, "Application-controlled acknowledgements").

    aiomqtt acknowledges each message as paho hands it over, before the daemon has it; paho
    itself can wait for the application. The two paho calls that switch this on and send an
    acknowledgement are made here, on the paho client aiomqtt wraps (its private ``_client``),
    and nowhere else in tdmon. ``tests/ingest/test_mqtt_manual_ack.py`` holds each to what it
    must do on a real broker, so a paho release that changes either fails there.
    """

    def __init__(self, client: aiomqtt.Client) -> None:
        # private: the paho client, for the two calls below only
        self._paho: mqtt.Client = client._client  # noqa: SLF001  aiomqtt issue 345: no public way
        # call 1 of 2: manual acknowledgement, switched on before connecting, so that nothing
        # a resumed session brings (messages queued while the daemon was away) is
        # acknowledged on receipt (paho >= 2.0; also its constructor's manual_ack=True,
        # which aiomqtt does not pass on)
        self._paho.manual_ack_set(True)

    def ack(self, mid: int, qos: int) -> None:
        """Acknowledge message ``mid`` received at ``qos`` (1: PUBACK, 2: PUBCOMP).

        On a connection that is gone paho has no socket to send on and nothing is sent: the
        broker keeps the message and resends it on the next session.
        """
        # call 2 of 2: paho queues the acknowledgement; aiomqtt's event-loop writer sends it
        self._paho.ack(mid, qos)


class RecentDeliveries:
    """The last ``size`` (topic, payload) pairs handed out, to recognise a redelivery.

    A broker resends a QoS 1 message it had no acknowledgement for when the session resumes
    after a dropped connection; at most 65 535 such messages can be outstanding (the packet
    identifier space), so a window of that size holds every one this run could have handed out.
    """

    def __init__(self, size: int = 65_535) -> None:
        self.size = size
        self._seen: dict[int, int] = {}
        self._order: deque[int] = deque()

    def add(self, topic: str, payload: bytes) -> None:
        key = hash((topic, payload))
        self._seen[key] = self._seen.get(key, 0) + 1
        self._order.append(key)
        if len(self._order) > self.size:
            old = self._order.popleft()
            left = self._seen[old] - 1
            if left:
                self._seen[old] = left
            else:
                del self._seen[old]

    def __contains__(self, item: tuple[str, bytes]) -> bool:
        return hash(item) in self._seen

    def __len__(self) -> int:
        return len(self._order)


class MqttSource:
    """Subscribe to ``<prefix>/#`` with QoS 1 on a persistent session and yield RawMessages.

    ``async with MqttSource(...) as source: async for raw in source: ...``. A fixed client id
    and ``clean_session=False`` make the broker keep the subscription and queue QoS 1 messages
    while the daemon is away, so a reconnect resumes where it left off.

    Acknowledgements are manual (docs/daemon.md, "At-least-once delivery"): each RawMessage
    carries an ``ack`` the daemon calls once the message is processed and flushed to the
    recording; until then the broker keeps it and resends it after a reconnect or a restart.
    On a connection after this run's first (``recent`` is shared by every connection of one
    daemon), a message whose topic and payload this run already handed out is one the broker
    sent again, and is marked ``duplicate``.

    At most ``max_queued`` QoS 0 messages wait in the client (0: no bound); one more is
    dropped and counted through ``on_drop`` (see :class:`_Inbox`).
    """

    name = "mqtt"

    def __init__(
        self,
        config: MqttConfig,
        subscribe: list[str],
        ignore_prefixes: tuple[str, ...] = (),
        base: Path | None = None,
        recent: RecentDeliveries | None = None,
        max_queued: int = 0,
        on_drop: Callable[[int], None] | None = None,
    ) -> None:
        self.config = config
        self.subscribe = subscribe
        self.max_queued = max_queued
        self.on_drop = on_drop
        self.ignore_prefixes = ignore_prefixes
        self.base = base
        self.recent = recent if recent is not None else RecentDeliveries()
        self._client: aiomqtt.Client | None = None
        self._messages: aiomqtt.MessagesIterator | None = None
        self._inbox: _Inbox | None = None
        self._subscribing: asyncio.Future[None] | None = None
        self._acks: ManualAcks | None = None
        self._resumed = False

    async def __aenter__(self) -> MqttSource:
        made: list[_Inbox] = []
        client = make_client(self.config, self.config.client_id, self.base,
                             queue_type=_inbox_class(made, self.max_queued, self.on_drop))
        (inbox,) = made  # made by the client's constructor
        acks = ManualAcks(client)  # before connecting: see ManualAcks
        try:
            await client.__aenter__()
        except aiomqtt.MqttError as exc:
            raise _translate(self.config, "cannot connect", exc) from exc
        subscribing = asyncio.ensure_future(self._subscribe(client))
        try:
            await self._subscribed(client, subscribing, inbox)
        except BaseException:
            subscribing.cancel()
            await asyncio.gather(subscribing, return_exceptions=True)
            await _quiet_exit(client)
            raise
        self._subscribing = subscribing
        self._client = client
        self._messages = client.messages
        self._inbox = inbox
        self._acks = acks
        # the broker resends only on a session resumed within this run: nothing handed out
        # before, nothing to recognise
        self._resumed = len(self.recent) > 0
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._subscribing is not None:
            self._subscribing.cancel()
            await asyncio.gather(self._subscribing, return_exceptions=True)
            self._subscribing = None
        if self._client is not None:
            await _quiet_exit(self._client)
            self._client = None
            self._messages = None
            self._inbox = None

    async def _subscribe(self, client: aiomqtt.Client) -> None:
        for topic in self.subscribe:
            # no timeout here: see _subscribed
            await client.subscribe(topic, qos=self.config.qos, timeout=math.inf)

    async def _subscribed(self, client: aiomqtt.Client, subscribing: asyncio.Future[None],
                          inbox: _Inbox) -> None:
        """Wait until the broker has answered the subscription, or a message has come.

        On a resumed session mosquitto sends the whole queue it kept for it before its
        answer (aiomqtt read 57 000 messages in 9.6 s, near its 10 s timeout); a message that
        comes shows the session's subscription in place, and the answer is then awaited
        beside the reading. A new session's answer comes at once. Neither within the
        client's timeout: the subscription failed.
        """
        arrived: asyncio.Future[Any] = asyncio.ensure_future(inbox.arrived.wait())
        waiting: list[asyncio.Future[Any]] = [subscribing, arrived]
        try:
            await asyncio.wait(waiting, timeout=client.timeout,
                               return_when=asyncio.FIRST_COMPLETED)
        finally:
            arrived.cancel()
        if subscribing.done():
            exc = subscribing.exception()
            if exc is not None:
                raise _translate(self.config, "cannot subscribe", exc) from exc
        elif not inbox.arrived.is_set():
            raise _translate(self.config, "cannot subscribe",
                             aiomqtt.MqttError("Operation timed out"))

    def __aiter__(self) -> MqttSource:
        return self

    async def __anext__(self) -> RawMessage:
        while True:
            raw = self._raw(await self._next())
            if raw is not None:
                return raw

    async def batches(self) -> AsyncIterator[list[RawMessage]]:
        """What has arrived, up to ``BATCH`` messages at a time (the daemon queues a list as
        one entry and processes what is queued as one burst: docs/daemon.md, "Bursts").

        aiomqtt reads one packet per event-loop turn: after the first message the source
        gives the loop a turn per message while more arrive, so a backlog comes in lists of
        up to ``BATCH``, and a message at a rig's rate on its own at once. What waits is
        handed over before a lost connection is reported.
        """
        assert self._inbox is not None, "not entered"
        inbox = self._inbox
        while True:
            batch: list[RawMessage] = []
            first = self._raw(await self._next())
            if first is not None:
                batch.append(first)
            while len(batch) < BATCH:
                while not inbox.empty() and len(batch) < BATCH:
                    raw = self._raw(inbox.get_nowait())
                    if raw is not None:
                        batch.append(raw)
                if len(batch) >= BATCH:
                    break
                await asyncio.sleep(0)  # a turn, in which aiomqtt reads a packet if one came
                if inbox.empty():
                    break
            if batch:
                yield batch

    async def _next(self) -> aiomqtt.Message:
        """The next message: one waiting in the queue, else the next to arrive (raises
        :class:`IngestError` when the connection is lost before one does)."""
        assert self._inbox is not None and self._messages is not None, "not entered"
        if not self._inbox.empty():
            return self._inbox.get_nowait()
        subscribing = self._subscribing
        if subscribing is not None and subscribing.done():
            exc = subscribing.exception()
            if exc is not None:
                raise _translate(self.config, "cannot subscribe", exc) from exc
        try:
            return await anext(self._messages)
        except aiomqtt.MqttError as exc:
            raise _translate(self.config, "connection lost", exc) from exc

    def _raw(self, message: aiomqtt.Message) -> RawMessage | None:
        """The RawMessage of one message (None: one of our own results, acknowledged)."""
        assert self._acks is not None, "not entered"
        topic = message.topic.value
        ack = (None if message.qos == 0
               else functools.partial(self._acks.ack, message.mid, message.qos))
        if topic.startswith(self.ignore_prefixes):
            if ack is not None:
                ack()  # our own results coming back on the shared prefix: nothing to keep
            return None
        payload = cast(bytes, message.payload)  # paho's bytes, as received
        duplicate = self._resumed and (topic, payload) in self.recent
        if not duplicate:
            self.recent.add(topic, payload)
        return RawMessage("mqtt", topic, payload, time.time(), ack, False, duplicate)


async def _quiet_exit(client: aiomqtt.Client) -> None:
    try:
        await client.__aexit__(None, None, None)
    except Exception as exc:  # already disconnected: nothing left to close
        log.debug("mqtt disconnect: %s", exc)


async def disconnection(client: aiomqtt.Client) -> BaseException | None:
    """Wait until ``client``'s connection ends; why it ended (None: we closed it).

    aiomqtt's message iterator raises when the connection ends, with the reason as the
    cause; a client that subscribes to nothing receives no message before that.
    """
    try:
        async for _ in client.messages:
            pass
    except aiomqtt.MqttError as exc:
        return exc.__cause__
    return None


class MqttPublisher(Sink):
    """Sink publishing result messages as JSON on ``<prefix>/tdmon/<name>``.

    ``write_batch`` only queues (sinks are synchronous); the daemon's supervisor keeps a
    connection open with :meth:`connect` and runs :meth:`pump` on it. When the queue is full
    the oldest message is dropped and counted through ``on_drop``, never silently. The rigs of
    a fleet daemon share one publisher, each through its own prefix (:meth:`for_prefix`).

    A batch the broker has not acknowledged within ``ack_timeout`` seconds is sent again on a
    new connection (counted in ``timeouts``): a connection whose acknowledgements stopped
    coming must not hold the results back for good.
    """

    def __init__(
        self,
        config: MqttConfig,
        prefix: str,
        names: list[str],
        qos: int = 1,
        queue_size: int = 10_000,
        on_drop: Callable[[int], None] | None = None,
        base: Path | None = None,
        ack_timeout: float = ACK_TIMEOUT,
    ) -> None:
        self.name = "mqtt-publish"
        self.config = config
        self.prefix = prefix.strip("/")
        self.names = frozenset(names)
        #: the pipeline routes only these topics here (see tdmon.daemon.pipeline)
        self.topics = frozenset(f"/tdmon/{name}" for name in names)
        self.qos = qos
        self.base = base
        self._queue: deque[tuple[str, bytes]] = deque()
        self._queue_size = queue_size
        self._wake = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self._on_drop = on_drop
        self.dropped = 0
        self.published = 0
        self.ack_timeout = ack_timeout
        #: batches sent again on a new connection, their acknowledgement overdue
        self.timeouts = 0

    def write_batch(self, batch: Batch) -> None:
        self.enqueue(self.prefix, batch)

    def for_prefix(self, prefix: str) -> Sink:
        """A sink publishing on ``<prefix>/tdmon/<name>`` through this publisher (itself for
        its own prefix)."""
        prefix = prefix.strip("/")
        return self if prefix == self.prefix else _PrefixedResults(self, prefix)

    def enqueue(self, prefix: str, batch: Batch) -> None:
        """Queue the messages of ``batch`` for ``<prefix>/tdmon/<name>``."""
        name = batch.topic.rsplit("/", 1)[-1]
        if name not in self.names:
            return
        topic = f"{prefix}/tdmon/{name}"
        queue = self._queue
        for data in batch.encoded().datas:
            if len(queue) >= self._queue_size:
                queue.popleft()
                self.dropped += 1
                if self._on_drop is not None:
                    self._on_drop(1)
            queue.append((topic, data))
        self._idle.clear()
        self._wake.set()

    def close(self) -> None:
        """Nothing to release here: the supervisor owns the connection."""

    def connect(self) -> _PublisherConnection:
        return _PublisherConnection(self.config, self.config.client_id + "-pub", self.base)

    async def pump(self, client: aiomqtt.Client) -> None:
        """Publish queued messages in order until cancelled; a message is removed only once
        sent (QoS 1/2: acknowledged by the broker; QoS 0: written to the socket).

        Up to ``PUBLISH_BATCH`` are published at once: each ``publish`` hands its message to
        paho before it waits, in the order the calls start, and the event loop writes them
        together (one at a time, a result waits for its own write or acknowledgement first:
        an event-loop turn or more per message, more than the daemon spends on a sample).
        """
        client.pending_calls_threshold = max(client.pending_calls_threshold, PUBLISH_BATCH)
        queue = self._queue
        while True:
            if not queue:
                self._idle.set()
                self._wake.clear()
                await self._wake.wait()
                continue
            batch = list(islice(queue, PUBLISH_BATCH))
            outcomes = await self._publish(client, batch)
            for outcome in outcomes:
                if isinstance(outcome, BaseException):
                    # the rest go again on the next connection, in order
                    raise _translate(self.config, "publish failed", outcome) from outcome
                queue.popleft()
                self.published += 1

    async def _publish(self, client: aiomqtt.Client, batch: list[tuple[str, bytes]]
                       ) -> list[BaseException | None]:
        """Publish ``batch`` at once; each call's outcome (None: sent). Raises
        :class:`IngestError` when the batch is not through within ``ack_timeout``."""
        try:
            async with asyncio.timeout(self.ack_timeout):
                # one deadline for the whole batch, not aiomqtt's per call
                return await asyncio.gather(
                    *(client.publish(topic, payload, qos=self.qos, timeout=math.inf)
                      for topic, payload in batch),
                    return_exceptions=True)
        except TimeoutError:
            self.timeouts += 1
            raise IngestError(
                f"{describe(self.config)}: {len(batch)} results not acknowledged within "
                f"{self.ack_timeout:g} s; sending them again on a new connection") from None

    async def drain(self, timeout: float) -> bool:
        """Wait until everything queued is published (True) or ``timeout`` passes (False)."""
        try:
            await asyncio.wait_for(self._idle.wait(), timeout)
        except TimeoutError:
            return False
        return True

    @property
    def pending(self) -> int:
        return len(self._queue)


class _PrefixedResults(Sink):
    """A rig's results on its own prefix through a shared :class:`MqttPublisher`."""

    def __init__(self, publisher: MqttPublisher, prefix: str) -> None:
        self.publisher = publisher
        self.prefix = prefix
        self.topics = publisher.topics

    def write_batch(self, batch: Batch) -> None:
        self.publisher.enqueue(self.prefix, batch)


class _PublisherConnection:
    def __init__(self, config: MqttConfig, client_id: str, base: Path | None) -> None:
        self.config = config
        self.client_id = client_id
        self.base = base
        self._client: aiomqtt.Client | None = None

    async def __aenter__(self) -> aiomqtt.Client:
        # results are fire-and-forget for the broker: no persistent session needed
        client = make_client(self.config.model_copy(update={"clean_session": True}),
                             self.client_id, self.base)
        try:
            await client.__aenter__()
        except aiomqtt.MqttError as exc:
            raise _translate(self.config, "cannot connect", exc) from exc
        self._client = client
        return client

    async def __aexit__(self, *exc: object) -> None:
        if self._client is not None:
            await _quiet_exit(self._client)
            self._client = None
