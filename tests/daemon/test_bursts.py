"""Bursts: the ingest queue bounded in messages, sources handing lists over, the pipeline and
the recorder taking a burst's raw input and samples at once (docs/daemon.md, "Bursts")."""

from __future__ import annotations

import asyncio
import dataclasses
import json
import math
import pickle
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import orjson
import pytest
import zenoh
from daemon_support import CollectSink, linear_model
from mcap.writer import Writer

from tdmon.config.daemon import ZenohConfig
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.inbox import Inbox
from tdmon.daemon.pipeline import Pipeline, Sink, Step
from tdmon.daemon.steps.monitor import MonitorStep
from tdmon.daemon.steps.rig_state import RigStateStep
from tdmon.errors import IngestError
from tdmon.ingest import mcap_source
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.types import (
    RAW_ROW,
    RawMessage,
    Sample,
    raw_message,
    sample_message,
    samples_json,
)
from tdmon.ingest.zenoh_io import ZenohSource, key_expr_for, open_session
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import read_messages


def raw(i: int, topic: str = "rig/hookload") -> RawMessage:
    return RawMessage("mqtt", topic, str(i).encode(), float(i))


# -- the ingest queue ---------------------------------------------------------------------------


async def test_the_inbox_counts_messages_keeps_order_and_ends() -> None:
    inbox = Inbox(limit=5)
    inbox.put_nowait(raw(0))
    await inbox.put_many([raw(1), raw(2), raw(3)])
    assert len(inbox) == 4 and not inbox.full()
    await inbox.put_many([raw(4), raw(5), raw(6)])  # room for one: the list goes in whole
    assert len(inbox) == 7 and inbox.full()

    blocked = asyncio.create_task(inbox.put(raw(7)))
    await asyncio.sleep(0.01)
    assert not blocked.done()  # full: the source waits
    first = await inbox.take(2)
    assert [int(m.payload) for m in first] == [0, 1, 2, 3]  # a list is taken whole
    await asyncio.sleep(0)  # 3 queued now, under the limit: the waiting put goes in
    assert blocked.done() and len(inbox) == 4
    inbox.end()
    rest = await inbox.take(100)
    assert rest is not None and [int(m.payload) for m in rest] == [4, 5, 6, 7]
    assert await inbox.take(100) is None and inbox.empty()


async def test_the_inbox_wakes_a_waiting_consumer() -> None:
    inbox = Inbox(limit=10)
    waiting = asyncio.create_task(inbox.take(10))
    await asyncio.sleep(0.01)
    assert not waiting.done()
    await inbox.put_many([raw(1), raw(2)])
    assert [int(m.payload) for m in await waiting] == [1, 2]
    with pytest.raises(ValueError, match="at least 1"):
        Inbox(0)


# -- the pipeline ---------------------------------------------------------------------------------


class ManySink(CollectSink):
    """A sink taking bursts: remembers each write_many call."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[tuple[str, int]] = []

    def write_many(self, topic: str, log_times_ns: list[int],
                   messages: list[dict[str, Any]]) -> None:
        self.calls.append((topic, len(messages)))
        for log_time_ns, message in zip(log_times_ns, messages, strict=True):
            self.write(topic, log_time_ns, message)


def _pipeline(sinks: list[Sink]) -> Pipeline:
    steps: list[Step] = [RigStateStep(), MonitorStep(linear_model())]
    decoder = Decoder("rig", [ChannelSpec("hookload", "hookload", "N"),
                              ChannelSpec("bit_depth", "bit_depth", "m")])
    return Pipeline(decoder, Aligner(wait_for=("bit_depth",)), steps, sinks)


def _rig_messages() -> list[RawMessage]:
    messages = []
    for i in range(30):
        for channel, value in (("bit_depth", 1000.0 + i), ("hookload", 1e6 + 1e3 * i)):
            body = json.dumps({"t": float(i), "value": value}).encode()
            messages.append(RawMessage("mqtt", f"rig/{channel}", body, 100.0 + i))
        if i % 11 == 5:
            messages.append(RawMessage("mqtt", "rig/hookload", b"not json", 100.0 + i))
        if i % 13 == 7:  # a duplicate sample: counted by the aligner
            messages.append(messages[-1])
    return messages


def _one_by_one_and_in_bursts(bursts: list[list[RawMessage]], sinks: list[Sink]
                              ) -> tuple[Pipeline, Pipeline, CollectSink]:
    """The messages through one pipeline one by one (recorded by the sink returned) and
    through another burst by burst into ``sinks``; both flushed. Each sink got what the
    one-by-one sink got, topic for topic."""
    alone = CollectSink()
    single = _pipeline([alone])
    for burst in bursts:
        for message in burst:
            single.process(message)
    batched = _pipeline(sinks)
    for burst in bursts:
        batched.process_burst(burst)
    for pipeline in (single, batched):
        pipeline.flush()
    for topic in ("raw", "sample", "rejected", "state", "model"):
        assert alone[topic], topic
        for sink in sinks:
            assert sink[topic] == alone[topic], (sink, topic)  # type: ignore[index]
    return single, batched, alone


def test_a_burst_records_and_computes_what_one_by_one_does() -> None:
    messages = _rig_messages()
    bursts = [messages[k:k + 7] for k in range(0, len(messages), 7)]
    single, batched, _ = _one_by_one_and_in_bursts(bursts, [ManySink(), together := ManySink()])
    for name in ("messages_in", "samples_in", "rejected", "frames", "duplicates"):
        assert getattr(batched.stats, name) == getattr(single.stats, name), name
    assert batched.stats.samples_in == 62 and batched.stats.rejected == 3
    assert batched.stats.duplicates == 2
    # one call per burst and topic: a burst's raw input before anything else of it, its
    # samples after everything else
    raw_calls = [n for topic, n in together.calls if topic == "/tdmon/raw"]
    assert raw_calls == [len(burst) for burst in bursts]
    segments: list[list[str]] = []
    for topic in together.order:
        if topic == "/tdmon/raw" and (not segments or segments[-1][-1] != "/tdmon/raw"):
            segments.append([])
        segments[-1].append(topic)
    assert [segment.count("/tdmon/raw") for segment in segments] == raw_calls
    for segment in segments:
        first_sample = segment.index("/tdmon/sample")
        assert set(segment[first_sample:]) == {"/tdmon/sample"}


class RowsSink(CollectSink):
    """A sink taking a burst as rows, as the recorder in a child process does: it makes the
    messages itself, with ``make`` sent by name as to another process."""

    def __init__(self) -> None:
        super().__init__()
        self.row_calls: list[tuple[str, int]] = []

    def write_rows(self, topic: str, log_times_ns: list[int],
                   make: Callable[[Any], dict[str, Any]], rows: list[tuple[Any, ...]]) -> None:
        assert all(type(row) is tuple for row in rows)
        make = pickle.loads(pickle.dumps(make))
        self.row_calls.append((topic, len(rows)))
        for log_time_ns, row in zip(log_times_ns, rows, strict=True):
            self.write(topic, log_time_ns, make(row))


def test_a_sink_taking_rows_gets_the_messages_the_others_get() -> None:
    messages = _rig_messages()
    # a payload longer than the recorded limit: its raw message is cut (bounded_payload)
    messages.insert(9, RawMessage("mqtt", "rig/hookload", b'{"t": 4.5, "value": 1}' + b" " * 5000,
                                  104.5))
    rows = RowsSink()
    _one_by_one_and_in_bursts([messages[k:k + 7] for k in range(0, len(messages), 7)],
                              [rows, ManySink()])
    assert any(m.get("payload_truncated") for m in rows["raw"])
    assert {topic for topic, _ in rows.row_calls} == {"/tdmon/raw", "/tdmon/sample"}
    assert sum(n for topic, n in rows.row_calls if topic == "/tdmon/raw") == len(messages)


class EncodedSink(ManySink):
    """A sink taking messages already JSON, as the in-process recorder does."""

    def __init__(self) -> None:
        super().__init__()
        self.encoded_calls: list[tuple[str, int]] = []

    def write_encoded_many(self, topic: str, log_times_ns: list[int],
                           datas: list[bytes]) -> None:
        self.encoded_calls.append((topic, len(datas)))
        for log_time_ns, data in zip(log_times_ns, datas, strict=True):
            self.write(topic, log_time_ns, json.loads(data))


def _as_recorded(messages: list[RawMessage]) -> list[RawMessage]:
    """The messages as a replay of their recording reads them: with their bytes."""
    return [mcap_source.raw_from_record("/tdmon/raw", orjson.dumps(raw_message(raw)), 0)
            for raw in messages]  # type: ignore[misc]


def test_a_replay_s_raw_input_is_recorded_as_its_recording_held_it() -> None:
    messages = _as_recorded(_rig_messages())
    assert all(raw.recorded is not None for raw in messages)
    bursts = [messages[k:k + 7] for k in range(0, len(messages), 7)]
    # one burst with a message that has no bytes (as live input), one with a payload
    # longer than the pipeline keeps whole: both made into messages as usual
    bursts[1][3] = RawMessage(*RAW_ROW(bursts[1][3]))
    payload = b'{"t": 4.5, "value": 1}' + b" " * 5000
    whole = {"source": "mqtt", "topic": "rig/hookload", "receive_time": 104.5,
             "payload": payload.decode(), "payload_encoding": "utf-8"}
    bursts[2].insert(2, RawMessage("mqtt", "rig/hookload", payload, 104.5,
                                   recorded=orjson.dumps(whole)))
    encoded = EncodedSink()
    _one_by_one_and_in_bursts(bursts, [encoded, RowsSink()])
    assert any(m.get("payload_truncated") for m in encoded["raw"])
    assert [call for call in encoded.encoded_calls if call[0] == "/tdmon/raw"] == [
        ("/tdmon/raw", len(burst)) for i, burst in enumerate(bursts) if i not in (1, 2)]
    assert [n for topic, n in encoded.calls if topic == "/tdmon/raw"] == [7, 8]
    # the samples as JSON bytes too (live input as well): every burst's that has one
    assert sum(n for topic, n in encoded.encoded_calls if topic == "/tdmon/sample") == len(
        encoded["sample"])
    assert not [n for topic, n in encoded.calls if topic == "/tdmon/sample"]


@pytest.mark.parametrize("sample", [
    Sample("hookload", 1.7e9, 1.2e6, "mqtt", "rig/F4/hookload", "N", 1.7e9 + 0.2),
    Sample("torque", 1714521600.125, -0.0, "zenoh", 'rig/"F4"/tq\\ü🙂', "N*m", 0.0, 7),
    Sample("bit_depth", 0.0, 1e16, "mcap", "rig/bit", "m", 1.0),
    Sample("flow_in", 7e9, 5e-324, "wits0", "rig/flow", "m**3/s", 1.0),
    Sample("spp", 1.5, 123456789.98765432, "mqtt", "", "Pa", 1.0),
])
def test_samples_json_writes_the_bytes_orjson_writes_of_the_messages(sample: Sample) -> None:
    other = dataclasses.replace(sample, t=sample.t + 1.0, value=-sample.value)
    assert samples_json([sample, other, sample]) == [
        orjson.dumps(sample_message(s)) for s in (sample, other, sample)]


def test_samples_json_leaves_a_non_finite_number_to_the_recorder() -> None:
    good = Sample("hookload", 1.7e9, 1.2e6, "mqtt", "rig/F4/hookload", "N", 1.7e9)
    for bad in (dataclasses.replace(good, value=math.nan), dataclasses.replace(good, t=math.inf)):
        assert samples_json([good, bad]) is None


def test_a_sink_failing_a_burst_is_counted_and_the_others_get_it() -> None:
    class Broken(ManySink):
        def write_many(self, topic: str, log_times_ns: list[int],
                       messages: list[dict[str, Any]]) -> None:
            raise RuntimeError("bug in a sink")

    good = CollectSink()
    pipeline = _pipeline([Broken(), good])
    messages = _rig_messages()
    pipeline.process_burst(messages)
    assert len(good["raw"]) == len(messages) and len(good["sample"]) == 62
    assert pipeline.stats.sink_errors == 2  # the raw and the sample burst


# -- the recorder ---------------------------------------------------------------------------


def test_write_many_records_what_write_does(tmp_path: Path) -> None:
    messages = [{"channel": "hookload", "t": 1.0 + i, "value": 1e6 + i, "unit": "N",
                 "source": "mqtt", "topic": "rig/hookload"} for i in range(700)]
    times = [1_700_000_000_000_000_000 + i * 10**9 for i in range(700)]
    with McapRecorder(tmp_path / "one", recover=False) as one:
        for log_time_ns, message in zip(times, messages, strict=True):
            one.write("/tdmon/sample", log_time_ns, message)
    with McapRecorder(tmp_path / "many", recover=False) as many:
        many.write_many("/tdmon/sample", times[:300], messages[:300])
        many.write("/tdmon/alarm", times[300], {"t": 1.0, "kind": "k", "severity": "info",
                                                "message": "m", "value": math.nan})
        # a short list goes through the queue, a long one straight to the file: same order
        many.write_many("/tdmon/sample", times[300:310], messages[300:310])
        many.write_many("/tdmon/sample", times[310:], messages[310:])
        with pytest.raises(ValueError, match="2 log times for 1 messages"):
            many.write_many("/tdmon/sample", times[:2], messages[:1])
    [path_one] = one.stats.files
    [path_many] = many.stats.files
    back_one = list(read_messages(path_one))
    back_many = [m for m in read_messages(path_many) if m.topic == "/tdmon/sample"]
    assert [(m.log_time_ns, m.message) for m in back_many] == [
        (m.log_time_ns, m.message) for m in back_one]
    assert back_many[0].message == messages[0] and len(back_many) == 700
    assert many.stats.per_topic == {"/tdmon/sample": 700, "/tdmon/alarm": 1}
    assert many.stats.nonfinite_replaced == 1 and many.stats.lost == 0


def test_write_encoded_many_records_the_bytes_given(tmp_path: Path) -> None:
    messages = [{"source": "mqtt", "topic": "rig/hookload", "receive_time": 1.0 + i,
                 "payload": f'{{"t":{i}}}', "payload_encoding": "utf-8"} for i in range(300)]
    datas = [orjson.dumps(message) for message in messages]
    times = [1_700_000_000_000_000_000 + i * 10**9 for i in range(300)]
    with McapRecorder(tmp_path, recover=False) as recorder:
        recorder.write_many("/tdmon/raw", times[:5], messages[:5])
        recorder.write_encoded_many("/tdmon/raw", times[5:20], datas[5:20])  # queued
        recorder.write_encoded_many("/tdmon/raw", times[20:], datas[20:])  # straight on
        with pytest.raises(ValueError, match="2 log times for 1 messages"):
            recorder.write_encoded_many("/tdmon/raw", times[:2], datas[:1])
    [path] = recorder.stats.files
    back = list(read_messages(path))
    assert [(m.log_time_ns, m.message) for m in back] == list(zip(times, messages, strict=True))
    assert recorder.stats.per_topic == {"/tdmon/raw": 300} and recorder.stats.lost == 0
    assert recorder.stats.nonfinite_replaced == 0


def test_a_message_that_is_not_json_leaves_its_list_s_others_recorded(tmp_path: Path) -> None:
    messages: list[dict[str, Any]] = [{"t": float(i), "value": float(i)} for i in range(40)]
    messages[13] = {"t": 13.0, "value": {1, 2}}  # a set: neither orjson nor json writes it
    with McapRecorder(tmp_path, recover=False) as recorder:
        recorder.write_many("/tdmon/sample", list(range(40)), messages)
    assert recorder.stats.unencodable == 1 and recorder.stats.lost == 1
    assert recorder.stats.per_topic == {"/tdmon/sample": 39}
    [path] = recorder.stats.files
    back = list(read_messages(path))
    assert [m.log_time_ns for m in back] == [i for i in range(40) if i != 13]
    assert [m.message for m in back] == [m for i, m in enumerate(messages) if i != 13]


# -- sources handing lists over -------------------------------------------------------------


def _recording(path: Path, n: int, damaged_at: int | None = None) -> None:
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("any", "jsonschema", b"{}")
        channel = writer.register_channel("/tdmon/raw", "json", schema)
        for i in range(n):
            data = (b"{damaged" if i == damaged_at else
                    json.dumps(raw_message(raw(i))).encode())
            writer.add_message(channel, 10**9 * (i + 1), data, 10**9 * (i + 1))
        writer.finish()


async def test_the_recording_is_handed_over_in_lists(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    _recording(path, 600)
    async with McapSource(path, batch=256) as source:
        batches = [batch async for batch in source.batches()]
    assert [len(batch) for batch in batches] == [256, 256, 88]
    assert [int(m.payload) for batch in batches for m in batch] == list(range(600))


async def test_what_came_before_an_unreadable_record_is_handed_over(tmp_path: Path) -> None:
    path = tmp_path / "rec.mcap"
    _recording(path, 600, damaged_at=300)
    got: list[int] = []
    with pytest.raises(IngestError, match="unreadable"):
        async with McapSource(path, batch=256) as source:
            async for batch in source.batches():
                got += [int(m.payload) for m in batch]
    assert got == list(range(300))


async def test_zenoh_hands_over_what_waits_in_lists(free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    session = open_session(ZenohConfig(listen=[f"tcp/127.0.0.1:{port}"]))
    rig = open_session(ZenohConfig(connect=[f"tcp/127.0.0.1:{port}"]))
    n = 1000
    try:
        async with ZenohSource(session, key_expr_for("rig/B"), ("rig/B/tdmon/",)) as source:
            # the source's subscription has reached the rig (was: a 0.3 s pause)
            probe = rig.declare_publisher("rig/B/hookload")
            deadline = time.monotonic() + 60
            while not probe.matching_status.matching:
                assert time.monotonic() < deadline, "the subscription never reached the rig"
                await asyncio.sleep(0.02)
            probe.undeclare()
            block = zenoh.CongestionControl.BLOCK
            rig.put("rig/B/tdmon/model", b"{}", congestion_control=block)  # ignored
            for i in range(n):
                rig.put("rig/B/hookload", str(i).encode(), congestion_control=block)
            sizes: list[int] = []
            received: list[int] = []
            async for batch in source.batches():
                sizes.append(len(batch))
                received += [int(m.payload) for m in batch]
                if len(received) >= n:
                    break
        assert received == list(range(n))
        assert max(sizes) <= 256 and max(sizes) > 1  # what waited came in lists
        assert all(m.topic == "rig/B/hookload" for m in batch)
    finally:
        rig.close()
        session.close()


def test_the_batch_search_for_nan_finds_every_one(tmp_path: Path) -> None:
    """NaN and None are both written as null; a message is counted when a NaN made one, at
    any place in a batch, and not for a None or the word inside a string."""
    nan_at = {0, 17, 255, 256, 299}
    messages: list[dict[str, Any]] = []
    for i in range(300):
        message: dict[str, Any] = {"t": float(i), "kind": "k", "severity": "info",
                                   "message": "nullable" if i % 7 == 0 else "m"}
        if i in nan_at:
            message["value"] = math.nan
        if i in {5, 17, 100, 298}:
            message["extra"] = None
        messages.append(message)
    with McapRecorder(tmp_path, recover=False) as recorder:
        recorder.write_many("/tdmon/alarm", list(range(300)), messages)
    assert recorder.stats.nonfinite_replaced == len(nan_at)
    [path] = recorder.stats.files
    back = [m.message for m in read_messages(path)]
    assert [i for i, m in enumerate(back) if m.get("value", 0) is None] == sorted(nan_at)
