"""Helpers of the MQTT tests: a rig publishing QoS 1 messages (paho, in a thread), a source's
messages taken with a timeout, and a wait until the broker has its acknowledgements."""

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


async def acknowledged(source: MqttSource, timeout: float = 10.0) -> None:
    """Return once the broker has the acknowledgements ``source`` gave so far: a QoS 1 round
    trip on the same connection, whose packets the broker reads in order (a fixed pause, on a
    loaded machine, left acknowledgements unread when the connection closed, and the broker
    sent their messages again)."""
    assert source._client is not None
    await source._client.publish("probe/acknowledged", b"", qos=1, timeout=timeout)


async def nothing_within(source: MqttSource, seconds: float) -> bool:
    """Whether ``source`` hands out nothing for ``seconds``."""
    try:
        await asyncio.wait_for(anext(aiter(source)), seconds)
    except TimeoutError:
        return True
    return False
