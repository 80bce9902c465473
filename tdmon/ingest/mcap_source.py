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
import json
import logging
import time
from collections.abc import AsyncIterator, Iterator
from itertools import islice
from pathlib import Path
from types import TracebackType
from typing import IO, Any

import orjson
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

from tdmon.errors import IngestError
from tdmon.ingest.types import RawMessage

RAW_TOPIC = "/tdmon/raw"

#: The fields of a ``/tdmon/raw`` record as :func:`tdmon.ingest.types.raw_message` writes it
#: for a payload kept whole
_RAW_FIELDS = frozenset({"source", "topic", "receive_time", "payload", "payload_encoding"})

log = logging.getLogger(__name__)


class _Truncated(Exception):
    """A recorded payload kept only in part: nothing to replay."""


def raw_from_record(channel_topic: str, data: bytes, log_time_ns: int) -> RawMessage | None:
    """Turn one MCAP message into the RawMessage it stands for (None: not an input message).

    A ``/tdmon/raw`` record whose payload was kept only in part raises ``_Truncated``.
    """
    if channel_topic == RAW_TOPIC:
        try:
            record = orjson.loads(data)
        except orjson.JSONDecodeError:
            # what orjson refuses (NaN, lone surrogates, damage) goes to json, whose result
            # or error is the one given
            return _raw_of_record(data, log_time_ns, json_module=True)
        # bytes that say what raw_message would of the RawMessage may be recorded again as
        # they are (RawMessage.recorded)
        if _says_what_raw_message_would(record):
            return _raw_of_record(record, log_time_ns, recorded=data)
        if type(record) is dict and not all(type(record.get(k, "")) is str
                                            for k in ("source", "topic")):
            # a name that is not text (orjson reads an integer beyond 64 bits as a float):
            # the json module's reading is the one given
            return _raw_of_record(data, log_time_ns, json_module=True)
        return _raw_of_record(record, log_time_ns)
    if channel_topic.startswith("/tdmon/"):
        return None  # derived data (samples, results): replay recomputes it
    return RawMessage("mcap", channel_topic.lstrip("/"), bytes(data), log_time_ns / 1e9)


def _says_what_raw_message_would(record: Any) -> bool:
    """Whether a record (strict JSON, read by orjson) holds exactly what ``raw_message`` writes
    of the RawMessage made of it: its five fields, a float time, a text payload as UTF-8."""
    return (type(record) is dict and record.keys() == _RAW_FIELDS
            and type(record["receive_time"]) is float and type(record["payload"]) is str
            and record["payload_encoding"] == "utf-8" and type(record["source"]) is str
            and type(record["topic"]) is str)


def _raw_of_record(record: Any, log_time_ns: int, json_module: bool = False,
                   recorded: bytes | None = None) -> RawMessage:
    """The RawMessage of a ``/tdmon/raw`` record: ``record`` parsed, or its bytes to parse
    with the json module (``json_module``). Raises ``_Truncated`` for a payload kept only in
    part, :class:`IngestError` for a record that is not a raw message."""
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
            recorded=recorded,
        )
    except (ValueError, KeyError, TypeError, binascii.Error) as exc:
        raise IngestError(f"recorded {RAW_TOPIC} message is unreadable: {exc}") from exc


def _has_raw_channel(stream: IO[bytes]) -> bool:
    """Whether a finished file's summary lists a ``/tdmon/raw`` channel (False without a
    summary, e.g. a footer-less file: then its channel record decides, when it comes)."""
    start = stream.tell()
    try:
        summary = make_reader(stream).get_summary()
    except Exception:  # no footer or summary (a killed writer): decided while reading
        return False
    finally:
        stream.seek(start)
    return summary is not None and any(
        channel.topic == RAW_TOPIC for channel in summary.channels.values())


def iter_raw(stream: IO[bytes]) -> Iterator[tuple[int, RawMessage]]:
    """(log_time_ns, RawMessage) in file order; a file with ``/tdmon/raw`` yields only those.

    The records are read one after another by the ``mcap`` package's stream reader, which
    reads a file without a footer (a killed writer) up to its first incomplete record too.
    """
    channels: dict[int, str] = {}
    has_raw = _has_raw_channel(stream)
    truncated = 0
    try:
        for record in StreamReader(stream, skip_magic=False).records:
            if type(record) is Message:
                topic = channels.get(record.channel_id)
                if topic is None or (has_raw and topic != RAW_TOPIC):
                    continue
                try:
                    raw = raw_from_record(topic, record.data, record.log_time)
                except _Truncated:
                    truncated += 1
                    continue
                if raw is not None:
                    yield record.log_time, raw
            elif type(record) is Channel:
                # a channel's record comes with its first message, so without a summary other
                # topics (``/truth/...``) may come before the first /tdmon/raw one
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
