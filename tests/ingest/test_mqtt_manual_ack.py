"""The two paho calls of :class:`tdmon.ingest.mqtt.ManualAcks` (aiomqtt issue 345), each held
to what it must do on a real mosquitto, so that a paho release that changes either fails here
(pyproject.toml pins paho-mqtt to the releases these tests passed on)."""

from __future__ import annotations

import asyncio
from typing import Any

from mqtt_support import acknowledged, nothing_within, publish, take

from tdmon.config.daemon import MqttConfig
from tdmon.ingest.mqtt import MqttSource, RecentDeliveries


def _messages(prefix: str, n: int) -> list[tuple[str, bytes]]:
    return [(f"{prefix}/{('hookload', 'torque')[i % 2]}", b'{"t": %d, "value": %d}' % (i, i))
            for i in range(n)]


async def test_call_1_nothing_is_acknowledged_on_receipt_not_even_on_a_resumed_session(
        mosquitto: Any) -> None:
    """``manual_ack_set(True)`` before connecting: messages queued for the session while the
    source was away, delivered as it connects, are not acknowledged by paho on receipt."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-ack-1", clean_session=False)
    async with MqttSource(config, ["rig/K1/#"]):
        pass  # the broker now keeps a session for this client id
    messages = _messages("rig/K1", 5)
    await asyncio.to_thread(publish, mosquitto.port, messages)  # queued for the session

    async with MqttSource(config, ["rig/K1/#"]) as source:
        first = await take(source, 5)
        assert [(m.topic, m.payload) for m in first] == messages
        assert all(m.ack is not None for m in first)  # handed out, never called
        await acknowledged(source)  # anything paho sent of its own is with the broker

    async with MqttSource(config, ["rig/K1/#"], recent=RecentDeliveries()) as source:
        again = await take(source, 5)
        assert [(m.topic, m.payload) for m in again] == messages
        for message in again:
            assert message.ack is not None
            message.ack()
        await acknowledged(source)


async def test_call_2_acknowledges_the_messages_acked_and_no_other(mosquitto: Any) -> None:
    """``ack(mid, qos)``: a PUBACK for that message only; after the connection is gone it
    sends nothing (and does not raise), so the broker keeps the message."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-ack-2", clean_session=False)
    messages = _messages("rig/K2", 10)
    async with MqttSource(config, ["rig/K2/#"]) as source:
        await asyncio.to_thread(publish, mosquitto.port, messages)
        first = await take(source, 10)
        for message in first[::2]:
            assert message.ack is not None
            message.ack()
        await acknowledged(source)
    late = first[1].ack
    assert late is not None
    late()  # its connection is closed: nothing is sent

    async with MqttSource(config, ["rig/K2/#"], recent=RecentDeliveries()) as source:
        again = await take(source, 5)
        assert [(m.topic, m.payload) for m in again] == messages[1::2]
        assert await nothing_within(source, 1.0)
        for message in again:
            assert message.ack is not None
            message.ack()
        await acknowledged(source)

    async with MqttSource(config, ["rig/K2/#"], recent=RecentDeliveries()) as source:
        assert await nothing_within(source, 1.5)


async def test_call_2_completes_each_qos_2_message(mosquitto: Any) -> None:
    """At QoS 2 ``ack`` sends the PUBCOMP that completes the message: the test broker has at
    most 100 messages in flight to a client, so 150 arrive only if each ack completed one."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-ack-3", clean_session=False,
                        qos=2)
    messages = _messages("rig/K3", 150)
    async with MqttSource(config, ["rig/K3/#"]) as source:
        sending = asyncio.create_task(asyncio.to_thread(publish, mosquitto.port, messages, 2))
        received = []
        iterator = aiter(source)
        while len(received) < len(messages):
            message = await asyncio.wait_for(anext(iterator), 10)
            assert message.ack is not None
            message.ack()
            received.append((message.topic, message.payload))
        await sending
        assert received == messages
