"""The MCAP recorder: round trip, schemas, rotation, restart, numbers that are not JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from tdmon.errors import RecordError
from tdmon.record import schemas
from tdmon.record.mcap_recorder import FILE_PATTERN, McapRecorder
from tdmon.record.reader import (
    RecordedMessage,
    is_finished,
    read_messages,
    schemas_of,
    topic_counts,
)

TRUTH_SCHEMA: dict[str, Any] = {
    "$schema": schemas.DRAFT,
    "type": "object",
    "properties": {"t": {"type": "number"}, "mu": {"type": "number"}},
    "required": ["t", "mu"],
}


def _record(folder: Path, messages: list[RecordedMessage], **options: Any) -> McapRecorder:
    with McapRecorder(folder, extra_topics={"/truth/mu": TRUTH_SCHEMA}, **options) as recorder:
        for topic, log_time_ns, message in messages:
            recorder.write(topic, log_time_ns, message)
        recorder.write("/truth/mu", messages[0].log_time_ns, {"t": 1.0, "mu": 0.25})
    return recorder


def test_round_trip_every_topic(tmp_path: Path, stream: list[RecordedMessage]) -> None:
    recorder = _record(tmp_path, stream)
    assert recorder.error is None
    [path] = recorder.stats.files
    assert FILE_PATTERN.match(path.name)
    assert is_finished(path)

    expected: dict[str, int] = {}
    for item in stream:
        expected[item.topic] = expected.get(item.topic, 0) + 1
    expected["/truth/mu"] = 1
    assert set(expected) >= {f"/tdmon/{name}" for name in (
        "raw", "sample", "rejected", "state", "model", "estimate", "alarm", "status",
        "well", "profile")}
    counts = topic_counts(path)
    assert {topic: n for topic, n in counts.items() if n} == expected
    assert recorder.stats.per_topic == expected
    assert recorder.stats.lost == 0

    back = [item for item in read_messages(path) if item.topic != "/truth/mu"]
    # Log-time order is stable for equal times, so the sequence matches the stream exactly.
    assert [(m.topic, m.log_time_ns) for m in back] == [(m.topic, m.log_time_ns) for m in stream]
    assert [m.message for m in back] == [json.loads(json.dumps(m.message)) for m in stream]
    assert [m.message for m in read_messages(path, "/truth/mu")] == [{"t": 1.0, "mu": 0.25}]
    only = list(read_messages(path, ["/tdmon/alarm", "/tdmon/status"]))
    assert len(only) == expected["/tdmon/alarm"] + expected["/tdmon/status"]


def test_every_message_validates_against_its_channel_schema(
    tmp_path: Path, stream: list[RecordedMessage]
) -> None:
    recorder = _record(tmp_path, stream)
    [path] = recorder.stats.files
    stored = schemas_of(path)
    # every topic with a message has its schema (a channel is registered with its first
    # message in the file)
    assert set(stored) == {m.topic for m in stream} | {"/truth/mu"}
    validators = {}
    for topic, schema in stored.items():
        jsonschema.Draft202012Validator.check_schema(schema)
        validators[topic] = jsonschema.Draft202012Validator(schema)
    checked = 0
    for topic, _, message in read_messages(path):
        errors = list(validators[topic].iter_errors(message))
        assert not errors, (topic, message, errors[0].message)
        checked += 1
    assert checked == len(stream) + 1


def test_schemas_reject_wrong_shapes() -> None:
    model = schemas.TOPIC_SCHEMAS["/tdmon/model"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"t": 1.0, "bit_depth_m": 10.0}, model)
    state = schemas.TOPIC_SCHEMAS["/tdmon/state"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(
            {"t": 1.0, "state": "flying", "steady": True, "bit_depth_m": 1.0}, state
        )
    alarm = schemas.TOPIC_SCHEMAS["/tdmon/alarm"]
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"t": 1.0, "kind": "x", "severity": "fatal", "message": ""}, alarm)


def test_non_finite_numpy_and_untyped_messages(tmp_path: Path) -> None:
    with McapRecorder(tmp_path) as recorder:
        recorder.write("/tdmon/alarm", 5, {"t": 1.0, "kind": "k", "severity": "info",
                                           "message": "m", "value": float("nan")})
        recorder.write("/tdmon/profile", 6, {"t": np.float64(2.0),
                                             "md_m": np.array([0.0, 10.0]),
                                             "mu": np.array([0.2, np.inf], dtype=np.float32)})
        recorder.write("/tdmon/unknown", 7, {"x": 1})
        recorder.write("/tdmon/alarm", 8, {"t": object()})
        # a null that was None, beside NaN-free nested floats: not a replacement
        recorder.write("/tdmon/model", 9, {"t": 3.0, "residual": {"torque_Nm": None},
                                           "band": {"mu": [0.1, 0.2]}})
        recorder.write("/tdmon/model", 10, {"t": 4.0, "band": {"pick_up_N": [1.0, -math.inf]}})
    stats = recorder.stats
    assert stats.nonfinite_replaced == 3
    assert stats.untyped_topics == 1
    assert stats.unencodable == 1 and stats.lost == 1
    [path] = stats.files
    back = {m.log_time_ns: m.message for m in read_messages(path)}
    assert back[5]["value"] is None
    assert back[6] == {"t": 2.0, "md_m": [0.0, 10.0], "mu": [pytest.approx(0.2), None]}
    assert back[7] == {"x": 1}
    assert back[9]["residual"] == {"torque_Nm": None}
    assert back[10]["band"]["pick_up_N"] == [1.0, None]
    assert schemas_of(path)["/tdmon/unknown"]["type"] == "object"


def test_rotation_by_size_and_time(tmp_path: Path, stream: list[RecordedMessage]) -> None:
    recorder = _record(tmp_path / "size", stream, rotate_bytes=64 * 1024, chunk_size=16 * 1024)
    files = recorder.stats.files
    assert len(files) >= 3
    sequences = [int(FILE_PATTERN.match(p.name)["seq"]) for p in files]  # type: ignore[index]
    assert sequences == list(range(len(files)))
    assert all(is_finished(p) for p in files)
    total = sum(sum(topic_counts(p).values()) for p in files)
    assert total == len(stream) + 1
    # Files hold consecutive slices: concatenated they give the stream back.
    joined = [m for p in files for m in read_messages(p) if m.topic != "/truth/mu"]
    assert [m.message for m in joined] == [json.loads(json.dumps(m.message)) for m in stream]

    with McapRecorder(tmp_path / "time", rotate_s=0.0) as every_write:
        for i in range(3):
            every_write.write("/tdmon/alarm", i, {"t": 1.0, "kind": "k", "severity": "info",
                                                  "message": str(i)})
            # rotation is due between batches of queued messages; a flush ends a batch
            every_write.flush()
    assert len(every_write.stats.files) >= 3


def test_restart_starts_a_new_file(tmp_path: Path) -> None:
    names = []
    for _ in range(2):
        with McapRecorder(tmp_path, prefix="rig") as recorder:
            recorder.write("/tdmon/status", 1, {"t": 1.0, "samples_in": 0, "rejected": 0,
                                                "dropped": 0, "lag_s": None, "connections": {}})
        names.append(recorder.stats.files[0].name)
    assert names[0] != names[1]
    assert [FILE_PATTERN.match(n)["seq"] for n in names] == ["00000", "00001"]  # type: ignore[index]


def test_single_file_mode(tmp_path: Path) -> None:
    target = tmp_path / "replay" / "out.mcap"
    with McapRecorder(path=target) as recorder:
        recorder.write("/tdmon/alarm", 1, {"t": 1.0, "kind": "k", "severity": "info",
                                           "message": "m"})
    assert recorder.stats.files == [target]
    assert topic_counts(target)["/tdmon/alarm"] == 1
    with pytest.raises(RecordError, match="File exists"):
        McapRecorder(path=target)
    with McapRecorder(path=target, overwrite=True):
        pass
    # a channel is in a file from its first message on: an empty file has none
    assert topic_counts(target).get("/tdmon/alarm", 0) == 0


def test_register_topic_twice_with_another_schema_is_an_error(tmp_path: Path) -> None:
    with McapRecorder(tmp_path) as recorder:
        recorder.register_topic("/truth/x", TRUTH_SCHEMA)
        recorder.register_topic("/truth/x", TRUTH_SCHEMA)
        with pytest.raises(RecordError):
            recorder.register_topic("/truth/x", {"type": "object"})


def test_unfinished_file_is_refused_by_the_reader(tmp_path: Path) -> None:
    recorder = McapRecorder(tmp_path, background_flush=False)
    recorder.write("/tdmon/alarm", 1, {"t": 1.0, "kind": "k", "severity": "info", "message": "m"})
    recorder.flush()
    path = recorder.path
    assert path is not None and not is_finished(path)
    with pytest.raises(RecordError, match="recover"):
        list(read_messages(path))
    assert [m.log_time_ns for m in read_messages(path, allow_unfinished=True)] == [1]
    recorder.close()
    assert is_finished(path)


def test_non_finite_walk_of_long_lists_and_enums() -> None:
    from tdmon.record.batch import has_nonfinite as _has_nonfinite
    from tdmon.vocabulary import EstimateKind

    profile = [0.1 * i for i in range(141)]
    message = {"kind": EstimateKind.PROFILE, "mu_profile": profile,
               "reason": ["none"] * 140 + [None], "flags": [True] * 141}
    assert not _has_nonfinite(message)
    for bad in (math.nan, math.inf, -math.inf):
        assert _has_nonfinite({**message, "mu_profile": [*profile[:70], bad, *profile[70:]]})
    # finite numbers whose sum overflows: walked one by one, nothing replaced
    assert not _has_nonfinite({"big": [1e308] * 20, "ints": [10**400] * 20})
    assert _has_nonfinite({"big": [1e308] * 20 + [math.nan]})
    # a long list of numpy values: the json module decides
    assert _has_nonfinite({"x": list(np.array([1.0] * 20 + [np.nan]))})
    assert not _has_nonfinite({"x": list(np.array([1.0] * 21))})
    # a long list of texts and nulls is passed over by its element types; a number among
    # them, a container or an enum (a str subclass) sends it to the walk
    assert not _has_nonfinite({"reasons": ["no window used yet", None] * 20 + [EstimateKind.JOINT]})
    for odd in (math.nan, [math.inf], {"x": -math.inf}):
        assert _has_nonfinite({"reasons": ["no window used yet", None] * 20 + [odd]})
    assert not _has_nonfinite({"reasons": ["no window used yet"] * 40 + [1.5, [2.0]]})
    # short lists (a model message's band) and nested dicts, as orjson nests them at most
    band = {"mu": [0.1, 0.2, 0.3, 0.4], "pick_up_N": [1.6e6, 1.8e6, 2.1e6, 2.4e6]}
    assert not _has_nonfinite({"band": band, "residual": {"torque_Nm": None}})
    for bad in (math.nan, math.inf):
        assert _has_nonfinite({"band": {**band, "mu": [0.1, bad, 0.3, 0.4]}})
        assert _has_nonfinite({"residual": {"torque_Nm": None, "hookload_N": (1.0, bad)}})
    assert not _has_nonfinite({"big": [1e308, 1e308, -1e308]})  # an overflowing sum, finite
    deep: Any = [math.nan]
    for _ in range(250):
        deep = {"x": [deep]}
    assert _has_nonfinite(deep) and not _has_nonfinite({"x": [[[None]]] * 3})
