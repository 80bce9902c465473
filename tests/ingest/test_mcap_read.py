"""Reading a replay: the raw input of a recording, in file order, from any MCAP writer's file,
finished or cut short; a recorded raw message read as the json module reads it."""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from tdmon.errors import IngestError
from tdmon.ingest import mcap_source
from tdmon.ingest.mcap_source import iter_raw
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


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4,
                                         CompressionType.NONE])
def test_raw_input_is_read_in_file_order_however_the_file_is_written(
        tmp_path: Path, compression: CompressionType) -> None:
    chunked, flat, unindexed = (tmp_path / "chunked.mcap", tmp_path / "flat.mcap",
                                tmp_path / "unindexed.mcap")
    _write(chunked, chunking=True, compression=compression)
    _write(flat, chunking=False)
    _write(unindexed, chunking=True, index=False)
    with chunked.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 5

    read = _read(chunked)
    assert len(read) == 300
    # file order, not log-time order; each payload whole; only /tdmon/raw
    assert [json.loads(raw.payload)["value"] for _, raw in read] == [float(i) for i in
                                                                     range(300)]
    assert read[3][0] == T0 - 2 * 100_000_000  # message 3, received 0.5 s early
    assert {raw.source for _, raw in read} == {"mqtt"}
    assert read == _read(flat) == _read(unindexed)


def test_a_file_cut_short_is_read_up_to_the_cut(tmp_path: Path) -> None:
    path = tmp_path / "chunked.mcap"
    _write(path, chunking=True)
    data = path.read_bytes()
    with io.BytesIO(data[: len(data) // 2]) as stream:
        read = list(iter_raw(stream))
    assert 0 < len(read) < 300
    assert read == _read(path)[: len(read)]


def _library_raw(path: Path) -> list[tuple[int, RawMessage | None]]:
    """Every /tdmon/raw message in file order as (log time, RawMessage), by the mcap
    package's seeking reader (the summary's index: another way through the file)."""
    with path.open("rb") as stream:
        return [(message.log_time, mcap_source.raw_from_record(
                    mcap_source.RAW_TOPIC, message.data, message.log_time))
                for _, _, message in make_reader(stream).iter_messages(
                    topics=[mcap_source.RAW_TOPIC], log_time_order=False)]


def test_the_recorder_s_files_and_the_bundled_replays_are_read_whole(tmp_path: Path) -> None:
    # foxglove-sdk's writer (the recorder's), and every bundled replay
    from tdmon.record.mcap_recorder import McapRecorder

    path = tmp_path / "recorded.mcap"
    with McapRecorder(path=path, recover=False) as recorder:
        for i in range(5000):
            raw = RawMessage("mqtt", "rig/F4/hookload", b'{"t": %d, "value": 1}' % i, 1e9 + i)
            recorder.write(mcap_source.RAW_TOPIC, T0 + i * 10**9, raw_message(raw))
    read = _read(path)
    assert len(read) == 5000 and read == _library_raw(path)
    # tdmon's own records: their bytes kept, to be recorded again as they are
    assert all(raw.recorded is not None for _, raw in read)
    replays = sorted((Path(__file__).parents[2] / "replays").glob("*.mcap"))
    assert replays
    for replay in replays:
        assert _read(replay) == _library_raw(replay), replay


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


def _refuse(data: bytes) -> object:
    raise orjson.JSONDecodeError("refused", "", 0)


def _outcome(data: bytes, by_orjson: bool) -> object:
    """What raw_from_record makes of ``data``, read by orjson, or by the json module alone."""
    with pytest.MonkeyPatch.context() as patched:
        if not by_orjson:
            patched.setattr(mcap_source.orjson, "loads", _refuse)
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
def test_a_recorded_raw_message_is_what_the_json_module_reads(
        record: dict[str, object], drop: set[str], ascii_only: bool) -> None:
    for key in drop:
        record.pop(key)
    data = json.dumps(record, ensure_ascii=ascii_only).encode("utf-8", "surrogatepass")
    read, oracle = _outcome(data, by_orjson=True), _outcome(data, by_orjson=False)
    if isinstance(read, RawMessage) and isinstance(oracle, RawMessage):
        same_time = (read.receive_time == oracle.receive_time
                     or (math.isnan(read.receive_time) and math.isnan(oracle.receive_time)))
        assert (read.source, read.topic, read.payload) == (
            oracle.source, oracle.topic, oracle.payload) and same_time
        if read.recorded is not None:  # kept only when the bytes say what raw_message would
            assert read.recorded is data and json.loads(data) == raw_message(read)
    else:
        assert read == oracle


def test_a_recorded_raw_message_kept_in_part_or_damaged_is_refused() -> None:
    truncated = {"source": "mqtt", "topic": "rig/a", "receive_time": 12.5, "payload": "x",
                 "payload_encoding": "utf-8", "payload_truncated": True}
    with pytest.raises(mcap_source._Truncated):
        mcap_source.raw_from_record("/tdmon/raw", json.dumps(truncated).encode(), 0)
    with pytest.raises(IngestError, match="unreadable"):
        mcap_source.raw_from_record("/tdmon/raw", b'{"source": "mqtt", "payload": "x"}', 0)
