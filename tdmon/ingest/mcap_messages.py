"""The messages of an MCAP file in file order, read without a record object per message.

The ``mcap`` package's ``StreamReader`` reads every field through a stream object and builds a
``Message`` record per message: about 8 us per message, a quarter of a full-speed replay
(docs/benchmarks.md, issue 15). A replay needs only each message's channel, log time and data,
so this reader takes whole records with one ``read`` each, decompresses a chunk at once and
cuts its messages out of the decompressed bytes with ``struct``: about 1 us per message.

It follows ``StreamReader``'s behaviour on what a replay can meet: records of unknown kinds
are skipped; the file ends at the footer; a file cut short (a writer that was killed) ends at
its last whole record, quietly; a file not starting with the MCAP magic raises
``InvalidMagic``; a chunk compressed otherwise than with zstd, lz4 or not at all raises
``UnsupportedCompressionError`` (both from ``mcap.exceptions``). CRCs are not checked, as
``StreamReader`` does not by default.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from typing import IO

from mcap.exceptions import InvalidMagic, UnsupportedCompressionError

__all__ = ["MAGIC", "iter_messages"]

MAGIC = b"\x89MCAP0\r\n"

_HEADER = struct.Struct("<BQ")  # opcode, content length [bytes]
_CHANNEL_HEAD = struct.Struct("<HHI")  # channel id, schema id, topic length
_MESSAGE_HEAD = struct.Struct("<HIQ")  # channel id, sequence, log time [ns]
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression length
_MESSAGE_DATA = 2 + 4 + 8 + 8  # a message's fields before its data [bytes]

_CHANNEL, _MESSAGE, _CHUNK, _FOOTER = 0x04, 0x05, 0x06, 0x02

#: Longest record read (the mcap package's default limit): a longer length is a damaged file.
_RECORD_LIMIT = 4 * 2**30


def iter_messages(
    stream: IO[bytes], on_channel: Callable[[int, str], None],
) -> Iterator[tuple[int, int, bytes]]:
    """``(channel id, log time [ns], data)`` of every message, in file order.

    ``on_channel(id, topic)`` is called for each channel record as it comes (a channel's record
    comes before its first message), so a caller knows the topics before their messages.
    """
    magic = stream.read(len(MAGIC))
    if len(magic) < len(MAGIC):
        return  # shorter than the magic: nothing to read (as StreamReader ends there)
    if magic != MAGIC:
        raise InvalidMagic(tuple(magic))
    read, header = stream.read, _HEADER
    while True:
        head = read(9)
        if len(head) < 9:
            return  # cut short
        opcode, length = header.unpack(head)
        if length > _RECORD_LIMIT:
            return
        content = read(length)
        if len(content) < length:
            return  # cut short inside the record
        if opcode == _MESSAGE:
            channel_id, _, log_time = _MESSAGE_HEAD.unpack_from(content)
            yield channel_id, log_time, content[_MESSAGE_DATA:]
        elif opcode == _CHUNK:
            yield from _chunk_messages(_decompress(content), on_channel)
        elif opcode == _CHANNEL:
            _channel(content, 0, on_channel)
        elif opcode == _FOOTER:
            return


def _chunk_messages(
    data: bytes, on_channel: Callable[[int, str], None],
) -> Iterator[tuple[int, int, bytes]]:
    """The messages of one decompressed chunk (channel records go to ``on_channel``)."""
    header, message_head = _HEADER.unpack_from, _MESSAGE_HEAD.unpack_from
    position, end = 0, len(data)
    while position + 9 <= end:
        opcode, length = header(data, position)
        start = position + 9
        position = start + length
        if position > end:
            return  # a record longer than its chunk: damaged
        if opcode == _MESSAGE:
            channel_id, _, log_time = message_head(data, start)
            yield channel_id, log_time, data[start + _MESSAGE_DATA:position]
        elif opcode == _CHANNEL:
            _channel(data, start, on_channel)


def _channel(data: bytes, start: int, on_channel: Callable[[int, str], None]) -> None:
    channel_id, _, topic_length = _CHANNEL_HEAD.unpack_from(data, start)
    topic_start = start + _CHANNEL_HEAD.size
    on_channel(channel_id, str(data[topic_start:topic_start + topic_length], "utf-8"))


def _decompress(content: bytes) -> bytes:
    """The records of a chunk record's content, decompressed."""
    _, _, size, _, name_length = _CHUNK_HEAD.unpack_from(content)
    name_start = _CHUNK_HEAD.size
    compression = str(content[name_start:name_start + name_length], "utf-8")
    (records_length,) = struct.unpack_from("<Q", content, name_start + name_length)
    records_start = name_start + name_length + 8
    records = content[records_start:records_start + records_length]
    if compression == "zstd":
        import zstandard  # a dependency of mcap, as lz4

        return zstandard.decompress(records, size)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(records)
    if compression == "":
        return records
    raise UnsupportedCompressionError(compression)
