"""A WITS Level 0 feed as a daemon source: TCP client, TCP server or serial (docs/wits0.md).

The transport only delivers bytes; :mod:`tdmon.ingest.wits0` cuts them into frames and
decodes them, and :func:`frame_messages` (pure) turns each frame into RawMessages in tdmon's
own JSON payload form, so that the pipeline records, decodes and replays them like any other
input: one message per mapped item on ``<prefix>/<channel topic>`` (SI value, SI unit, the
WITS line; the first also carries the whole frame), and one per rejected line or frame
(``error`` says why) on ``<prefix>/wits0``.

Reconnecting is the supervisor's: a source raises :class:`~tdmon.errors.IngestError` when it
cannot connect, when the peer closes, and when the feed stays silent for ``timeout`` seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import time
from collections import deque
from collections.abc import Mapping
from datetime import tzinfo
from types import TracebackType
from typing import Any, Protocol

from tdmon.channels import CHANNEL_UNITS
from tdmon.config.daemon import Wits0Config
from tdmon.errors import IngestError
from tdmon.ingest.types import RawMessage
from tdmon.ingest.wits0 import (
    MAX_FRAME_BYTES,
    FrameError,
    FrameParser,
    ItemSpec,
    WitsFrame,
    decode_frame,
)

log = logging.getLogger(__name__)

#: the RawMessage source name of everything a WITS0 feed gives
SOURCE = "wits0"

#: topic level (after the prefix) of rejected lines and frames
REJECT_TOPIC = "wits0"

_READ_SIZE = 65536


def frame_messages(parsed: WitsFrame | FrameError, items: Mapping[str, ItemSpec],
                   topics: Mapping[str, str], reject_topic: str, receive_time: float,
                   tz: tzinfo | None = None) -> list[RawMessage]:
    """The RawMessages of one parsed frame (or frame error), in the order they go in.

    ``topics`` maps each channel to its full topic (``<prefix>/<topic>``). A mapped item
    gives ``{"t", "value", "unit", "wits"}`` (SI value and unit, the line as received) on
    its channel's topic, the first of a frame also ``"frame"`` (the whole frame) and
    ``"time_from"``; a mapped item whose value is not a number gives the same with the
    value text and ``"error"``, so that the decoder rejects it; any other rejected line,
    a frame without any mapped item and a frame error give ``{"t", "error", "wits" or
    "frame"}`` on ``reject_topic``, which no channel uses, so it is rejected too and kept.
    """
    if isinstance(parsed, FrameError):
        body = {"t": receive_time, "error": parsed.reason,
                "frame": parsed.raw.decode("ascii", "replace")}
        return [_raw(reject_topic, body, receive_time)]
    decoded = decode_frame(parsed, items, receive_time, tz)
    frame_text = parsed.raw.decode("ascii", "replace")
    messages: list[RawMessage] = []
    first = True
    for item in decoded.items:
        body = {"t": decoded.t, "value": item.value, "unit": CHANNEL_UNITS[item.channel][0],
                "wits": item.line}
        if first:
            body.update(frame=frame_text, time_from=decoded.time_from)
            if parsed.error is not None:
                body["frame_error"] = parsed.error
            first = False
        messages.append(_raw(topics[item.channel], body, receive_time))
    for error in decoded.errors:
        code = error.text[:4]
        spec = items.get(code)
        if spec is not None and error.text[4:].strip():
            # the value of a mapped item: on its channel, where the decoder rejects it
            body = {"t": decoded.t, "value": error.text[4:].strip(),
                    "unit": CHANNEL_UNITS[spec.channel][0], "wits": error.text,
                    "error": error.reason}
            messages.append(_raw(topics[spec.channel], body, receive_time))
        else:
            body = {"t": decoded.t, "error": error.reason, "wits": error.text}
            messages.append(_raw(reject_topic, body, receive_time))
    if first:
        # nothing mapped: the frame is kept (raw) with the reason
        reason = parsed.error or "no item of the frame is mapped to a channel"
        body = {"t": decoded.t, "error": reason, "frame": frame_text}
        messages.insert(0, _raw(reject_topic, body, receive_time))
    return messages


def _raw(topic: str, body: dict[str, Any], receive_time: float) -> RawMessage:
    return RawMessage(SOURCE, topic, json.dumps(body).encode(), receive_time)


class Wits0Source:
    """``async with Wits0Source(...) as source: async for raw in source: ...``.

    Parameters
    ----------
    config : the ``[sources.wits0]`` section
    items : the feed's item map (:func:`tdmon.ingest.wits0.item_map`)
    topics : channel -> full topic of its samples
    reject_topic : full topic of rejected lines and frames
    tz : the zone of the frames' date and time items
    max_frame_bytes : longest frame kept
    """

    name = SOURCE

    def __init__(self, config: Wits0Config, items: Mapping[str, ItemSpec],
                 topics: Mapping[str, str], reject_topic: str, tz: tzinfo,
                 max_frame_bytes: int = MAX_FRAME_BYTES) -> None:
        self.config = config
        self.items = items
        self.topics = topics
        self.reject_topic = reject_topic
        self.tz = tz
        self.max_frame_bytes = max_frame_bytes
        self._parser = FrameParser(max_frame_bytes)
        self._pending: deque[RawMessage] = deque()
        self._transport: _Transport | None = None
        self._lost: IngestError | None = None

    async def __aenter__(self) -> Wits0Source:
        config = self.config
        self._parser = FrameParser(self.max_frame_bytes)
        self._pending.clear()
        self._lost = None
        transport: _Transport
        if config.mode == "tcp-client":
            transport = _TcpClient(config)
        elif config.mode == "tcp-server":
            transport = _TcpServer(config)
        else:
            transport = _Serial(config)
        await transport.open()
        self._transport = transport
        return self

    async def __aexit__(self, exc_type: type[BaseException] | None,
                        exc: BaseException | None, tb: TracebackType | None) -> None:
        if self._transport is not None:
            await self._transport.close()
            self._transport = None

    def __aiter__(self) -> Wits0Source:
        return self

    async def __anext__(self) -> RawMessage:
        assert self._transport is not None, "not entered"
        while not self._pending:
            if self._lost is not None:
                raise self._lost
            data: bytes | IngestError | None
            try:
                data = await asyncio.wait_for(self._transport.read(), self.config.timeout)
            except TimeoutError:
                data = IngestError(f"{self._transport.describe()}: no data for "
                                   f"{self.config.timeout:g} s")
            except IngestError as exc:
                data = exc
            if isinstance(data, IngestError):
                # what the stream left unfinished is recorded before the error is raised
                self._lost = data
                self._messages(self._parser.close(), time.time())
                continue
            if data is None:
                # a new connection replaced the old one (server mode): start afresh
                self._messages(self._parser.close(), time.time())
                self._parser = FrameParser(self.max_frame_bytes)
                continue
            self._messages(self._parser.feed(data), time.time())
        return self._pending.popleft()

    def _messages(self, parsed: list[WitsFrame | FrameError], receive_time: float) -> None:
        for item in parsed:
            self._pending.extend(frame_messages(item, self.items, self.topics,
                                                self.reject_topic, receive_time, self.tz))


class _Transport(Protocol):
    """Bytes from a peer: ``read()`` returns the next bytes, None when a new connection
    replaced the old, and raises IngestError when the peer is gone."""

    async def open(self) -> None: ...

    async def read(self) -> bytes | None: ...

    async def close(self) -> None: ...

    def describe(self) -> str: ...


class _TcpClient:
    def __init__(self, config: Wits0Config) -> None:
        self.host, self.port = str(config.host), int(config.port or 0)
        self.timeout = config.timeout
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    def describe(self) -> str:
        return f"wits0 tcp {self.host}:{self.port}"

    async def open(self) -> None:
        try:
            self._reader, self._writer = await asyncio.wait_for(
                asyncio.open_connection(self.host, self.port), self.timeout)
        except (OSError, TimeoutError) as exc:
            raise IngestError(f"{self.describe()}: cannot connect: "
                              f"{exc or type(exc).__name__}") from exc

    async def read(self) -> bytes | None:
        assert self._reader is not None
        try:
            data = await self._reader.read(_READ_SIZE)
        except OSError as exc:
            raise IngestError(f"{self.describe()}: connection lost: {exc}") from exc
        if not data:
            raise IngestError(f"{self.describe()}: connection closed by the rig")
        return data

    async def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            with contextlib.suppress(OSError, ConnectionError):
                await self._writer.wait_closed()
            self._writer = None


class _TcpServer:
    """Listen; one rig connection at a time, a new one replaces the old."""

    def __init__(self, config: Wits0Config) -> None:
        self.listen, self.port = config.listen, int(config.port or 0)
        self._server: asyncio.Server | None = None
        self._chunks: asyncio.Queue[tuple[int, bytes | None]] = asyncio.Queue(maxsize=64)
        self._current = 0  # the connection whose bytes count
        self._writers: dict[int, asyncio.StreamWriter] = {}
        self._reading = 0  # the connection whose bytes read() returned last
        self._stash: bytes | None = None

    def describe(self) -> str:
        return f"wits0 listening on {self.listen}:{self.port}"

    async def open(self) -> None:
        try:
            self._server = await asyncio.start_server(self._accept, self.listen, self.port)
        except OSError as exc:
            raise IngestError(f"{self.describe()}: cannot listen: {exc}") from exc

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self._current += 1
        me = self._current
        for old in list(self._writers.values()):
            old.close()  # its reader ends; what it still sends is ignored
        self._writers[me] = writer
        log.info("%s: rig connected from %s", self.describe(), writer.get_extra_info("peername"))
        try:
            while me == self._current:
                try:
                    data = await reader.read(_READ_SIZE)
                except OSError:
                    break
                if not data:
                    break
                await self._chunks.put((me, data))
        finally:
            self._writers.pop(me, None)
            writer.close()

    async def read(self) -> bytes | None:
        if self._stash is not None:
            stashed, self._stash = self._stash, None
            return stashed
        while True:
            me, data = await self._chunks.get()
            if me != self._current:
                continue  # from a connection already replaced
            if me != self._reading:
                first = self._reading == 0
                self._reading = me
                if not first:
                    # the stream changed: say so before the new connection's first bytes
                    self._stash = data
                    return None
            return data

    async def close(self) -> None:
        for writer in list(self._writers.values()):
            writer.close()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await asyncio.wait_for(self._server.wait_closed(), 5)
            self._server = None


class _Serial:
    """A serial line through pyserial (the ``serial`` extra), read when the loop sees the
    port's descriptor readable (POSIX), so no thread is needed."""

    def __init__(self, config: Wits0Config) -> None:
        self.device, self.baud_rate = str(config.device), config.baud_rate
        self._port: Any = None
        self._chunks: asyncio.Queue[bytes | BaseException] = asyncio.Queue(maxsize=256)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._paused = False

    def describe(self) -> str:
        return f"wits0 serial {self.device}"

    async def open(self) -> None:
        try:
            import serial
        except ImportError as exc:
            raise IngestError("wits0 serial needs pyserial: pip install 'tdmon[serial]'") from exc
        try:
            # timeout=0: reads return at once with what is there
            self._port = await asyncio.to_thread(serial.Serial, self.device, self.baud_rate,
                                                 timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise IngestError(f"{self.describe()}: cannot open: {exc}") from exc
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(self._port.fileno(), self._on_readable)

    def _on_readable(self) -> None:
        import serial

        assert self._loop is not None
        if self._chunks.full():
            # the pipeline is behind: stop watching the port until read() takes a chunk
            self._loop.remove_reader(self._port.fileno())
            self._paused = True
            return
        try:
            data: bytes | BaseException = self._port.read(_READ_SIZE)
        except (serial.SerialException, OSError) as exc:
            # e.g. the device went away: report it once, stop watching
            self._loop.remove_reader(self._port.fileno())
            data = exc
        if isinstance(data, BaseException) or data:
            self._chunks.put_nowait(data)

    async def read(self) -> bytes | None:
        data = await self._chunks.get()
        if isinstance(data, BaseException):
            raise IngestError(f"{self.describe()}: read failed: {data}") from data
        if self._paused and self._loop is not None and self._port is not None:
            self._paused = False
            self._loop.add_reader(self._port.fileno(), self._on_readable)
        return data

    async def close(self) -> None:
        if self._port is not None:
            if self._loop is not None:
                with contextlib.suppress(Exception):
                    self._loop.remove_reader(self._port.fileno())
            with contextlib.suppress(Exception):
                self._port.close()
            self._port = None
