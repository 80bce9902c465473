"""Helpers of the MQTT tests: a rig publishing QoS 1 messages (paho, in a thread) and a source's
messages taken with a timeout."""

from __future__ import annotations

import asyncio

import paho.mqtt.client as mqtt

from tdmon.ingest.mqtt import MqttSource
from tdmon.ingest.types import RawMessage


def publish(port: int, messages: list[tuple[str, bytes]], qos: int = 1,
            client_id: str = "test-rig") -> None:
    """Publish ``messages`` in order and wait until the broker has each (blocking)."""
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
    if qos == 1:
        client.max_inflight_messages_set(0)  # no limit: a burst as fast as the broker takes it
    client.connect("127.0.0.1", port)
    client.loop_start()
    try:
        infos = [client.publish(topic, body, qos=qos) for topic, body in messages]
        for info in infos:
            info.wait_for_publish(20)
    finally:
        client.loop_stop()
        client.disconnect()


async def take(source: MqttSource, n: int, timeout: float = 10.0) -> list[RawMessage]:
    """The next ``n`` messages of ``source`` (each within ``timeout`` seconds)."""
    iterator = aiter(source)
    return [await asyncio.wait_for(anext(iterator), timeout) for _ in range(n)]


async def nothing_within(source: MqttSource, seconds: float) -> bool:
    """Whether ``source`` hands out nothing for ``seconds``."""
    try:
        await asyncio.wait_for(anext(aiter(source)), seconds)
    except TimeoutError:
        return True
    return False
