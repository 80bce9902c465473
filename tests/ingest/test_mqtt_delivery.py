"""Delivery through the MQTT source on a real mosquitto: what was handed out but not
acknowledged comes back on the next session and is recognised as a duplicate; an acknowledged
message never comes back; a burst arrives whole and in order; results are all published."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable
from typing import Any

import paho.mqtt.client as mqtt
import pytest
from mqtt_support import acknowledged, nothing_within, publish, take

from tdmon.config.daemon import MqttConfig
from tdmon.ingest.mqtt import MqttPublisher, MqttSource, RecentDeliveries


async def test_unacknowledged_messages_come_back_as_recognised_duplicates(mosquitto: Any) -> None:
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-delivery", clean_session=False)
    recent = RecentDeliveries()
    messages = [(f"rig/D0/{('hookload', 'torque')[i % 2]}", b'{"t": %d, "value": %d}' % (i, i))
                for i in range(10)]

    async with MqttSource(config, ["rig/D0/#"], base=None, recent=recent) as source:
        await asyncio.to_thread(publish, mosquitto.port, messages)
        first = await take(source, 10)
        assert [(m.topic, m.payload) for m in first] == messages
        assert all(m.ack is not None and not m.duplicate for m in first)
        for message in first[:4]:
            assert message.ack is not None
            message.ack()  # the first four are safe with us; six are not acknowledged
        await acknowledged(source)

    # the broker resends the six it has no acknowledgement for, in order: this run handed
    # them out already
    async with MqttSource(config, ["rig/D0/#"], base=None, recent=recent) as source:
        again = await take(source, 6)
        assert [(m.topic, m.payload) for m in again] == messages[4:]
        assert all(m.duplicate for m in again)
        assert await nothing_within(source, 1.0)
        for message in again:
            assert message.ack is not None
            message.ack()
        await acknowledged(source)

    # a new run (its own memory) after acknowledging everything: nothing comes back
    async with MqttSource(config, ["rig/D0/#"], base=None,
                          recent=RecentDeliveries()) as source:
        assert await nothing_within(source, 1.5)


async def test_a_redelivery_this_run_has_not_seen_is_processed(mosquitto: Any) -> None:
    """After a restart the daemon cannot know whether a resent message was recorded: it is
    not a duplicate, so it is processed (at least once)."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-delivery2", clean_session=False)
    messages = [("rig/D0/hookload", b'{"t": %d, "value": 1}' % i) for i in range(3)]
    async with MqttSource(config, ["rig/D0/#"], base=None) as source:
        await asyncio.to_thread(publish, mosquitto.port, messages)
        await take(source, 3)  # never acknowledged: the "run" dies here
    async with MqttSource(config, ["rig/D0/#"], base=None,
                          recent=RecentDeliveries()) as source:
        again = await take(source, 3)
        assert [m.payload for m in again] == [body for _, body in messages]
        assert not any(m.duplicate for m in again)
        for message in again:
            assert message.ack is not None
            message.ack()
        await acknowledged(source)


async def test_a_payload_sent_twice_is_a_duplicate_only_on_a_resumed_session(
        mosquitto: Any) -> None:
    """The broker resends only on a session resumed after a reconnect: on a run's first
    connection a payload the rig sent twice is handed out twice; on a later one, the same
    topic and payload as one handed out before is taken for a resend."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-delivery3", clean_session=False)
    recent = RecentDeliveries()
    twice = [("rig/D3/hookload", b'{"t": 5, "value": 1}')] * 2
    for expected in ([False, False], [True, True]):
        async with MqttSource(config, ["rig/D3/#"], base=None, recent=recent) as source:
            await asyncio.to_thread(publish, mosquitto.port, twice)
            received = await take(source, 2)
            assert [m.duplicate for m in received] == expected
            for message in received:
                assert message.ack is not None
                message.ack()
            await acknowledged(source)


def test_recent_deliveries_window_forgets_the_oldest() -> None:
    recent = RecentDeliveries(size=3)
    for i in range(5):
        recent.add("a", b"%d" % i)
    assert ("a", b"1") not in recent and ("a", b"2") in recent and ("a", b"4") in recent
    assert len(recent) == 3
    recent.add("a", b"4")
    recent.add("a", b"4")
    recent.add("a", b"4")
    assert ("a", b"4") in recent and ("a", b"3") not in recent


async def test_a_burst_arrives_whole_in_order_and_every_ack_counts(mosquitto: Any) -> None:
    """3000 QoS 1 messages published while the source reads: all arrive, in order; every one
    is acknowledged, so a new session with the same client id gets none of them again."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-burst", clean_session=False)
    messages = [(f"rig/B0/{('hookload', 'torque', 'bit_depth')[i % 3]}",
                 b'{"t": %d, "value": %d}' % (1_700_000_000 + i, i)) for i in range(3000)]
    async with MqttSource(config, ["rig/B0/#"], base=None) as source:
        publisher = asyncio.create_task(asyncio.to_thread(publish, mosquitto.port, messages))
        received = []
        iterator = aiter(source)
        while len(received) < len(messages):
            raw = await asyncio.wait_for(anext(iterator), 20)
            assert raw.ack is not None and not raw.duplicate
            raw.ack()
            received.append((raw.topic, raw.payload))
        await publisher
        assert received == messages
        await acknowledged(source)

    async with MqttSource(config, ["rig/B0/#"], base=None,
                          recent=RecentDeliveries()) as source:
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(anext(aiter(source)), 1.5)


@pytest.mark.parametrize("qos", [0, 1])
async def test_results_are_all_delivered_in_order(mosquitto: Any, qos: int) -> None:
    n = 3000
    got: list[int] = []
    done = threading.Event()

    def on_message(_c: Any, _u: Any, message: mqtt.MQTTMessage) -> None:
        got.append(json.loads(message.payload)["i"])
        if len(got) == n:
            done.set()

    subscribed = threading.Event()
    dashboard = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"dash-{qos}")
    dashboard.on_message = on_message
    dashboard.on_subscribe = lambda *_: subscribed.set()
    dashboard.connect("127.0.0.1", mosquitto.port)
    dashboard.subscribe(f"rig/Q{qos}/tdmon/#", qos=qos)
    dashboard.loop_start()
    publisher = MqttPublisher(MqttConfig(port=mosquitto.port, client_id=f"tdmon-q{qos}"),
                              f"rig/Q{qos}", ["model"], qos=qos, queue_size=n)
    try:
        # the subscription is in place: the broker's SUBACK came
        assert await asyncio.to_thread(subscribed.wait, 60)
        for i in range(n):
            publisher.write("/tdmon/model", 0, {"i": i})
        async with publisher.connect() as client:
            pump = asyncio.create_task(publisher.pump(client))
            assert await publisher.drain(30)
            assert await asyncio.to_thread(done.wait, 20)
            pump.cancel()
            await asyncio.gather(pump, return_exceptions=True)
        assert got == list(range(n)) and publisher.published == n and publisher.dropped == 0
    finally:
        dashboard.loop_stop()
        dashboard.disconnect()


async def test_a_backlog_is_handed_over_in_lists_in_order(mosquitto: Any) -> None:
    """Messages queued for the session while the source was away come in lists of more than
    one (the daemon processes a list as one burst), every one once, in order."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-backlog", clean_session=False)
    async with MqttSource(config, ["rig/L0/#"], base=None):
        pass  # the broker keeps a session for this client id from now on
    messages = [(f"rig/L0/{('hookload', 'torque')[i % 2]}", b'{"t": %d, "value": 1}' % i)
                for i in range(2000)]
    await asyncio.to_thread(publish, mosquitto.port, messages)
    async with MqttSource(config, ["rig/L0/#"], base=None) as source:
        received: list[tuple[str, bytes]] = []
        sizes = []
        batches = source.batches()
        while len(received) < len(messages):
            batch = await asyncio.wait_for(anext(batches), 10)
            sizes.append(len(batch))
            for raw in batch:
                assert raw.ack is not None
                raw.ack()
                received.append((raw.topic, raw.payload))
        assert received == messages
        assert max(sizes) > 1 and len(sizes) < len(messages)
        await acknowledged(source)


async def test_a_resumed_session_s_backlog_does_not_hold_the_subscription_up(
        shipped_mosquitto: Callable[..., Any]) -> None:
    """On a session resumed with messages in flight, mosquitto (the shipped configuration)
    sends its whole queue before it answers the subscription: the source is entered once the
    first message has come (not after the whole backlog has been read, which with a large one
    took longer than aiomqtt's timeout), and the backlog then arrives whole and in order."""
    broker = shipped_mosquitto()
    config = MqttConfig(port=broker.port, client_id="tdmon-resume", clean_session=False)
    messages = [("rig/R0/hookload", b'{"t": %d, "value": 1}' % i) for i in range(20_000)]
    async with MqttSource(config, ["rig/R0/#"], base=None):
        pass  # the broker keeps a session for this client id from now on
    await asyncio.to_thread(publish, broker.port, messages)
    acked = set()
    async with MqttSource(config, ["rig/R0/#"], base=None) as source:
        for i, raw in enumerate(await take(source, 500)):
            if i % 2 and raw.ack is not None:  # half acknowledged; the run ends here
                raw.ack()
                acked.add(raw.payload)
        # the probe's answer comes behind the backlog the broker is sending
        await acknowledged(source, timeout=20)
    expected = [message for message in messages if message[1] not in acked]
    async with MqttSource(config, ["rig/R0/#"], base=None) as source:
        assert source._client is not None
        waiting = len(source._client.messages)
        received = []
        batches = source.batches()
        while len(received) < len(expected):
            for raw in await asyncio.wait_for(anext(batches), 20):
                assert raw.ack is not None
                raw.ack()
                received.append((raw.topic, raw.payload))
        assert received == expected
        assert waiting < len(expected) // 10  # entered long before all of it had been read
        await acknowledged(source)
