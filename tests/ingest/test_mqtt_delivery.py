"""Manual acknowledgement on a real mosquitto: a message the source handed out but nobody
acknowledged comes back on the next session with the DUP flag and is recognised as a duplicate;
an acknowledged one never comes back."""

from __future__ import annotations

import asyncio
from typing import Any

import paho.mqtt.client as mqtt

from tdmon.config.daemon import MqttConfig
from tdmon.ingest.mqtt import MqttSource, RecentDeliveries
from tdmon.ingest.types import RawMessage


def _publish(port: int, messages: list[tuple[str, bytes]]) -> None:
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="delivery-rig")
    client.connect("127.0.0.1", port)
    client.loop_start()
    try:
        for topic, body in messages:
            client.publish(topic, body, qos=1).wait_for_publish(10)
    finally:
        client.loop_stop()
        client.disconnect()


async def _acknowledged(source: MqttSource) -> None:
    """Return once the broker has the acknowledgements given so far: a QoS 1 round trip on the
    same connection, whose packets the broker takes in order (was: a 0.5 s pause)."""
    assert source._client is not None
    await source._client.publish("probe/acknowledged", b"", qos=1)


async def _take(source: MqttSource, n: int) -> list[RawMessage]:
    out = []
    iterator = aiter(source)
    for _ in range(n):
        out.append(await asyncio.wait_for(anext(iterator), 10))
    return out


async def _nothing_within(source: MqttSource, seconds: float) -> bool:
    try:
        await asyncio.wait_for(anext(aiter(source)), seconds)
    except TimeoutError:
        return True
    return False


async def test_unacknowledged_messages_come_back_as_recognised_duplicates(mosquitto: Any) -> None:
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-delivery", clean_session=False)
    recent = RecentDeliveries()
    messages = [(f"rig/D0/{('hookload', 'torque')[i % 2]}", b'{"t": %d, "value": %d}' % (i, i))
                for i in range(10)]

    async with MqttSource(config, ["rig/D0/#"], base=None, recent=recent) as source:
        await asyncio.to_thread(_publish, mosquitto.port, messages)
        first = await _take(source, 10)
        assert [(m.topic, m.payload) for m in first] == messages
        assert all(m.ack is not None and not m.redelivered and not m.duplicate for m in first)
        for message in first[:4]:
            assert message.ack is not None
            message.ack()  # the first four are safe with us; six are not acknowledged
        await _acknowledged(source)

    # the broker resends the six it has no acknowledgement for, flagged DUP, in order
    async with MqttSource(config, ["rig/D0/#"], base=None, recent=recent) as source:
        again = await _take(source, 6)
        assert [(m.topic, m.payload) for m in again] == messages[4:]
        assert all(m.redelivered and m.duplicate for m in again)
        assert await _nothing_within(source, 1.0)
        for message in again:
            assert message.ack is not None
            message.ack()
        await _acknowledged(source)

    # a new run (its own memory) after acknowledging everything: nothing comes back
    async with MqttSource(config, ["rig/D0/#"], base=None,
                          recent=RecentDeliveries()) as source:
        assert await _nothing_within(source, 1.5)


async def test_a_redelivery_this_run_has_not_seen_is_processed(mosquitto: Any) -> None:
    """After a restart the daemon cannot know whether a DUP message was recorded: it is
    marked redelivered but not duplicate, so it is processed (at least once)."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-delivery2", clean_session=False)
    messages = [("rig/D0/hookload", b'{"t": %d, "value": 1}' % i) for i in range(3)]
    async with MqttSource(config, ["rig/D0/#"], base=None) as source:
        await asyncio.to_thread(_publish, mosquitto.port, messages)
        await _take(source, 3)  # never acknowledged: the "run" dies here
    async with MqttSource(config, ["rig/D0/#"], base=None,
                          recent=RecentDeliveries()) as source:
        again = await _take(source, 3)
        assert [m.payload for m in again] == [body for _, body in messages]
        assert all(m.redelivered and not m.duplicate for m in again)
        for message in again:
            assert message.ack is not None
            message.ack()
        await _acknowledged(source)


def test_recent_deliveries_window_forgets_the_oldest() -> None:
    recent = RecentDeliveries(size=3)
    for i in range(5):
        recent.add("a", b"%d" % i)
    assert ("a", b"1") not in recent and ("a", b"2") in recent and ("a", b"4") in recent
    recent.add("a", b"4")
    recent.add("a", b"4")
    recent.add("a", b"4")
    assert ("a", b"4") in recent and ("a", b"3") not in recent
