"""MQTT transport (aiomqtt): a source of raw messages and a publisher sink for results.

Reconnecting is not done here: a source or publisher connection is an async context manager
that raises :class:`tdmon.errors.IngestError` when it cannot connect or loses the broker, and
the daemon's supervisor decides when to try again.
"""

from __future__ import annotations

import asyncio
import functools
import logging
import socket
import ssl
import struct
import time
from collections import deque
from collections.abc import Callable
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
                queue_type: type[asyncio.Queue[aiomqtt.Message]] | None = None) -> aiomqtt.Client:
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


class _Inbox(asyncio.Queue[Any]):
    """A client's incoming-message queue whose object the source holds.

    aiomqtt builds this queue itself from the class passed as ``queue_type`` and keeps it
    private; :func:`_inbox_class` makes a subclass per connection that hands the object back.
    It holds :class:`_Delivery` objects (:func:`_enable_manual_ack` puts them there), not
    aiomqtt's messages.
    """


def _inbox_class(made: list[_Inbox]) -> type[_Inbox]:
    """A queue class whose instances are appended to ``made`` when aiomqtt builds them."""

    class Inbox(_Inbox):
        def __init__(self, maxsize: int = 0) -> None:
            super().__init__(maxsize)
            made.append(self)

    return Inbox


class _Delivery:
    """What the source needs of one incoming PUBLISH, DUP flag included (aiomqtt's own message
    drops it, and building one validates the topic again: a third of the daemon's cost per
    message at 5 000 messages/s)."""

    __slots__ = ("dup", "mid", "payload", "qos", "receive_time", "topic")

    def __init__(self, message: mqtt.MQTTMessage) -> None:
        try:
            self.topic: str = message.topic
        except UnicodeDecodeError:  # the decoder rejects it as an unknown topic, with its text
            self.topic = message._topic.decode("utf-8", "replace")
        self.payload = bytes(message.payload)
        self.qos: int = message.qos
        self.mid: int = message.mid
        self.dup = bool(message.dup)
        self.receive_time = time.time()


def _enable_manual_ack(client: aiomqtt.Client) -> None:
    """Let ``client`` acknowledge QoS 1/2 messages only when told to, and keep DUP flags.

    aiomqtt 2.5 has no public hook for either (aiomqtt issue 345): the paho client it wraps
    (``_client``) is switched to manual acknowledgement before connecting, so that nothing
    the broker sends on a resumed session is acknowledged early, and its message callback is
    replaced by one that keeps the flag. Messages go into the same queue aiomqtt reads.

    paho's dispatch to that callback (``_handle_on_message``: two locks and a walk of its
    per-topic callback tree, which nobody fills here) is replaced too, when this paho has it:
    it cost a tenth of the daemon's time per message.
    """
    paho = client._client  # private: see the docstring
    paho.manual_ack_set(True)
    put = cast(_Inbox, client._queue).put_nowait  # our own _Inbox class, unbounded

    def on_message(_client: mqtt.Client, _userdata: Any, message: mqtt.MQTTMessage) -> None:
        put(_Delivery(message))

    paho.on_message = on_message
    if callable(getattr(paho, "_handle_on_message", None)):
        def handle_on_message(message: mqtt.MQTTMessage) -> None:
            put(_Delivery(message))

        paho._handle_on_message = handle_on_message  # type: ignore[method-assign]


class _BufferedReads:
    """paho's socket, read up to 64 kB at a time.

    paho reads each packet with three ``recv`` calls (type, length, rest), and aiomqtt's reader
    hands it one packet per event-loop turn. Served from a buffer, with :meth:`pending` saying
    how much is left (the hook aiomqtt already uses for TLS sockets), a burst of messages is
    read with one system call and handled in one turn. Everything else goes to the socket.
    """

    def __init__(self, sock: Any) -> None:
        self._sock = sock
        self._data = b""
        self._pos = 0

    def recv(self, size: int) -> bytes:
        data, pos = self._data, self._pos
        if pos >= len(data):
            data = self._sock.recv(65536)  # BlockingIOError, TLS and EOF (b"") as they come
            self._data, pos = data, 0
        end = min(pos + size, len(data))
        self._pos = end
        return data[pos:end]

    def pending(self) -> int:
        """Bytes read and not yet handed to paho (plus what TLS holds decrypted)."""
        held = len(self._data) - self._pos
        more = getattr(self._sock, "pending", None)
        return held + (more() if more is not None else 0)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sock, name)


def _buffer_reads(client: aiomqtt.Client) -> None:
    """Put :class:`_BufferedReads` under ``client``'s paho client once it is connected (its
    private ``_sock``); any bytes paho has not read yet are read through the buffer, in order."""
    paho = client._client
    sock = getattr(paho, "_sock", None)
    if sock is not None and not isinstance(sock, _BufferedReads):
        paho._sock = _BufferedReads(sock)


#: PUBACK's fixed header (packet type 4, remaining length 2), the packet id follows
_PUBACK = 0x4002 << 16


class _PubAcks:
    """The PUBACKs of one connection, queued in paho as one write per event-loop turn.

    ``paho.ack`` queues a 4-byte packet and makes a system call per message; the daemon releases
    hundreds of acknowledgements at once (after each recorder flush), so they are collected and
    handed to paho's output queue together (its private ``_packet_queue``, the call ``ack``
    makes). After the connection is gone they go nowhere, as with ``paho.ack``: the broker
    resends the messages on the next session.
    """

    def __init__(self, paho: mqtt.Client, loop: asyncio.AbstractEventLoop) -> None:
        self._paho = paho
        self._loop = loop
        self._mids: list[int] = []

    def ack(self, mid: int) -> None:
        if not self._mids:
            self._loop.call_soon(self.flush)
        self._mids.append(mid)

    def flush(self) -> None:
        mids, self._mids = self._mids, []
        if mids:
            packets = struct.pack(f"!{len(mids)}I", *[_PUBACK | mid for mid in mids])
            self._paho._packet_queue(mqtt.PUBACK, packets, 0, 0)


class RecentDeliveries:
    """The last ``size`` (topic, payload) pairs handed out, to recognise a redelivery.

    A broker resends a QoS 1 message with the DUP flag when it had no acknowledgement for it
    before the connection dropped; at most 65 535 such messages can be outstanding (the packet
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


class MqttSource:
    """Subscribe to ``<prefix>/#`` with QoS 1 on a persistent session and yield RawMessages.

    ``async with MqttSource(...) as source: async for raw in source: ...``. A fixed client id
    and ``clean_session=False`` make the broker keep the subscription and queue QoS 1 messages
    while the daemon is away, so a reconnect resumes where it left off.

    Acknowledgements are manual (docs/daemon.md, "At-least-once delivery"): each RawMessage
    carries an ``ack`` the daemon calls once the message is processed and flushed to the
    recording; until then the broker keeps it and resends it after a reconnect or a restart.
    A resent message (DUP flag) whose topic and payload this run already handed out is marked
    ``duplicate`` (``recent`` is shared by every connection of one daemon).
    """

    name = "mqtt"

    def __init__(
        self,
        config: MqttConfig,
        subscribe: list[str],
        ignore_prefixes: tuple[str, ...] = (),
        base: Path | None = None,
        recent: RecentDeliveries | None = None,
    ) -> None:
        self.config = config
        self.subscribe = subscribe
        self.ignore_prefixes = ignore_prefixes
        self.base = base
        self.recent = recent if recent is not None else RecentDeliveries()
        self._client: aiomqtt.Client | None = None
        self._inbox: _Inbox | None = None
        self._iterator: aiomqtt.MessagesIterator | None = None
        self._acks: _PubAcks | None = None
        self._lost: IngestError | None = None

    async def __aenter__(self) -> MqttSource:
        made: list[_Inbox] = []
        client = make_client(self.config, self.config.client_id, self.base,
                             queue_type=_inbox_class(made))
        (inbox,) = made  # built by the client's constructor
        _enable_manual_ack(client)
        try:
            await client.__aenter__()
        except aiomqtt.MqttError as exc:
            raise _translate(self.config, "cannot connect", exc) from exc
        _buffer_reads(client)
        try:
            for topic in self.subscribe:
                await client.subscribe(topic, qos=self.config.qos)
        except aiomqtt.MqttError as exc:
            await _quiet_exit(client)
            raise _translate(self.config, "cannot subscribe", exc) from exc
        self._client = client
        self._inbox = inbox
        self._iterator = client.messages
        self._acks = _PubAcks(client._client, asyncio.get_running_loop())
        self._lost = None
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._client is not None:
            await _quiet_exit(self._client)
            self._client = None
            self._inbox = None

    def __aiter__(self) -> MqttSource:
        return self

    async def __anext__(self) -> RawMessage:
        assert self._inbox is not None and self._iterator is not None, "not entered"
        inbox = self._inbox
        while True:
            if not inbox.empty():
                # Fast path: aiomqtt's iterator creates a task per message even when one is
                # already waiting, which costs more than all of our decoding. And after the
                # connection dropped, what waits here is still handed out (its iterator would
                # raise at once): the broker resends it unacknowledged on the next session,
                # where it is recognised as a duplicate, but a broker without persistence that
                # restarted would not, so processing it now loses nothing.
                message: _Delivery = inbox.get_nowait()
            elif self._lost is not None:
                raise self._lost
            else:
                try:
                    message = await self._iterator.__anext__()  # type: ignore[assignment]
                except aiomqtt.MqttError as exc:
                    self._lost = _translate(self.config, "connection lost", exc)
                    self._lost.__cause__ = exc
                    continue
            topic = message.topic
            ack = self._acker(message)
            if topic.startswith(self.ignore_prefixes):
                if ack is not None:
                    ack()  # our own results coming back on the shared prefix: nothing to keep
                continue
            payload = message.payload
            dup = message.dup
            duplicate = dup and (topic, payload) in self.recent
            if not duplicate:
                self.recent.add(topic, payload)
            return RawMessage("mqtt", topic, payload, message.receive_time, ack, dup, duplicate)

    def _acker(self, message: _Delivery) -> Callable[[], None] | None:
        """The acknowledgement of one QoS 1/2 message on the connection it came from.

        After that connection is gone the call does nothing (paho has no socket to send on):
        the broker resends the message on the next session, which is what at-least-once needs.
        """
        if message.qos == 0 or self._client is None:
            return None
        if message.qos == 1 and self._acks is not None:
            return functools.partial(self._acks.ack, message.mid)
        paho, mid, qos = self._client._client, message.mid, message.qos

        def ack() -> None:  # QoS 2: paho's own PUBCOMP
            paho.ack(mid, qos)

        return ack


async def _quiet_exit(client: aiomqtt.Client) -> None:
    try:
        await client.__aexit__(None, None, None)
    except Exception as exc:  # already disconnected: nothing left to close
        log.debug("mqtt disconnect: %s", exc)


class MqttPublisher(Sink):
    """Sink publishing result messages as JSON on ``<prefix>/tdmon/<name>``.

    ``write_batch`` only queues (sinks are synchronous); the daemon's supervisor keeps a
    connection open with :meth:`connect` and runs :meth:`pump` on it. When the queue is full
    the oldest message is dropped and counted through ``on_drop``, never silently. The rigs of
    a fleet daemon share one publisher, each through its own prefix (:meth:`for_prefix`).
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
        """Publish queued messages until cancelled; a message is removed only once sent
        (QoS 1/2: acknowledged; QoS 0: handed to paho, see :meth:`_publish_at_most_once`)."""
        client.pending_calls_threshold = 1000
        paho = client._client  # private: see _publish_at_most_once
        while True:
            if not self._queue:
                await self._written(paho)
                if self._queue:
                    continue
                self._idle.set()
                self._wake.clear()
                await self._wake.wait()
                continue
            if self.qos == 0:
                await self._publish_at_most_once(paho)
                continue
            topic, payload = self._queue[0]
            try:
                await client.publish(topic, payload, qos=self.qos)
            except aiomqtt.MqttError as exc:
                raise _translate(self.config, "publish failed", exc) from exc
            self._queue.popleft()
            self.published += 1

    async def _publish_at_most_once(self, paho: mqtt.Client, batch: int = 64) -> None:
        """Hand up to ``batch`` queued messages to paho at QoS 0, then wait until it has
        written them.

        aiomqtt's ``publish`` waits for each QoS 0 message to be written (an event, a timeout
        and an event-loop turn per message: a tenth of the daemon's time at 8 000 samples/s);
        paho queues them and the event loop writes them together when the socket is writable.
        A message is removed from our queue once paho holds it: at most ``batch`` are lost if
        the connection drops before the write, which QoS 0 allows.
        """
        queue = self._queue
        for _ in range(min(batch, len(queue))):
            topic, payload = queue[0]
            info = paho.publish(topic, payload, 0)
            if info.rc != mqtt.MQTT_ERR_SUCCESS:
                raise _translate(self.config, "publish failed",
                                 aiomqtt.MqttCodeError(info.rc, "Could not publish message"))
            queue.popleft()
            self.published += 1
        await self._written(paho)

    async def _written(self, paho: mqtt.Client) -> None:
        """Wait until paho has written all it holds (the event loop writes when the socket is
        writable; a broker that does not read keeps us here, and our queue bounded)."""
        turns = 0
        while paho.want_write():
            if not paho.is_connected():  # what paho holds is lost with the connection
                raise IngestError(f"{describe(self.config)}: publish failed: connection lost")
            await asyncio.sleep(0 if turns < 4 else 0.001)
            turns += 1

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
