"""Play the rig: publish a CSV log or a recording as per-channel messages on MQTT or Zenoh.

Used by ``tdmon publish`` for demonstrations, soak tests and benchmarks. Reading is pure
(``csv_messages``, ``recording_messages`` yield ``(t, topic, payload)``); sending goes through a
small ``Sender`` (one for MQTT, one for Zenoh), and pacing by :func:`publish`.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import time
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import aiomqtt
import orjson
import zenoh

from tdmon.channels import check_channel
from tdmon.config.daemon import MqttConfig, ZenohConfig
from tdmon.errors import IngestError
from tdmon.ingest.mcap_source import iter_raw
from tdmon.ingest.mqtt import connect_error, disconnection, make_client
from tdmon.ingest.zenoh_io import open_session
from tdmon.units import parse_time


@dataclass(frozen=True, slots=True)
class Column:
    """One CSV column feeding one channel, in ``unit``."""

    channel: str
    column: str
    unit: str


#: The column layout of the Volve F-4 CSV files (DESIGN data folder).
VOLVE_COLUMNS: tuple[Column, ...] = (
    Column("hookload", "hookload_kN", "kN"),
    Column("torque", "surface_torque_kNm", "kN*m"),
    Column("bit_depth", "bit_depth_m", "m"),
    Column("hole_depth", "hole_depth_m", "m"),
    Column("block_position", "block_pos_comp_m", "m"),
    Column("rpm", "surface_rpm", "rpm"),
    Column("flow_in", "flow_in_Lpm", "L/min"),
    Column("spp", "spp_bar", "bar"),
    Column("wob", "wob_kN", "kN"),
)


def parse_columns(text: str) -> tuple[Column, ...]:
    """``"hookload=hookload_kN:kN,bit_depth=bit_depth_m:m"`` -> columns."""
    columns = []
    for item in filter(None, (part.strip() for part in text.split(","))):
        try:
            channel, rest = item.split("=", 1)
            column, unit = rest.rsplit(":", 1)
        except ValueError:
            raise IngestError(f"column map item '{item}' is not channel=column:unit") from None
        try:
            check_channel(channel)
        except ValueError as exc:
            raise IngestError(f"column map: {exc}") from None
        columns.append(Column(channel.strip(), column.strip(), unit.strip()))
    if not columns:
        raise IngestError("column map is empty")
    return tuple(columns)


def csv_messages(
    path: Path, prefix: str, columns: Iterable[Column] = VOLVE_COLUMNS,
    time_column: str = "time_utc", shift: float = 0.0, seq: bool = False,
) -> Iterator[tuple[float, str, bytes]]:
    """One message per non-empty mapped cell: ``(t, topic, payload)``, times shifted by
    ``shift`` seconds. Columns missing from the file are an error. ``seq``: number each
    topic's messages 1, 2, ... in the payload (the daemon counts gaps in it as lost)."""
    columns = tuple(columns)
    counters = dict.fromkeys((c.channel for c in columns), 0)
    try:
        handle = path.open(newline="", encoding="utf-8")
    except OSError as exc:
        raise IngestError(f"cannot read {path}: {exc}") from exc
    with handle:
        reader = csv.DictReader(handle)
        fields = set(reader.fieldnames or ())
        missing = [c.column for c in columns if c.column not in fields]
        if time_column not in fields:
            missing.append(time_column)
        if missing:
            raise IngestError(f"{path}: no column {', '.join(missing)}")
        for line, row in enumerate(reader, start=2):
            t = parse_time(_number_or_text(row[time_column]))
            if isinstance(t, str):
                raise IngestError(f"{path}:{line}: {t}")
            for column in columns:
                cell = row[column.column].strip()
                if not cell:
                    continue  # missing values are not sent at all, as a rig would
                try:
                    value = float(cell)
                except ValueError:
                    raise IngestError(f"{path}:{line}: {column.column} is not a number: "
                                      f"'{cell}'") from None
                body: dict[str, object] = {"t": t + shift, "value": value,
                                           "unit": column.unit}
                if seq:
                    counters[column.channel] += 1
                    body["seq"] = counters[column.channel]
                # a cell of NaN or infinity goes as null (JSON has no word for either): the
                # daemon rejects it, as it would the rig's
                yield t + shift, f"{prefix}/{column.channel}", orjson.dumps(body)


def _number_or_text(cell: str) -> float | str:
    try:
        return float(cell)
    except ValueError:
        return cell


def recording_messages(path: Path, prefix: str | None = None
                       ) -> Iterator[tuple[float, str, bytes]]:
    """The raw inputs of a recording as ``(t, topic, payload)``; ``prefix`` replaces the
    recorded topic's prefix (everything before the last '/')."""
    try:
        handle = path.open("rb")
    except OSError as exc:
        raise IngestError(f"cannot read {path}: {exc}") from exc
    with handle:
        for log_ns, raw in iter_raw(handle):
            topic = raw.topic
            if prefix is not None:
                topic = f"{prefix}/{topic.rsplit('/', 1)[-1]}"
            yield log_ns / 1e9, topic, raw.payload


def csv_message_count(path: Path, columns: Iterable[Column] = VOLVE_COLUMNS) -> int:
    """How many messages :func:`csv_messages` sends for ``path`` (non-empty mapped cells),
    without parsing a number (for a progress bar); 0 when the file cannot be read."""
    names = [c.column for c in columns]
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            return sum(1 for row in reader for name in names if (row.get(name) or "").strip())
    except (OSError, UnicodeDecodeError, csv.Error):
        return 0


def recording_message_count(path: Path) -> int | None:
    """How many raw inputs a recording holds, from its summary (None: not stated)."""
    from mcap.reader import make_reader

    try:
        with path.open("rb") as handle:
            summary = make_reader(handle).get_summary()
    except Exception:  # not MCAP, truncated, no summary: the count is only for display
        return None
    if summary is None or summary.statistics is None:
        return None
    counts = summary.statistics.channel_message_counts
    raw = [counts.get(cid, 0) for cid, ch in summary.channels.items() if ch.topic == "/tdmon/raw"]
    return sum(raw) if raw else None


class Sender(Protocol):
    async def send(self, topic: str, payload: bytes) -> None: ...

    async def flush(self) -> None: ...


class MqttSender:
    """QoS 1 publishing with a window of unacknowledged messages that survives the broker
    going away.

    Every message is kept until the broker acknowledges it. When the connection is lost (a
    failed publish, or the broker closing it), the messages in flight are abandoned on the old
    connection, the sender reconnects with backoff (``retry_initial`` doubling to
    ``retry_max`` seconds, for ever: Ctrl-C stops it) and sends every unacknowledged message
    again, oldest first, before any new one: at least once, in order. ``send`` waits while
    the broker is away. ``on_state`` gets one line per loss and per reconnection.
    """

    def __init__(self, config: MqttConfig, qos: int = 1, window: int = 200,
                 retry_initial: float = 0.5, retry_max: float = 10.0,
                 on_state: Callable[[str], None] | None = None) -> None:
        self.config = config
        self.qos = qos
        self.window = window
        self.retry_initial = retry_initial
        self.retry_max = retry_max
        self.on_state = on_state or (lambda line: None)
        self._window = asyncio.Semaphore(window)
        self._unconfirmed: dict[int, tuple[str, bytes]] = {}  # insertion order = send order
        self._next = 0
        self._tasks: set[asyncio.Task[None]] = set()
        self._client: aiomqtt.Client | None = None
        self._healthy = asyncio.Event()
        self._broken = asyncio.Event()
        self._error: BaseException | None = None
        self._watch: asyncio.Task[None] | None = None
        #: messages the broker acknowledged; reconnections; messages sent again after one
        self.confirmed = 0
        self.reconnects = 0
        self.resent = 0

    async def start(self) -> None:
        """Connect the first time (a broker that is not there at all is an error)."""
        self._client = await self._connect()
        self._healthy.set()
        self._watch = asyncio.create_task(self._keep_connected(), name="mqtt-publish-watch")

    async def _connect(self) -> aiomqtt.Client:
        client = make_client(self.config, self.config.client_id)
        client.pending_calls_threshold = self.window + 10
        try:
            await client.__aenter__()
        except aiomqtt.MqttError as exc:
            raise connect_error(self.config, exc) from exc
        return client

    @property
    def pending(self) -> int:
        """Messages sent or waiting to be sent again, not yet acknowledged by the broker."""
        return len(self._unconfirmed)

    async def send(self, topic: str, payload: bytes) -> None:
        await self._window.acquire()
        await self._healthy.wait()
        number = self._next
        self._next += 1
        self._unconfirmed[number] = (topic, payload)
        self._spawn(number)

    def _spawn(self, number: int) -> None:
        assert self._client is not None
        task = asyncio.create_task(self._publish(self._client, number))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _publish(self, client: aiomqtt.Client, number: int) -> None:
        topic, payload = self._unconfirmed[number]
        try:
            await client.publish(topic, payload, qos=self.qos)
        except aiomqtt.MqttError as exc:
            # kept (and its window slot held) for sending again on the next connection
            if client is self._client and self._healthy.is_set():
                self._error = exc
                self._healthy.clear()
                self._broken.set()
            return
        if self._unconfirmed.pop(number, None) is not None:
            self.confirmed += 1
            self._window.release()

    async def _keep_connected(self) -> None:
        while True:
            client = self._client
            assert client is not None
            gone: asyncio.Future[BaseException | None] = asyncio.ensure_future(
                disconnection(client))
            broken: asyncio.Future[Any] = asyncio.ensure_future(self._broken.wait())
            await asyncio.wait([gone, broken], return_when=asyncio.FIRST_COMPLETED)
            for waiter in (gone, broken):
                waiter.cancel()
            await asyncio.gather(gone, broken, return_exceptions=True)
            self._healthy.clear()
            reason = self._error or (gone.result() if gone.done() and not gone.cancelled()
                                     else None)
            stranded = list(self._tasks)
            for task in stranded:
                task.cancel()
            await asyncio.gather(*stranded, return_exceptions=True)
            with contextlib.suppress(aiomqtt.MqttError, OSError):
                await client.__aexit__(None, None, None)
            delay = self.retry_initial
            while True:
                self.on_state(f"broker lost ({reason or 'connection closed'}); "
                              f"{len(self._unconfirmed)} unacknowledged; reconnecting in "
                              f"{delay:g} s")
                await asyncio.sleep(delay)
                try:
                    self._client = await self._connect()
                    break
                except IngestError as exc:
                    reason = exc
                    delay = min(delay * 2, self.retry_max)
            self.reconnects += 1
            self._error = None
            self._broken.clear()
            waiting = list(self._unconfirmed)
            self.resent += len(waiting)
            self.on_state(f"reconnected; sending {len(waiting)} unacknowledged message(s) again")
            for number in waiting:  # created before any new send: sent first, in order
                self._spawn(number)
            self._healthy.set()

    async def flush(self) -> None:
        """Wait until the broker has acknowledged every message (reconnecting if need be)."""
        while self._unconfirmed:
            await asyncio.sleep(0.02)

    async def close(self) -> None:
        if self._watch is not None:
            self._watch.cancel()
            await asyncio.gather(self._watch, return_exceptions=True)
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._client is not None:
            # already gone is fine: what was not acknowledged is counted by the caller
            with contextlib.suppress(aiomqtt.MqttError, OSError):
                await self._client.__aexit__(None, None, None)
            self._client = None


class ZenohSender:
    def __init__(self, session: zenoh.Session) -> None:
        self.session = session
        self._publishers: dict[str, zenoh.Publisher] = {}

    async def send(self, topic: str, payload: bytes) -> None:
        publisher = self._publishers.get(topic)
        if publisher is None:
            publisher = self.session.declare_publisher(
                topic, congestion_control=zenoh.CongestionControl.BLOCK)
            self._publishers[topic] = publisher
        publisher.put(payload)

    async def flush(self) -> None:
        for publisher in self._publishers.values():
            publisher.undeclare()
        self._publishers.clear()


@asynccontextmanager
async def mqtt_sender(config: MqttConfig, qos: int = 1,
                      on_state: Callable[[str], None] | None = None
                      ) -> AsyncIterator[MqttSender]:
    """A connected :class:`MqttSender`; on leaving normally, waits for every acknowledgement."""
    sender = MqttSender(config, qos, on_state=on_state)
    await sender.start()
    try:
        yield sender
        await sender.flush()
    finally:
        await sender.close()


@asynccontextmanager
async def zenoh_sender(config: ZenohConfig, wait_for_peer: float = 5.0
                       ) -> AsyncIterator[ZenohSender]:
    opening = asyncio.ensure_future(asyncio.to_thread(open_session, config))
    try:
        session = await asyncio.shield(opening)
    except asyncio.CancelledError:
        # stopped (Ctrl-C) while the session opens in its thread: it opens anyway, and an
        # open session left behind can hold the process at exit, so close it first
        with contextlib.suppress(Exception):
            await asyncio.to_thread((await opening).close)
        raise
    try:
        deadline = time.monotonic() + wait_for_peer
        # peer-to-peer puts go nowhere until a subscriber's session has connected
        while (not list(session.info.peers_zid()) and not list(session.info.routers_zid())
               and time.monotonic() < deadline):
            await asyncio.sleep(0.05)
        sender = ZenohSender(session)
        yield sender
        await sender.flush()
    finally:
        await asyncio.to_thread(session.close)


async def publish(
    messages: Iterable[tuple[float, str, bytes]],
    sender: Sender,
    speed: float | None = None,
    on_sent: Callable[[int], None] | None = None,
) -> int:
    """Send every message, paced at real time x ``speed`` by their ``t`` (None: at once)."""
    count = 0
    first_t: float | None = None
    start = time.monotonic()
    for t, topic, payload in messages:
        if speed is not None:
            if first_t is None:
                first_t = t
            delay = start + (t - first_t) / speed - time.monotonic()
            if delay > 0:
                await asyncio.sleep(delay)
        await sender.send(topic, payload)
        count += 1
        if on_sent is not None:
            on_sent(count)
        if speed is None and count % 512 == 0:
            await asyncio.sleep(0)
    await sender.flush()
    return count
