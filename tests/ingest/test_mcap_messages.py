"""tdmon.ingest.mcap_messages against the mcap package's own StreamReader, on real files."""

from __future__ import annotations

import io
import struct

import pytest
from mcap.exceptions import InvalidMagic, McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from tdmon.ingest.mcap_messages import iter_messages


def _file(compression: CompressionType, chunked: bool = True, chunk_size: int = 300) -> bytes:
    """Two channels, interleaved messages of varying size, several chunks."""
    out = io.BytesIO()
    writer = Writer(out, compression=compression, chunk_size=chunk_size, use_chunking=chunked)
    writer.start()
    schema = writer.register_schema("s", "jsonschema", b"{}")
    channels = [writer.register_channel("/tdmon/raw", "json", schema),
                writer.register_channel("rig/F4/hookload", "json", schema)]
    for i in range(60):
        data = b'{"i":%d,"pad":"%s"}' % (i, b"x" * (i % 7))
        writer.add_message(channels[i % 2], 1_000_000_000 + i, data, 1_000_000_000 + i,
                           sequence=i)
    writer.finish()
    return out.getvalue()


def _with_mcap(data: bytes) -> tuple[dict[int, str], list[tuple[int, int, bytes]]]:
    topics: dict[int, str] = {}
    messages = []
    try:
        for record in StreamReader(io.BytesIO(data)).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message):
                messages.append((record.channel_id, record.log_time, bytes(record.data)))
    except (McapError, struct.error):  # a cut file: what came before the cut
        pass
    return topics, messages


def _with_tdmon(data: bytes) -> tuple[dict[int, str], list[tuple[int, int, bytes]]]:
    topics: dict[int, str] = {}
    messages = list(iter_messages(io.BytesIO(data), topics.__setitem__))
    return topics, messages


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4,
                                         CompressionType.NONE])
@pytest.mark.parametrize("chunked", [True, False])
def test_same_messages_as_mcap(compression: CompressionType, chunked: bool) -> None:
    data = _file(compression, chunked)
    topics, messages = _with_tdmon(data)
    assert (topics, messages) == _with_mcap(data)
    assert len(messages) == 60
    assert sorted(topics.values()) == ["/tdmon/raw", "rig/F4/hookload"]
    assert messages[7][1] == 1_000_000_007 and messages[7][2] == b'{"i":7,"pad":""}'


def test_cut_file_ends_at_its_last_whole_record() -> None:
    data = _file(CompressionType.ZSTD)
    for cut in (9, 200, len(data) // 2, len(data) - 30):
        _, messages = _with_tdmon(data[:cut])
        _, expected = _with_mcap(data[:cut])
        assert messages == expected
    # half the file holds some of the chunks, not all
    assert 0 < len(_with_tdmon(data[:len(data) // 2])[1]) < 60


def test_not_mcap_raises_invalid_magic() -> None:
    with pytest.raises(InvalidMagic):
        list(iter_messages(io.BytesIO(b"time,hookload\n1,2\n"), lambda *_: None))
    assert list(iter_messages(io.BytesIO(b"\x89MC"), lambda *_: None)) == []
