"""Play a rig's WITS0 server: serve a session's samples as WITS Level 0 frames over TCP or
a serial line.

Used by ``tdmon publish X.mcap|X.csv --wits0 URL`` for tests and demonstrations
(docs/wits0.md, "Simulator"). The pieces are pure where they can be:

- :func:`session_steps` groups the ``(t, topic, payload)`` messages of
  :mod:`tdmon.ingest.publish` into time steps of SI channel values (one step per distinct
  message time: one CSV row, or one logged instant of a recording);
- :func:`build_frame` turns one step into the bytes of one frame with the codec
  (:func:`tdmon.ingest.wits0.encode_sample_frame`): the date and time items (0105, 0106) and
  every mapped channel of the step in its configured WITS unit;
- :class:`Wits0Server` owns the listening socket and the connected clients, and
  :class:`Wits0Sender` lets :func:`tdmon.ingest.publish.publish` pace the frames at real time
  x N like any other transport.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import termios
import tty
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from datetime import tzinfo
from types import TracebackType
from urllib.parse import parse_qs, urlsplit

from tdmon.channels import CHANNEL_UNITS
from tdmon.errors import IngestError
from tdmon.ingest.decode import parse_payload
from tdmon.ingest.wits0 import ItemSpec, encode_sample_frame
from tdmon.units import conversion

log = logging.getLogger(__name__)

#: How long one client may hold a frame back [s] before it is dropped (a stuck consumer must
#: not stall the others)
CLIENT_DRAIN_TIMEOUT = 10.0


@dataclass(frozen=True, slots=True)
class Step:
    """All samples of one time step: ``t`` [Unix s] and SI values by canonical channel."""

    t: float
    values: Mapping[str, float]


def session_steps(messages: Iterable[tuple[float, str, bytes]]) -> Iterator[Step]:
    """Group consecutive messages with the same ``t`` into one step of SI values.

    The channel is the topic's last level (as in the bundled replays, the importers' files and
    the CSV route); other topics are skipped, and so are payloads that do not decode. A payload
    without a unit is taken as SI. When a channel appears twice in one step the last value
    counts. The group's ``t`` (the CSV row's time, the recording's log time) is the step's
    time: a WITS frame has one time for all its items.

    Raises
    ------
    IngestError
        A payload's unit is unknown or does not fit its channel.
    """
    factors: dict[tuple[str, str], tuple[float, float]] = {}
    for t, group in itertools.groupby(messages, key=lambda message: message[0]):
        values: dict[str, float] = {}
        for _, topic, payload in group:
            channel = topic.rsplit("/", 1)[-1]
            if channel not in CHANNEL_UNITS:
                continue
            parsed = parse_payload(payload)
            if isinstance(parsed, str):
                log.debug("%s: skipped: %s", topic, parsed)
                continue
            _, value, unit = parsed
            target = CHANNEL_UNITS[channel][0]
            key = (channel, unit or target)
            factor = factors.get(key)
            if factor is None:
                try:
                    factor = factors[key] = conversion(unit or target, target)
                except ValueError as exc:
                    raise IngestError(f"{topic}: unit '{unit}' not usable for {channel}: "
                                      f"{exc}") from None
            values[channel] = value * factor[0] + factor[1]
        if values:
            yield Step(t, values)


@dataclass(frozen=True, slots=True)
class ServeAddress:
    """Where the simulator listens: ``tcp://HOST:PORT``."""

    host: str
    port: int


@dataclass(frozen=True, slots=True)
class SerialAddress:
    """The serial line the simulator writes to: ``serial:///dev/ttyS0?baud=9600``."""

    device: str
    baud: int = 9600


#: Line speeds a serial URL may ask for [bit/s] (those termios names on every platform)
BAUD_RATES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200)

_USAGE = "expected tcp://HOST:PORT or serial:///dev/DEVICE?baud=9600"


def parse_serve_url(text: str, flag: str = "--wits0") -> ServeAddress | SerialAddress:
    """``tcp://127.0.0.1:5001`` or ``serial:///dev/pts/3?baud=9600``; anything else is the
    user's mistake."""
    parts = urlsplit(text)
    if parts.scheme == "serial":
        query = parse_qs(parts.query)
        unknown = sorted(set(query) - {"baud"})
        if not parts.path or parts.netloc or unknown:
            raise IngestError(f"{flag} '{text}': {_USAGE}")
        baud_text = query.get("baud", ["9600"])[-1]
        if not baud_text.isdigit() or int(baud_text) not in BAUD_RATES:
            raise IngestError(f"{flag} '{text}': baud must be one of "
                              f"{', '.join(map(str, BAUD_RATES))}")
        return SerialAddress(parts.path, int(baud_text))
    if parts.scheme != "tcp":
        raise IngestError(f"{flag} '{text}': {_USAGE} (e.g. tcp://127.0.0.1:5001)")
    try:
        port = parts.port
    except ValueError:
        port = None
    if not parts.hostname or port is None:
        raise IngestError(f"{flag} '{text}': expected tcp://HOST:PORT with a port number")
    return ServeAddress(parts.hostname, port)


class Wits0SerialPort:
    """Write frames to a serial line (raw, 8N1, no flow control) at ``baud``.

    An async context manager. The standard library's termios sets the line up, so no serial
    package is needed to serve; writes run in a thread because a line at 9600 bit/s takes
    about 0.2 s per frame. A pseudo-terminal (``os.openpty``) stands in for a line in tests.
    """

    def __init__(self, device: str, baud: int = 9600) -> None:
        self.device = device
        self.baud = baud
        self.frames_sent = 0
        self._fd: int | None = None

    async def __aenter__(self) -> Wits0SerialPort:
        try:
            # non-blocking open: without CLOCAL (set below) a real port waits for a carrier
            fd = os.open(self.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError as exc:
            raise IngestError(f"wits0: cannot open {self.device}: {exc.strerror or exc}") from exc
        try:
            tty.setraw(fd)
            attributes = termios.tcgetattr(fd)
            speed = getattr(termios, f"B{self.baud}")
            attributes[4] = attributes[5] = speed  # output and input speed
            attributes[2] = (attributes[2] & ~(termios.CSTOPB | termios.PARENB)) | termios.CLOCAL
            termios.tcsetattr(fd, termios.TCSANOW, attributes)
            os.set_blocking(fd, True)  # writes wait in their thread for a full line buffer
        except termios.error as exc:
            os.close(fd)
            raise IngestError(f"wits0: {self.device} is not a serial line: {exc}") from exc
        self._fd = fd
        log.info("wits0: writing to %s at %d bit/s", self.device, self.baud)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    async def send(self, frame: bytes) -> None:
        """Write one frame (all of it: a full line buffer blocks the thread, not the loop)."""
        assert self._fd is not None, "not entered"
        try:
            await asyncio.to_thread(_write_all, self._fd, frame)
        except OSError as exc:
            raise IngestError(f"wits0: writing to {self.device} failed: "
                              f"{exc.strerror or exc}") from exc
        self.frames_sent += 1


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


class Wits0Server:
    """Listen on ``host:port`` and send every frame to every connected client.

    An async context manager; clients may come and go at any time (a rig's WITS server does
    not wait for anyone): a frame goes to the clients connected when it is sent. A client that
    disconnects, or does not take a frame within ``drain_timeout`` seconds, is dropped.
    Whatever a client sends (some consumers send their own frames back) is read and ignored.
    """

    def __init__(self, host: str, port: int, drain_timeout: float = CLIENT_DRAIN_TIMEOUT) -> None:
        self.host = host
        self.port = port
        self.drain_timeout = drain_timeout
        self.frames_sent = 0
        self.clients_served = 0
        self._server: asyncio.Server | None = None
        self._clients: dict[asyncio.StreamWriter, asyncio.Task[None]] = {}
        self._joined = asyncio.Condition()

    @property
    def clients(self) -> int:
        """Clients connected now."""
        return len(self._clients)

    @property
    def bound_port(self) -> int:
        """The port listened on (the chosen one when ``port`` was 0)."""
        assert self._server is not None, "not entered"
        return int(self._server.sockets[0].getsockname()[1])

    async def __aenter__(self) -> Wits0Server:
        try:
            self._server = await asyncio.start_server(self._accept, self.host, self.port)
        except OSError as exc:
            raise IngestError(f"wits0: cannot listen on {self.host}:{self.port}: "
                              f"{exc.strerror or exc}") from exc
        log.info("wits0: serving on %s:%d", self.host, self.bound_port)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._server is not None:
            self._server.close()
        for writer in list(self._clients):
            await self._drop(writer)
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        log.info("wits0: client %s connected", peer)
        self._clients[writer] = asyncio.create_task(self._discard_input(reader, writer))
        self.clients_served += 1
        async with self._joined:
            self._joined.notify_all()

    async def _discard_input(self, reader: asyncio.StreamReader,
                             writer: asyncio.StreamWriter) -> None:
        # reading also notices the client's end of the connection (EOF) between frames
        with contextlib.suppress(OSError):
            while await reader.read(4096):
                pass
        if writer in self._clients:
            self._clients.pop(writer)
            writer.close()

    async def wait_for_clients(self, count: int = 1) -> None:
        """Return once ``count`` clients are connected (at --speed max a session would
        otherwise be over before anybody connected)."""
        async with self._joined:
            await self._joined.wait_for(lambda: len(self._clients) >= count)

    async def send(self, frame: bytes) -> None:
        """Write one frame to every connected client; drop those that cannot take it."""
        clients = list(self._clients)
        for writer in clients:
            writer.write(frame)
        for writer in clients:
            try:
                await asyncio.wait_for(writer.drain(), self.drain_timeout)
            except (OSError, TimeoutError) as exc:
                log.warning("wits0: client %s dropped: %s", writer.get_extra_info("peername"),
                            exc or type(exc).__name__)
                await self._drop(writer)
        self.frames_sent += 1

    async def _drop(self, writer: asyncio.StreamWriter) -> None:
        task = self._clients.pop(writer, None)
        if task is not None:
            task.cancel()
        writer.close()  # sends what is still buffered, then closes
        try:
            await asyncio.wait_for(writer.wait_closed(), self.drain_timeout)
        except TimeoutError:
            writer.transport.abort()  # a client that reads nothing more must not hold us
        except OSError:
            pass


class Wits0Sender:
    """The :class:`tdmon.ingest.publish.Sender` of frames (to TCP clients or a serial line):
    the topic is ignored."""

    def __init__(self, server: Wits0Server | Wits0SerialPort) -> None:
        self.server = server

    async def send(self, topic: str, payload: bytes) -> None:
        await self.server.send(payload)

    async def flush(self) -> None:
        # the stream writers were drained frame by frame: nothing waits in a buffer of ours
        return None


def build_frame(step: Step, items: Mapping[str, ItemSpec], tz: tzinfo | None = None,
                decimals: int | None = None) -> bytes:
    """The bytes of one WITS0 frame for ``step``: its date and time (0105, 0106, whole seconds
    in ``tz``, default UTC) and each of its channels that ``items`` maps, in the item's WITS
    unit, rounded to ``decimals`` places when given (a rig's server sends a few; None sends
    every digit, so that a consumer gets the session's values back)."""
    return encode_sample_frame(step.t, step.values, items, tz, decimals)
