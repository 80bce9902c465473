"""RawMessage and Sample: built, frozen, compared, copied and pickled as dataclasses."""

from __future__ import annotations

import dataclasses
import pickle

import pytest

from tdmon.ingest.types import RawMessage, Sample


def test_a_raw_message_is_built_frozen_compared_and_copied_like_a_dataclass() -> None:
    def ack() -> None:
        pass

    raw = RawMessage("mqtt", "rig/F4/hookload", b'{"t":1,"value":2}', 12.5, ack,
                     redelivered=True)
    assert (raw.source, raw.topic, raw.payload, raw.receive_time, raw.ack, raw.redelivered,
            raw.duplicate) == ("mqtt", "rig/F4/hookload", b'{"t":1,"value":2}', 12.5, ack,
                               True, False)
    same = RawMessage(source="mqtt", topic="rig/F4/hookload", payload=b'{"t":1,"value":2}',
                      receive_time=12.5, redelivered=True)
    assert raw == same and hash(raw) == hash(same)  # ack is not compared
    assert raw != dataclasses.replace(raw, duplicate=True)
    with pytest.raises(dataclasses.FrozenInstanceError):
        raw.topic = "elsewhere"  # type: ignore[misc]
    assert repr(same) == ("RawMessage(source='mqtt', topic='rig/F4/hookload', "
                          "payload=b'{\"t\":1,\"value\":2}', receive_time=12.5, "
                          "redelivered=True, duplicate=False)")


def test_a_sample_is_built_frozen_and_pickled_like_a_dataclass() -> None:
    sample = Sample("hookload", 1.7e9, 1.2e6, "mqtt", "rig/F4/hookload", "N", 1.7e9 + 0.2)
    assert sample.seq is None and sample.value == 1.2e6 and sample.unit == "N"
    assert dataclasses.replace(sample, seq=7).seq == 7
    assert pickle.loads(pickle.dumps(sample)) == sample
    assert dataclasses.asdict(sample)["receive_time"] == 1.7e9 + 0.2
    with pytest.raises(dataclasses.FrozenInstanceError):
        sample.value = 0.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        Sample("hookload", 1.0, 2.0, "mqtt", "t", "N")  # type: ignore[call-arg]
