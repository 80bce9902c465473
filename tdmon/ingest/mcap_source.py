"""Replay a recording as a source: recorded ``/tdmon/raw`` messages, or input-channel messages.

A flight recording made by the daemon holds every raw input on ``/tdmon/raw`` (JSON with the
original topic, payload and receive time); a file made elsewhere may instead hold the rig's
payloads directly on topics such as ``rig/F4/hookload``. Both replay as RawMessages, paced at
real time x ``speed`` (by log time) or as fast as the pipeline takes them (``speed=None``).
Footer-less files (a writer that was killed) are read up to their last flushed chunk. A
recorded payload kept only in part (``payload_truncated``: an oversized payload, see
docs/recording.md) cannot be replayed and is skipped, with one log line per file.
"""

from __future__ import annotations

import asyncio
import base64
import binascii
import io
import json
import logging
import struct
import time
from collections.abc import AsyncIterator, Iterable, Iterator
from itertools import islice
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import msgspec
import orjson
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.summary import Summary

from tdmon.errors import IngestError
from tdmon.ingest.types import RawMessage

RAW_TOPIC = "/tdmon/raw"

log = logging.getLogger(__name__)


class _Truncated(Exception):
    """A recorded payload kept only in part: nothing to replay."""


class _UsualRecord(msgspec.Struct, forbid_unknown_fields=True, gc=False):
    """A ``/tdmon/raw`` record as tdmon writes it: exactly :func:`raw_message`'s fields, a
    text payload. ``receive_time`` keeps an integer apart from a float: raw_message writes a
    float, so only then do the record's bytes say what it would."""

    source: str
    topic: str
    payload: str
    receive_time: float | int
    payload_encoding: str


#: Reads the usual record into a :class:`_UsualRecord`, or raises ``msgspec.DecodeError``
#: (``UnicodeDecodeError`` for invalid UTF-8): with the RawMessage made of it, 1.49 instead of
#: 1.83 us a record through orjson's dict (docs/benchmarks.md)
_read_usual = msgspec.json.Decoder(_UsualRecord).decode


def raw_from_record(channel_topic: str, data: bytes, log_time_ns: int) -> RawMessage | None:
    """Turn one MCAP message into the RawMessage it stands for (None: not an input message).

    A ``/tdmon/raw`` record whose payload was kept only in part raises ``_Truncated``.
    """
    if channel_topic == RAW_TOPIC:
        try:
            usual = _read_usual(data)
        except (msgspec.DecodeError, ValueError):
            pass  # another record (more fields, a base64 payload...) or damage: read below
        else:
            # strict JSON, as orjson's below (no NaN, no lone surrogate): the bytes say what
            # raw_message would of this RawMessage, so they may be recorded again as they are
            if type(usual.receive_time) is float and usual.payload_encoding == "utf-8":
                return RawMessage(usual.source, usual.topic, usual.payload.encode("utf-8"),
                                  usual.receive_time, None, False, False, data)
        try:
            # any other record: orjson (~5x faster than json); what it refuses (NaN, lone
            # surrogates, huge integers, damage) goes to json, whose result or error is the
            # one given. Never ``recorded``: such a record is not what raw_message writes
            record = orjson.loads(data)
        except orjson.JSONDecodeError:
            return _raw_of_record(data, log_time_ns, json_module=True)
        return _raw_of_record(record, log_time_ns)
    if channel_topic.startswith("/tdmon/"):
        return None  # derived data (samples, results): replay recomputes it
    return RawMessage("mcap", channel_topic.lstrip("/"), bytes(data), log_time_ns / 1e9)


def _raw_of_record(record: Any, log_time_ns: int, json_module: bool = False) -> RawMessage:
    """The RawMessage of a ``/tdmon/raw`` record in general: ``record`` parsed, or its bytes
    to parse with the json module (``json_module``). Raises ``_Truncated`` for a payload kept
    only in part, :class:`IngestError` for a record that is not a raw message."""
    try:
        if json_module:
            record = json.loads(record)
        if isinstance(record, dict) and record.get("payload_truncated"):
            raise _Truncated
        text = record["payload"]
        if not isinstance(text, str):
            raise TypeError(f"payload is a {type(text).__name__}, not text")
        if record.get("payload_encoding") == "base64":
            payload = base64.b64decode(text, validate=True)
        else:
            payload = text.encode("utf-8")
        return RawMessage(
            source=str(record.get("source", "mcap")),
            topic=str(record["topic"]),
            payload=payload,
            receive_time=float(record.get("receive_time", log_time_ns / 1e9)),
        )
    except (ValueError, KeyError, TypeError, binascii.Error) as exc:
        raise IngestError(f"recorded {RAW_TOPIC} message is unreadable: {exc}") from exc


def _summary(stream: IO[bytes]) -> Summary | None:
    """A finished file's summary (None without one, e.g. a footer-less file)."""
    start = stream.tell()
    try:
        return make_reader(stream).get_summary()
    except Exception:  # no footer or summary (a killed writer): decided while reading
        return None
    finally:
        stream.seek(start)


def _all_in_indexed_chunks(summary: Summary) -> bool:
    """Whether every message of the file sits in a chunk its summary indexes.

    The chunk indexes give each chunk's message-index records' total length; each such record
    is 15 bytes of opcode, length, channel id and entry length, then 16 bytes per message, so
    the chunks hold (length - 15 x channels) / 16 messages. Equal to the statistics' count:
    no message lies outside the chunks (an unchunked writer), none is left without an index.
    """
    statistics = summary.statistics
    if statistics is None or not summary.chunk_indexes:
        return False
    indexed = 0
    for index in summary.chunk_indexes:
        entries, rest = divmod(index.message_index_length - 15 * len(index.message_index_offsets),
                               16)
        if rest or entries < 0:
            return False
        indexed += entries
    return indexed == statistics.message_count


#: A record's opcode and length; a message record's channel id, sequence, log and publish time.
_RECORD = struct.Struct("<BQ")
_MESSAGE = struct.Struct("<HIQQ")


def _chunk_data(chunk: Chunk) -> bytes | None:
    """A chunk's records, decompressed (None: a compression this reader leaves to ``mcap``)."""
    if chunk.compression == "zstd":
        return zstandard.decompress(chunk.data, chunk.uncompressed_size)
    if chunk.compression == "":
        return chunk.data
    return None


def _chunk_records(data: bytes) -> Iterator[Channel | tuple[int, int, bytes]]:
    """The channel records and messages of a chunk's decompressed records, messages as
    ``(channel id, log time [ns], data)``.

    The message record's layout (MCAP specification: opcode 0x05, a 64-bit length, then
    channel id u16, sequence u32, log time u64, publish time u64 and the data) read with one
    ``struct`` call, where ``breakup_chunk`` builds a ``Message`` from a field-by-field
    stream: about five times faster on a replay's small messages. Other records (channel
    records, rare in chunks) are read by the ``mcap`` package; the rest are skipped, as there.
    A record that runs past the chunk's end, or a message record too short for its fields,
    raises ``McapError``.
    """
    offset, end = 0, len(data)
    record, message = _RECORD.unpack_from, _MESSAGE.unpack_from
    try:
        while offset < end:
            opcode, length = record(data, offset)
            start = offset + 9
            offset = start + length
            if offset > end:
                raise McapError(f"a chunk's record runs {offset - end} bytes past its end")
            if opcode == Opcode.MESSAGE:
                if length < 22:
                    raise McapError(f"a chunk's message record of {length} bytes is too short")
                channel_id, _, log_time, _ = message(data, start)
                yield channel_id, log_time, data[start + 22:offset]
            elif opcode == Opcode.CHANNEL:
                yield Channel.read(ReadDataStream(io.BytesIO(data[start:offset])))
    except struct.error as exc:
        raise McapError(f"a chunk's record is cut short: {exc}") from exc


def _indexed_messages(stream: IO[bytes], summary: Summary
                      ) -> Iterator[Channel | tuple[int, int, bytes]]:
    """The channels and messages of the file, chunk by chunk in file order (the summary's
    channels first); messages as ``(channel id, log time [ns], data)``.

    Each chunk is reached through the summary's chunk indexes, as the ``mcap`` package's
    seeking reader does, but in file order and one chunk at a time (that reader's file-order
    mode decodes every chunk before the first message), and the message-index records after
    each chunk are skipped (the stream reader parses them entry by entry). The chunk's
    records are read by :func:`_chunk_records`; a chunk compressed otherwise than zstd or
    not at all goes through the package's ``breakup_chunk``.
    """
    yield from summary.channels.values()
    for index in sorted(summary.chunk_indexes, key=lambda chunk: chunk.chunk_start_offset):
        stream.seek(index.chunk_start_offset + 1 + 8)  # past the opcode and record length
        chunk = Chunk.read(ReadDataStream(stream))
        data = _chunk_data(chunk)
        if data is not None:
            yield from _chunk_records(data)
            continue
        for item in breakup_chunk(chunk):
            if isinstance(item, Message):
                yield item.channel_id, item.log_time, item.data
            elif isinstance(item, Channel):
                yield item


def _streamed_messages(stream: IO[bytes]) -> Iterator[Channel | tuple[int, int, bytes]]:
    """Every channel and message record in turn (``mcap``'s stream reader), messages as
    :func:`_indexed_messages` gives them: for a file without a summary (a killed writer) or
    with messages outside indexed chunks."""
    for record in StreamReader(stream, skip_magic=False).records:
        if isinstance(record, Message):
            yield record.channel_id, record.log_time, record.data
        elif isinstance(record, Channel):
            yield record


def iter_raw(stream: IO[bytes]) -> Iterator[tuple[int, RawMessage]]:
    """(log_time_ns, RawMessage) in file order; a file with ``/tdmon/raw`` yields only those."""
    channels: dict[int, str] = {}
    summary = _summary(stream)
    has_raw = summary is not None and any(
        channel.topic == RAW_TOPIC for channel in summary.channels.values())
    records: Iterable[Channel | tuple[int, int, bytes]]
    if summary is not None and _all_in_indexed_chunks(summary):
        records = _indexed_messages(stream, summary)
    else:
        # a channel's record comes with its first message, so other topics (``/truth/...``)
        # may come before the first /tdmon/raw one
        records = _streamed_messages(stream)
    truncated = 0
    try:
        for record in records:
            if type(record) is tuple:
                channel_id, log_time, data = record
                topic = channels.get(channel_id)
                if topic is None or (has_raw and topic != RAW_TOPIC):
                    continue
                try:
                    raw = raw_from_record(topic, data, log_time)
                except _Truncated:
                    truncated += 1
                    continue
                if raw is not None:
                    yield log_time, raw
            elif isinstance(record, Channel):
                channels[record.id] = record.topic
                has_raw = has_raw or record.topic == RAW_TOPIC
    except (McapError, EOFError, ValueError) as exc:
        # a truncated file ends in the middle of a record: what came before is good
        if "magic" in str(exc).lower() and not channels:
            raise IngestError(f"not an MCAP file: {exc}") from exc
    finally:
        if truncated:
            log.warning("skipped %d recorded payloads kept only in part (oversized when "
                        "received; rejected then, not replayable)", truncated)


class McapSource:
    """A recording as an async context manager yielding RawMessages (finite)."""

    name = "mcap"

    def __init__(self, path: str | Path, speed: float | None = None, batch: int = 256) -> None:
        if speed is not None and speed <= 0:
            raise ValueError("speed must be positive (or None for as fast as possible)")
        self.path = Path(path)
        self.speed = speed
        self.batch = batch
        self._file: IO[bytes] | None = None
        self._records: Iterator[tuple[int, RawMessage]] | None = None
        self._first_log_ns: int | None = None
        self._start_wall = 0.0
        self._count = 0

    async def __aenter__(self) -> McapSource:
        try:
            self._file = self.path.open("rb")
        except OSError as exc:
            raise IngestError(f"cannot open recording {self.path}: {exc}") from exc
        self._records = iter_raw(self._file)
        self._first_log_ns = None
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __aiter__(self) -> McapSource:
        return self

    async def batches(self) -> AsyncIterator[list[RawMessage]]:
        """The messages in lists: up to ``batch`` at a time at full speed (the daemon queues a
        list as one entry), one at a time when paced."""
        if self.speed is not None:
            async for raw in self:
                yield [raw]
            return
        records = self._records
        assert records is not None, "not entered"
        size = self.batch
        while True:
            batch: list[RawMessage] = []
            try:
                for _, raw in islice(records, size):
                    batch.append(raw)
            except Exception:
                if batch:  # what came before an unreadable record is handed over first
                    self._count += len(batch)
                    yield batch
                raise
            if not batch:
                return
            self._count += len(batch)
            yield batch
            await asyncio.sleep(0)  # let the rest of the daemon run between batches

    async def __anext__(self) -> RawMessage:
        assert self._records is not None, "not entered"
        try:
            log_ns, raw = next(self._records)
        except StopIteration:
            raise StopAsyncIteration from None
        self._count += 1
        if self.speed is None:
            if self._count % self.batch == 0:
                await asyncio.sleep(0)  # let the rest of the daemon run between batches
            return raw
        if self._first_log_ns is None:
            self._first_log_ns = log_ns
            self._start_wall = time.monotonic()
        due = self._start_wall + (log_ns - self._first_log_ns) / 1e9 / self.speed
        delay = due - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        return raw
