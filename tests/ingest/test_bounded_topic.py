"""A topic of 64 KiB (MQTT allows it) is recorded to the same bound as a payload (issue 32,
fault 11): its first bytes, its size, and a mark; rig topics are recorded whole as before."""

from __future__ import annotations

import jsonschema

from tdmon.ingest.types import (
    RECORDED_PAYLOAD_BYTES,
    RawMessage,
    Rejected,
    bounded_topic,
    raw_message,
    rejected_message,
)
from tdmon.record import schemas


def test_a_rig_topic_is_recorded_whole() -> None:
    raw = RawMessage("mqtt", "rig/T1/hookload", b'{"t": 1, "value": 2}', 3.0)
    assert raw_message(raw) == {"source": "mqtt", "topic": "rig/T1/hookload",
                                "receive_time": 3.0, "payload": '{"t": 1, "value": 2}',
                                "payload_encoding": "utf-8"}
    # the longest topic that still fits, in 4-byte characters and in ASCII
    assert bounded_topic("\U0001f600" * 1024) == {"topic": "\U0001f600" * 1024}
    assert bounded_topic("a" * RECORDED_PAYLOAD_BYTES) == {"topic": "a" * 4096}


def test_a_64_kib_topic_is_cut_like_a_payload() -> None:
    topic = "rig/" + "x" * 65_000 + "/hookload"
    rejected = Rejected("unknown channel", b"{}", "mqtt", topic, 5.0)
    message = rejected_message(rejected)
    assert message["topic"] == topic[:RECORDED_PAYLOAD_BYTES]
    assert message["topic_bytes"] == len(topic) == 65_013
    assert message["topic_truncated"] is True
    jsonschema.validate(message, schemas.TOPIC_SCHEMAS["/tdmon/rejected"])
    raw = raw_message(RawMessage("mqtt", topic, b"{}", 5.0))
    assert (raw["topic"], raw["topic_bytes"], raw["payload"]) == (
        topic[:RECORDED_PAYLOAD_BYTES], 65_013, "{}")
    jsonschema.validate(raw, schemas.TOPIC_SCHEMAS["/tdmon/raw"])


def test_a_cut_never_splits_a_character() -> None:
    topic = "rig/" + "\u00e9" * 5000  # 2 bytes each: the bound falls inside one
    cut = bounded_topic(topic, 4097)
    assert cut["topic"] == "rig/" + "\u00e9" * 2046
    assert cut["topic_bytes"] == 10_004
