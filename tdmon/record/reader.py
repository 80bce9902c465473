"""Reading flight recordings: decoded JSON messages, topic filters, counts per topic.

mcap ships no JSON decoder, hence :class:`JsonDecoderFactory`. A finished file is read through
mcap's seeking reader (log-time order, summary statistics for counts). A footer-less file (a
writer that was killed) is refused unless ``allow_unfinished=True``, in which case its records
are read in file order up to the first incomplete one (see :func:`iter_records_tolerant`, also
used by recovery).
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Callable, Collection, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any, Final, NamedTuple

from mcap.decoder import DecoderFactory
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from tdmon.errors import RecordError

MAGIC: Final = b"\x89MCAP0\r\n"
_FOOTER_OPCODE: Final = 0x02
# Footer record: opcode (1) + length (8) + summary_start (8) + summary_offset_start (8) + crc (4).
_FOOTER_TAIL: Final = 1 + 8 + 20 + len(MAGIC)


class RecordedMessage(NamedTuple):
    """One decoded message of a recording."""

    topic: str
    log_time_ns: int
    message: dict[str, Any]


class JsonDecoderFactory(DecoderFactory):
    """Decodes channels with ``message_encoding="json"`` into Python objects."""

    def decoder_for(
        self, message_encoding: str, schema: Schema | None
    ) -> Callable[[bytes], Any] | None:
        if message_encoding == "json":
            return json.loads
        return None


def describe_os_error(path: Path, exc: OSError) -> str:
    """One line naming the file and what is wrong with it."""
    if isinstance(exc, FileNotFoundError):
        return f"{path}: no such file"
    if isinstance(exc, IsADirectoryError):
        return f"{path}: is a folder, not an MCAP file"
    if isinstance(exc, PermissionError):
        return f"{path}: permission denied"
    return f"{path}: cannot read: {exc.strerror or exc}"


@contextmanager
def open_recording(path: str | os.PathLike[str]) -> Iterator[IO[bytes]]:
    """Open an MCAP file for reading, with one clear :class:`RecordError` for any problem.

    Checks the magic so that a non-MCAP file is named as such.
    """
    file_path = Path(path)
    try:
        stream = open(file_path, "rb")  # noqa: SIM115 - closed below
    except OSError as exc:
        raise RecordError(describe_os_error(file_path, exc)) from exc
    try:
        try:
            head = stream.read(len(MAGIC))
        except OSError as exc:
            raise RecordError(describe_os_error(file_path, exc)) from exc
        if not head:
            raise RecordError(
                f"{file_path}: empty file (a recorder stopped before its first flush?)"
            )
        if head != MAGIC:
            raise RecordError(f"{file_path}: not an MCAP file")
        stream.seek(0)
        yield stream
    finally:
        stream.close()


def has_footer(stream: IO[bytes]) -> bool:
    """Whether the file ends with a footer record and the closing magic (i.e. was finished)."""
    stream.seek(0, os.SEEK_END)
    size = stream.tell()
    if size < len(MAGIC) + _FOOTER_TAIL:
        stream.seek(0)
        return False
    stream.seek(size - _FOOTER_TAIL)
    tail = stream.read(_FOOTER_TAIL)
    stream.seek(0)
    opcode, length = struct.unpack_from("<BQ", tail)
    return tail.endswith(MAGIC) and opcode == _FOOTER_OPCODE and length == 20


def is_finished(path: str | os.PathLike[str]) -> bool:
    """Whether an MCAP file has its footer (``RecordError`` if it is not MCAP at all)."""
    with open_recording(path) as stream:
        return has_footer(stream)


class TolerantScan:
    """Records of a possibly truncated file, in file order, up to the first damaged one.

    Iterating yields Header, Schema, Channel, Message and Metadata records (chunks are opened).
    Afterwards ``complete`` says whether the footer was reached and ``stop_reason`` why not.
    """

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream
        self.complete = False
        self.stop_reason = ""

    def __iter__(self) -> Iterator[McapRecord]:
        reader = StreamReader(self._stream, validate_crcs=True, record_size_limit=1 << 31)
        records = reader.records
        while True:
            try:
                record = next(records)
            except StopIteration:
                self.complete = True
                return
            except Exception as exc:
                # A chunk cut by the kill (EndOfFile, struct.error), a CRC mismatch, zstd
                # garbage (zstandard.ZstdError): everything before it was a complete record and
                # nothing after it can be trusted, whatever the exception's type.
                self.stop_reason = f"{type(exc).__name__}: {exc}".rstrip(": ")
                return
            if isinstance(record, Header | Schema | Channel | Message | Metadata):
                yield record


def iter_records_tolerant(stream: IO[bytes]) -> TolerantScan:
    """See :class:`TolerantScan`."""
    return TolerantScan(stream)


def _iter_unfinished(
    stream: IO[bytes], topics: Collection[str] | None
) -> Iterator[RecordedMessage]:
    channels: dict[int, Channel] = {}
    for record in TolerantScan(stream):
        if isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Message):
            channel = channels.get(record.channel_id)
            if channel is None or (topics is not None and channel.topic not in topics):
                continue
            if channel.message_encoding != "json":
                continue
            yield RecordedMessage(channel.topic, record.log_time, json.loads(record.data))


def read_messages(
    path: str | os.PathLike[str],
    topics: Collection[str] | str | None = None,
    *,
    allow_unfinished: bool = False,
) -> Iterator[RecordedMessage]:
    """Decoded messages of a recording, in log-time order, optionally only some topics.

    Raises :class:`RecordError` for a missing, unreadable or non-MCAP file, and for an
    unfinished one unless ``allow_unfinished`` (then read in file order up to the last flush).
    """
    wanted = [topics] if isinstance(topics, str) else topics
    with open_recording(path) as stream:
        if not has_footer(stream):
            if not allow_unfinished:
                raise RecordError(
                    f"{path}: unfinished recording (no footer); run `tdmon recover {path}` first"
                )
            yield from _iter_unfinished(stream, wanted)
            return
        reader = make_reader(stream, decoder_factories=[JsonDecoderFactory()])
        try:
            for _schema, channel, message, decoded in reader.iter_decoded_messages(
                topics=wanted, log_time_order=True
            ):
                yield RecordedMessage(channel.topic, message.log_time, decoded)
        except (McapError, struct.error, ValueError) as exc:
            raise RecordError(f"{path}: damaged MCAP file: {exc}") from exc


def topic_counts(path: str | os.PathLike[str], *, allow_unfinished: bool = False) -> dict[str, int]:
    """Number of messages per topic (from the summary statistics when the file has them)."""
    with open_recording(path) as stream:
        if has_footer(stream):
            try:
                summary = make_reader(stream).get_summary()
            except (McapError, struct.error, ValueError) as exc:
                raise RecordError(f"{path}: damaged MCAP summary: {exc}") from exc
            if summary is not None and summary.statistics is not None:
                counts: dict[str, int] = {channel.topic: 0 for channel in summary.channels.values()}
                for channel_id, count in summary.statistics.channel_message_counts.items():
                    topic = summary.channels[channel_id].topic
                    counts[topic] = counts.get(topic, 0) + count
                return counts
    counts = {}
    for item in read_messages(path, allow_unfinished=allow_unfinished):
        counts[item.topic] = counts.get(item.topic, 0) + 1
    return counts


def schemas_of(path: str | os.PathLike[str]) -> dict[str, dict[str, Any]]:
    """The JSON Schema of each topic, as stored in the file."""
    found: dict[str, dict[str, Any]] = {}
    with open_recording(path) as stream:
        known: dict[int, Schema] = {}
        for record in TolerantScan(stream):
            if isinstance(record, Schema):
                known[record.id] = record
            elif isinstance(record, Channel) and record.schema_id in known:
                schema = known[record.schema_id]
                if schema.encoding == "jsonschema":
                    found[record.topic] = json.loads(schema.data)
    return found
