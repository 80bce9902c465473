"""The sink contract: a batch's forms (messages, JSON bytes, rows), each made once and shared;
its JSON (compact, NaN/inf as null and counted, numpy values as numbers); a batch pickled as
its rows; the sink base classes and the TestingSink."""

from __future__ import annotations

import json
import math
import pickle
from functools import partial
from typing import Any

import numpy as np
import orjson
import pytest

from tdmon.ingest.types import (
    SAMPLE_ITEMS,
    RawMessage,
    Sample,
    raw_items,
    raw_message,
    sample_message,
)
from tdmon.record.batch import MESSAGES, Batch, Items, encode_message
from tdmon.record.sink import MessageSink, Sink, TestingSink


class Counted:
    """An item kind that counts how often each form is made."""

    def __init__(self) -> None:
        self.made = {"message": 0, "row": 0}
        self.items = Items(message=self.message, row=self.row,
                           from_row=partial(dict, kind="from row"))

    def message(self, item: int) -> dict[str, Any]:
        self.made["message"] += 1
        return {"i": item}

    def row(self, item: int) -> tuple[tuple[str, int]]:
        self.made["row"] += 1
        return (("i", item),)


def test_each_form_is_made_once_on_first_demand() -> None:
    counted = Counted()
    batch = Batch("/tdmon/x", [10, 20, 30], [1, 2, 3], counted.items)
    assert counted.made == {"message": 0, "row": 0} and len(batch) == 3
    assert batch.messages() == [{"i": 1}, {"i": 2}, {"i": 3}]
    assert batch.encoded().datas == [b'{"i":1}', b'{"i":2}', b'{"i":3}']
    assert batch.rows() == [(("i", 1),), (("i", 2),), (("i", 3),)]
    for _ in range(3):  # as by three sinks
        batch.messages(), batch.encoded(), batch.rows()
    assert counted.made == {"message": 3, "row": 3}
    assert batch.encoded() is batch.encoded()
    assert batch.encoded().log_times_ns == [10, 20, 30]


def test_a_batch_is_pickled_as_its_rows_and_makes_its_messages_from_them() -> None:
    counted = Counted()
    batch = Batch("/tdmon/x", [10, 20], [1, 2], counted.items)
    copy = pickle.loads(pickle.dumps(batch, protocol=pickle.HIGHEST_PROTOCOL))
    assert counted.made == {"message": 0, "row": 2}  # no message made on this side
    assert (copy.topic, list(copy.log_times_ns)) == ("/tdmon/x", [10, 20])
    assert copy.items == [(("i", 1),), (("i", 2),)]
    assert copy.messages() == [{"i": 1, "kind": "from row"}, {"i": 2, "kind": "from row"}]
    # messages without rows of their own are their own rows
    plain = pickle.loads(pickle.dumps(Batch.one("/tdmon/y", 5, {"a": [1.5]})))
    assert plain.kind is MESSAGES and list(plain.messages()) == [{"a": [1.5]}]


def test_raw_and_sample_items_make_the_daemon_s_messages() -> None:
    raws = [RawMessage("mqtt", "rig/hookload", b'{"t":1,"value":2}', 1.5),
            RawMessage("zenoh", "rig/torque", b"\xff\xfe", 2.5),
            RawMessage("mqtt", "rig/hookload", b"x" * 100, 3.5)]
    batch = Batch("/tdmon/raw", [1, 2, 3], raws, raw_items(max_bytes=64))
    assert batch.messages() == [raw_message(raw, 64) for raw in raws]
    assert batch.messages()[2]["payload_truncated"] is True  # bounded to 64 bytes
    copy = pickle.loads(pickle.dumps(batch))
    assert all(type(row) is tuple for row in copy.items)
    assert copy.messages() == batch.messages()
    assert batch.encoded().datas == [orjson.dumps(m) for m in batch.messages()]
    samples = [Sample("hookload", 1.7e9, 1.2e6, "mqtt", "rig/F4/hookload", "N", 1.7e9 + 0.2),
               Sample("torque", 1714521600.125, -0.0, "zenoh", 'rig/"F4"/tq\\ü🙂', "N*m", 0.0, 7)]
    batch = Batch("/tdmon/sample", [1, 2], samples, SAMPLE_ITEMS)
    assert batch.messages() == [sample_message(s) for s in samples]
    assert pickle.loads(pickle.dumps(batch)).messages() == batch.messages()
    assert batch.encoded().datas == [orjson.dumps(sample_message(s)) for s in samples]


def test_a_replayed_recording_s_bytes_are_the_encoded_form() -> None:
    recorded = orjson.dumps(raw_message(RawMessage("mqtt", "rig/a", b"{}", 1.0)))
    held = RawMessage("mqtt", "rig/a", b"{}", 1.0, recorded=recorded)
    batch = Batch("/tdmon/raw", [1, 2], [held, held], raw_items())
    assert all(data is recorded for data in batch.encoded().datas)
    # one without its bytes (live input), or with a payload too long to keep whole: encoded
    live = RawMessage("mqtt", "rig/a", b"{}", 1.0)
    long = RawMessage("mqtt", "rig/a", b"y" * 100, 1.0,
                      recorded=orjson.dumps(raw_message(RawMessage("mqtt", "rig/a", b"y" * 100,
                                                                   1.0), 1000)))
    for other in (live, long):
        datas = Batch("/tdmon/raw", [1, 2], [held, other], raw_items(64)).encoded().datas
        assert datas[0] is not recorded and datas[0] == recorded
        assert json.loads(datas[1]) == raw_message(other, 64)


def test_a_model_message_round_trips_through_the_json_module() -> None:
    message = {"t": 1.7e9 + 0.125, "bit_depth": 2450.25, "alarms": [], "state": "pick_up",
               "band": {"mu": [0.1, 0.2], "hookload": [1.1e6, 1.2e6]}, "residual": None,
               "count": 3, "ok": True}
    encoded = Batch.one("/tdmon/model", 1, message).encoded()
    assert json.loads(encoded.datas[0]) == message and encoded.nonfinite == 0
    assert b" " not in encoded.datas[0].replace(b"pick_up", b"")  # compact separators


def test_non_finite_numbers_become_null_and_are_counted() -> None:
    messages = [{"a": math.nan, "b": [1.0, math.inf], "c": {"d": -math.inf}},
                {"a": None, "text": "null"},  # a null, and the word, but nothing replaced
                {"a": [2.0, -math.inf]}]
    encoded = Batch("/tdmon/x", [1, 2, 3], messages).encoded()
    # the json module's strict parse refuses NaN/Infinity tokens
    back = [json.loads(data, parse_constant=lambda name: pytest.fail(name))
            for data in encoded.datas]
    assert back == [{"a": None, "b": [1.0, None], "c": {"d": None}}, messages[1],
                    {"a": [2.0, None]}]
    assert encoded.nonfinite == 2 and not encoded.refused


def test_numpy_values_are_written_as_their_numbers() -> None:
    data, replaced = encode_message({"x": np.float64(1.5), "y": np.float32(0.25),
                                     "z": np.arange(3), "n": np.int64(7)})
    assert json.loads(data) == {"x": 1.5, "y": 0.25, "z": [0, 1, 2], "n": 7} and not replaced
    assert encode_message({"x": np.array([1.0, np.nan])})[1]


def test_what_orjson_refuses_goes_through_the_json_module_with_the_same_rules() -> None:
    # an integer beyond 64 bits and a non-string key: orjson refuses both
    message = {"big": 2**70, 3: "three", "nan": math.nan}
    encoded = Batch("/tdmon/x", [1, 2], [{"t": 1.0}, message]).encoded()
    assert [json.loads(data) for data in encoded.datas] == [
        {"t": 1.0}, {"big": 2**70, "3": "three", "nan": None}]
    assert encoded.nonfinite == 1


def test_a_message_that_is_not_json_is_left_out_with_why() -> None:
    messages = [{"t": 1.0}, {"x": object()}, {"t": 3.0, "v": math.nan}]
    encoded = Batch("/tdmon/x", [1, 2, 3], messages).encoded()
    assert encoded.datas == [b'{"t":1.0}', b'{"t":3.0,"v":null}']
    assert list(encoded.log_times_ns) == [1, 3] and encoded.nonfinite == 1
    [why] = encoded.refused
    assert why.startswith("a message on /tdmon/x is not JSON") and "object" in why
    # an item that makes no message is left out the same way
    broken = Items(message=lambda item: {"v": 1 / item})
    encoded = Batch("/tdmon/x", [1, 2], [1, 0], broken).encoded()
    assert encoded.datas == [b'{"v":1.0}'] and "division by zero" in encoded.refused[0]


class Probe(MessageSink):
    topics = frozenset({"/tdmon/state"})

    def __init__(self) -> None:
        self.got: list[tuple[str, int, dict[str, Any]]] = []

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        self.got.append((topic, log_time_ns, message))


def test_a_simple_sink_takes_a_batch_one_message_at_a_time() -> None:
    probe = Probe()
    probe.write_batch(Batch("/tdmon/state", [1, 2], [{"n": 1}, {"n": 2}]))
    assert probe.got == [("/tdmon/state", 1, {"n": 1}), ("/tdmon/state", 2, {"n": 2})]
    probe.close()  # nothing to release: the base's close
    with pytest.raises(TypeError, match="abstract"):
        MessageSink()  # type: ignore[abstract]


def test_the_testing_sink_keeps_what_it_is_given() -> None:
    sink = TestingSink(topics={"/tdmon/a", "/tdmon/b"})
    assert isinstance(sink, Sink) and "/tdmon/b" in sink.topics  # type: ignore[operator]
    sink.write("/tdmon/a", 5, {"x": 1})  # one message: a batch of one
    sink.write_batch(Batch("/tdmon/b", [6, 7], [{"y": 1}, {"y": 2}]))
    assert sink.items == [("/tdmon/a", 5, {"x": 1}), ("/tdmon/b", 6, {"y": 1}),
                          ("/tdmon/b", 7, {"y": 2})]
    assert sink.of("/tdmon/b") == [{"y": 1}, {"y": 2}] and sink.batches == 2
    sink.close()
    assert sink.closed
