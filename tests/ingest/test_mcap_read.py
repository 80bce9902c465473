"""Reading a replay through its chunk index and record by record gives the same messages."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import msgspec
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from tdmon.errors import IngestError
from tdmon.ingest import mcap_source
from tdmon.ingest.mcap_source import _all_in_indexed_chunks, iter_raw
from tdmon.ingest.types import RawMessage, raw_message

T0 = 1_700_000_000_000_000_000


def _write(path: Path, *, chunking: bool, chunk_size: int = 2000, index: bool = True,
           compression: CompressionType = CompressionType.ZSTD) -> None:
    """Raw input (every third message from an earlier receive time: file order is not log
    time order) with a derived topic between, in small chunks so that there are several."""
    with path.open("wb") as stream:
        writer = Writer(stream, use_chunking=chunking, chunk_size=chunk_size,
                        compression=compression,
                        index_types=IndexType.ALL if index else IndexType.CHUNK)
        writer.start()
        schema = writer.register_schema("any", "jsonschema", b"{}")
        derived = writer.register_channel("/truth/hookload", "json", schema)
        raw = writer.register_channel("/tdmon/raw", "json", schema)
        for i in range(300):
            t_ns = T0 + (i - 5 * (i % 3 == 0)) * 100_000_000
            writer.add_message(derived, t_ns, b'{"value": 1.0}', t_ns)
            payload = json.dumps({"t": t_ns / 1e9, "value": float(i)}).encode()
            body = raw_message(RawMessage("mqtt", f"rig/F4/ch{i % 4}", payload, t_ns / 1e9))
            writer.add_message(raw, t_ns, json.dumps(body).encode(), t_ns)
        writer.finish()


def _read(path: Path) -> list[tuple[int, RawMessage]]:
    with path.open("rb") as stream:
        return list(iter_raw(stream))


def test_indexed_chunks_read_like_the_stream(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                             ) -> None:
    chunked, flat = tmp_path / "chunked.mcap", tmp_path / "flat.mcap"
    _write(chunked, chunking=True)
    _write(flat, chunking=False)
    with chunked.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 5
    assert _all_in_indexed_chunks(summary)

    read = _read(chunked)
    assert len(read) == 300
    # file order, not log-time order; each payload whole
    assert [json.loads(raw.payload)["value"] for _, raw in read] == [float(i) for i in
                                                                     range(300)]
    assert read[3][0] == T0 - 2 * 100_000_000  # message 3, received 0.5 s early
    assert read == _read(flat)

    # the same file read record by record, as a file without a summary is
    monkeypatch.setattr(mcap_source, "_summary", lambda stream: None)
    assert read == _read(chunked)


def test_messages_outside_the_index_are_read_record_by_record(tmp_path: Path) -> None:
    flat, unindexed = tmp_path / "flat.mcap", tmp_path / "unindexed.mcap"
    _write(flat, chunking=False)
    _write(unindexed, chunking=True, index=False)
    for path in (flat, unindexed):
        with path.open("rb") as stream:
            summary = make_reader(stream).get_summary()
        assert summary is not None and not _all_in_indexed_chunks(summary)
        assert len(_read(path)) == 300


def test_a_file_cut_short_is_read_up_to_the_cut(tmp_path: Path) -> None:
    path = tmp_path / "chunked.mcap"
    _write(path, chunking=True)
    data = path.read_bytes()
    with io.BytesIO(data[: len(data) // 2]) as stream:
        read = list(iter_raw(stream))
    assert 0 < len(read) < 300
    assert read == _read(path)[: len(read)]


def _library_messages(path: Path) -> list[tuple[int, int, bytes]]:
    """(channel id, log time, data) of every message, in file order, by the mcap package."""
    with path.open("rb") as stream:
        return [(message.channel_id, message.log_time, message.data)
                for _, _, message in make_reader(stream).iter_messages(log_time_order=False)]


def _own_messages(path: Path) -> list[tuple[int, int, bytes]]:
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
        assert summary is not None and _all_in_indexed_chunks(summary)
        stream.seek(0)
        return [item for item in mcap_source._indexed_messages(stream, summary)
                if isinstance(item, tuple)]


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4,
                                         CompressionType.NONE])
def test_the_chunk_reader_gives_the_library_s_messages(tmp_path: Path,
                                                       compression: CompressionType) -> None:
    # the struct-based reading of zstd and uncompressed chunks, and lz4 through the package
    path = tmp_path / "chunked.mcap"
    _write(path, chunking=True, compression=compression)
    own = _own_messages(path)
    assert len(own) == 600
    assert own == _library_messages(path)


def test_the_chunk_reader_reads_the_recorder_s_files(tmp_path: Path) -> None:
    # foxglove-sdk's writer (the recorder's), and every bundled replay
    from tdmon.record.mcap_recorder import McapRecorder

    path = tmp_path / "recorded.mcap"
    with McapRecorder(path=path, recover=False) as recorder:
        for i in range(5000):
            recorder.write("/tdmon/sample", T0 + i * 10**9,
                           {"channel": "hookload", "t": T0 / 1e9 + i, "value": 1e6 + i,
                            "unit": "N", "source": "mqtt", "topic": "rig/F4/hookload"})
    assert len(_own_messages(path)) == 5000
    assert _own_messages(path) == _library_messages(path)
    replays = sorted((Path(__file__).parents[2] / "replays").glob("*.mcap"))
    assert replays
    for replay in replays:
        assert _own_messages(replay) == _library_messages(replay), replay


def test_a_record_running_past_its_chunk_stops_the_reading_there() -> None:
    good = mcap_source._RECORD.pack(5, 22 + 3) + mcap_source._MESSAGE.pack(7, 0, 11, 11) + b"abc"
    # a second message whose length says more than the chunk holds
    bad = mcap_source._RECORD.pack(5, 500) + mcap_source._MESSAGE.pack(7, 1, 12, 12) + b"x"
    records = mcap_source._chunk_records(good + bad)
    assert next(records) == (7, 11, b"abc")
    with pytest.raises(McapError, match="past its end"):
        next(records)
    short = mcap_source._chunk_records(good + mcap_source._RECORD.pack(5, 4) + b"abcd")
    assert next(short) == (7, 11, b"abc")
    with pytest.raises(McapError, match="too short"):
        next(short)
    cut = mcap_source._chunk_records(good + bad[:5])  # not even a whole record header
    assert next(cut) == (7, 11, b"abc")
    with pytest.raises(McapError, match="cut short"):
        next(cut)


@pytest.mark.parametrize(("record", "expected"), [
    # tdmon's own record (the fast path)
    ({"source": "mqtt", "topic": "rig/a", "receive_time": 12.5, "payload": '{"v":1}',
      "payload_encoding": "utf-8"}, RawMessage("mqtt", "rig/a", b'{"v":1}', 12.5)),
    # another writer's: an integer time, no encoding, no source, no time, base64
    ({"source": "mqtt", "topic": "rig/a", "receive_time": 12, "payload": "x"},
     RawMessage("mqtt", "rig/a", b"x", 12.0)),
    ({"topic": "rig/a", "receive_time": 12.5, "payload": "x"},
     RawMessage("mcap", "rig/a", b"x", 12.5)),
    ({"source": "mqtt", "topic": "rig/a", "payload": "x"}, RawMessage("mqtt", "rig/a", b"x", 3.0)),
    ({"source": "mqtt", "topic": "rig/a", "receive_time": 12.5, "payload": "/w==",
      "payload_encoding": "base64"}, RawMessage("mqtt", "rig/a", b"\xff", 12.5)),
])
def test_a_recorded_raw_message_becomes_its_raw_message(record: dict[str, object],
                                                        expected: RawMessage) -> None:
    raw = mcap_source.raw_from_record("/tdmon/raw", json.dumps(record).encode(), 3 * 10**9)
    assert raw == expected and raw is not None and type(raw.receive_time) is float


@pytest.mark.parametrize(("data", "kept"), [
    # tdmon's own record, whatever its key order and spacing: the same JSON value
    (b'{"source":"mqtt","topic":"rig/a","receive_time":12.5,"payload":"{\\"v\\":1}",'
     b'"payload_encoding":"utf-8"}', True),
    (b'{"payload_encoding": "utf-8", "payload": "x", "receive_time": 12.5, "topic": "rig/a",'
     b' "source": "mqtt"}', True),
    # not what raw_message writes of the message it becomes: no encoding, no source, another
    # key, an integer time, base64, a NaN time only the json module reads
    (b'{"source":"mqtt","topic":"rig/a","receive_time":12.5,"payload":"x"}', False),
    (b'{"topic":"rig/a","receive_time":12.5,"payload":"x","payload_encoding":"utf-8"}', False),
    (b'{"source":"mqtt","topic":"rig/a","receive_time":12.5,"payload":"x",'
     b'"payload_encoding":"utf-8","note":"n"}', False),
    (b'{"source":"mqtt","topic":"rig/a","receive_time":12,"payload":"x",'
     b'"payload_encoding":"utf-8"}', False),
    (b'{"source":"mqtt","topic":"rig/a","receive_time":12.5,"payload":"eA==",'
     b'"payload_encoding":"base64"}', False),
    (b'{"source":"mqtt","topic":"rig/a","receive_time":NaN,"payload":"x",'
     b'"payload_encoding":"utf-8"}', False),
])
def test_a_recorded_raw_message_keeps_its_bytes_only_when_they_say_what_it_says(
        data: bytes, kept: bool) -> None:
    raw = mcap_source.raw_from_record("/tdmon/raw", data, 3 * 10**9)
    assert raw is not None
    if kept:
        assert raw.recorded is data
        assert json.loads(data) == raw_message(raw)
    else:
        assert raw.recorded is None
    # the bytes kept are no part of the message's value (a NaN time equals nothing)
    if not math.isnan(raw.receive_time):
        assert raw == RawMessage(raw.source, raw.topic, raw.payload, raw.receive_time)


def _refuse_usual(data: bytes) -> object:
    raise msgspec.DecodeError("refused")


def _outcome(data: bytes, usual: bool) -> object:
    """What raw_from_record makes of ``data``, with msgspec's quick path or without it."""
    with pytest.MonkeyPatch.context() as patched:
        if not usual:
            patched.setattr(mcap_source, "_read_usual", _refuse_usual)
        try:
            return mcap_source.raw_from_record("/tdmon/raw", data, 3 * 10**9)
        except (IngestError, mcap_source._Truncated) as exc:
            return type(exc)


record_values = (st.text(max_size=4) | st.floats() | st.integers(-2**70, 2**70) | st.none()
                 | st.booleans() | st.sampled_from(["utf-8", "base64", "\ud800", "eA=="]))
records = st.fixed_dictionaries(
    {"source": st.text(max_size=4) | record_values, "topic": st.text(max_size=4),
     "receive_time": st.floats() | st.integers(-10, 10**20) | record_values,
     "payload": st.text(max_size=6) | record_values,
     "payload_encoding": st.sampled_from(["utf-8", "base64", "UTF-8"]) | record_values},
    optional={"payload_truncated": st.booleans(), "note": record_values})


@settings(max_examples=800, deadline=None)
@given(record=records, drop=st.sets(st.sampled_from(
    ["source", "topic", "receive_time", "payload", "payload_encoding"]), max_size=2),
    ascii_only=st.booleans())
def test_msgspec_s_quick_path_makes_the_general_path_s_raw_message(
        record: dict[str, object], drop: set[str], ascii_only: bool) -> None:
    for key in drop:
        record.pop(key)
    data = json.dumps(record, ensure_ascii=ascii_only).encode("utf-8", "surrogatepass")
    quick, general = _outcome(data, usual=True), _outcome(data, usual=False)
    if isinstance(quick, RawMessage) and isinstance(general, RawMessage):
        same_time = (quick.receive_time == general.receive_time
                     or (math.isnan(quick.receive_time) and math.isnan(general.receive_time)))
        assert (quick.source, quick.topic, quick.payload) == (
            general.source, general.topic, general.payload) and same_time
        if quick.recorded is not None:  # kept only when the bytes say what raw_message would
            assert quick.recorded is data and json.loads(data) == raw_message(quick)
    else:
        assert quick == general


def test_a_recorded_raw_message_kept_in_part_or_damaged_is_refused() -> None:
    truncated = {"source": "mqtt", "topic": "rig/a", "receive_time": 12.5, "payload": "x",
                 "payload_encoding": "utf-8", "payload_truncated": True}
    with pytest.raises(mcap_source._Truncated):
        mcap_source.raw_from_record("/tdmon/raw", json.dumps(truncated).encode(), 0)
    with pytest.raises(IngestError, match="unreadable"):
        mcap_source.raw_from_record("/tdmon/raw", b'{"source": "mqtt", "payload": "x"}', 0)
