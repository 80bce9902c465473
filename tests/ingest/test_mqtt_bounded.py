"""The MQTT source's queue under a QoS 0 flood, on a real mosquitto (issue 32, item 6).

The broker's in-flight window bounds QoS 1 messages, but not QoS 0: a publisher faster than
the daemon once filled the client's queue without bound (150 000 x 3 KB: 108 -> 587 MB). Here
the source is entered and not read while a flood arrives, the worst case: its queue keeps
``max_queued`` QoS 0 messages, drops and counts the rest, and still keeps QoS 1 messages.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

from mqtt_support import flood, publish, take

from tdmon.config.daemon import MqttConfig
from tdmon.daemon.loss import DropAlarm
from tdmon.ingest.mqtt import MqttSource

SENT = 5000
PAYLOAD = b"x" * 3000
LIMIT = 200


async def _flooded(source: MqttSource, expected: int, timeout: float = 60.0) -> None:
    """Let the client read until ``expected`` messages were queued or dropped."""
    inbox = source._inbox
    assert inbox is not None
    deadline = time.monotonic() + timeout
    while inbox.qsize() + inbox.dropped < expected:
        assert time.monotonic() < deadline, (inbox.qsize(), inbox.dropped)
        await asyncio.sleep(0.01)


async def test_a_qos0_flood_keeps_at_most_the_limit_and_counts_the_rest(mosquitto: Any) -> None:
    drops: list[int] = []
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-bounded", clean_session=True)
    async with MqttSource(config, ["rig/#"], max_queued=LIMIT, on_drop=drops.append) as source:
        await asyncio.to_thread(flood, mosquitto.port, "rig/F1/hookload", PAYLOAD, SENT)
        await _flooded(source, SENT)
        inbox = source._inbox
        assert inbox is not None
        assert inbox.qsize() == LIMIT and inbox.dropped == SENT - LIMIT
        assert sum(drops) == SENT - LIMIT
        # QoS 1 is bounded by the broker's in-flight window, and kept beyond the limit
        await asyncio.to_thread(publish, mosquitto.port,
                                [(f"rig/F1/torque{i}", b"kept") for i in range(3)])
        await _flooded(source, SENT + 3)
        assert inbox.qsize() == LIMIT + 3 and inbox.dropped == SENT - LIMIT
        taken = await take(source, LIMIT + 3)
        assert [raw.topic for raw in taken[LIMIT:]] == [f"rig/F1/torque{i}" for i in range(3)]
        assert all(raw.payload == PAYLOAD for raw in taken[:LIMIT])


async def test_without_a_limit_the_flood_is_all_kept(mosquitto: Any) -> None:
    """The control: what the bound prevents (every message of the flood held at once)."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-unbounded", clean_session=True)
    async with MqttSource(config, ["rig/#"]) as source:
        await asyncio.to_thread(flood, mosquitto.port, "rig/F1/hookload", PAYLOAD, SENT)
        await _flooded(source, SENT)
        assert source._inbox is not None and source._inbox.qsize() == SENT


async def test_drops_are_counted_at_once_and_alarmed_once_per_interval() -> None:
    counted: list[int] = []
    alarms: list[dict[str, Any]] = []
    drops = DropAlarm("the queue was full", counted.append, alarms.append, interval=0.2)
    for _ in range(7):
        drops.add()
    assert sum(counted) == 7 and alarms == []  # counted now, alarmed once the interval ends
    await asyncio.sleep(0.4)
    drops.add(3)
    await asyncio.sleep(0.4)
    assert [a["value"] for a in alarms] == [7, 3]
    assert all(a["kind"] == "data_loss" and a["severity"] == "warning" for a in alarms)
    assert alarms[0]["message"] == "7 message(s) dropped: the queue was full"
    await asyncio.sleep(0.3)
    assert len(alarms) == 2  # no drop, no alarm
