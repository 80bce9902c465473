"""Play the rig: publish a CSV log or a recording as per-channel messages on MQTT or Zenoh.

Used by ``tdmon publish`` for demonstrations, soak tests and benchmarks. Reading is pure
(``csv_messages``, ``recording_messages`` yield ``(t, topic, payload)``); sending goes through a
small ``Sender`` (one for MQTT, one for Zenoh), and pacing by :func:`publish`.
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import json
import time
from collections.abc import AsyncIterator, Callable, Iterable, Iterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import aiomqtt
import zenoh

from tdmon.channels import check_channel
from tdmon.config.daemon import MqttConfig, ZenohConfig
from tdmon.errors import IngestError
from tdmon.ingest.mcap_source import iter_raw
from tdmon.ingest.mqtt import make_client
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
    time_column: str = "time_utc", shift: float = 0.0,
) -> Iterator[tuple[float, str, bytes]]:
    """One message per non-empty mapped cell: ``(t, topic, payload)``, times shifted by
    ``shift`` seconds. Columns missing from the file are an error."""
    columns = tuple(columns)
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
                body = {"t": t + shift, "value": value, "unit": column.unit}
                yield t + shift, f"{prefix}/{column.channel}", json.dumps(body).encode()


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


class Sender(Protocol):
    async def send(self, topic: str, payload: bytes) -> None: ...

    async def flush(self) -> None: ...


class MqttSender:
    """QoS-1 publishing with a window of unacknowledged messages (one at a time is slow)."""

    def __init__(self, client: aiomqtt.Client, qos: int = 1, window: int = 200) -> None:
        self.client = client
        self.qos = qos
        self._window = asyncio.Semaphore(window)
        self._tasks: set[asyncio.Task[None]] = set()
        self._error: BaseException | None = None
        client.pending_calls_threshold = window + 10

    async def send(self, topic: str, payload: bytes) -> None:
        if self._error is not None:
            raise IngestError(f"mqtt publish failed: {self._error}") from self._error
        await self._window.acquire()
        task = asyncio.create_task(self._publish(topic, payload))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _publish(self, topic: str, payload: bytes) -> None:
        try:
            await self.client.publish(topic, payload, qos=self.qos)
        except aiomqtt.MqttError as exc:
            self._error = exc
        finally:
            self._window.release()

    async def flush(self) -> None:
        await asyncio.gather(*list(self._tasks))
        if self._error is not None:
            raise IngestError(f"mqtt publish failed: {self._error}") from self._error


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
async def mqtt_sender(config: MqttConfig, qos: int = 1) -> AsyncIterator[MqttSender]:
    client = make_client(config, config.client_id)
    try:
        await client.__aenter__()
    except aiomqtt.MqttError as exc:
        raise IngestError(f"mqtt {config.host}:{config.port}: cannot connect: {exc}") from exc
    try:
        sender = MqttSender(client, qos)
        yield sender
        await sender.flush()
    finally:
        # already gone is fine: the flush above has reported any loss
        with contextlib.suppress(aiomqtt.MqttError):
            await client.__aexit__(None, None, None)


@asynccontextmanager
async def zenoh_sender(config: ZenohConfig, wait_for_peer: float = 5.0
                       ) -> AsyncIterator[ZenohSender]:
    session = await asyncio.to_thread(open_session, config)
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
