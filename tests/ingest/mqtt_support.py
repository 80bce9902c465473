"""Helpers of the MQTT tests: a rig publishing QoS 1 messages (paho, in a thread), a source's
messages taken with a timeout, and a wait until the broker has its acknowledgements."""

from __future__ import annotations

import asyncio
import socket

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


def _remaining_length(n: int) -> bytes:
    """MQTT's variable-length integer (MQTT 3.1.1, 2.2.3)."""
    out = bytearray()
    while True:
        n, digit = n >> 7, n & 0x7F
        out.append(digit | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _packet(kind: int, body: bytes) -> bytes:
    return bytes([kind]) + _remaining_length(len(body)) + body


def _string(text: str) -> bytes:
    data = text.encode()
    return len(data).to_bytes(2, "big") + data


def flood(port: int, topic: str, payload: bytes, count: int) -> None:
    """Publish ``count`` QoS 0 messages as fast as the socket takes them (blocking). The
    packets are written by hand (MQTT 3.1.1, 3.1 CONNECT and 3.3 PUBLISH): a Python client's
    work per message would be slower than the reader it is meant to outrun."""
    with socket.create_connection(("127.0.0.1", port), timeout=30) as sock:
        connect = _string("MQTT") + bytes([4, 0x02]) + (60).to_bytes(2, "big") + _string("flood")
        sock.sendall(_packet(0x10, connect))
        assert sock.recv(4) == b"\x20\x02\x00\x00", "CONNACK refused"
        publish = _packet(0x30, _string(topic) + payload)
        for _ in range(count // 1000):
            sock.sendall(publish * 1000)
        sock.sendall(publish * (count % 1000) + _packet(0xE0, b""))
