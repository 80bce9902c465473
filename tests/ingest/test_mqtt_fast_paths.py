"""The MQTT source's and publisher's fast paths, on a real mosquitto where it matters: paho's
socket read through a buffer, PUBACKs written together, QoS 0 results handed to paho in
batches. Each must keep what the slow paths guaranteed: every message, in order, acknowledged
exactly when told, results all delivered."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
from typing import Any

import paho.mqtt.client as mqtt
import pytest

from tdmon.config.daemon import MqttConfig
from tdmon.ingest.mqtt import MqttPublisher, MqttSource, RecentDeliveries, _BufferedReads


def test_buffered_reads_serve_small_reads_from_one_receive_and_say_what_is_left() -> None:
    left, right = socket.socketpair()
    try:
        right.sendall(b"\x30\x05abcde\x30\x02xy")
        reader = _BufferedReads(left)
        assert reader.recv(1) == b"\x30" and reader.recv(1) == b"\x05"
        assert reader.pending() == 9  # read at once, not yet handed out
        assert reader.recv(5) == b"abcde"
        assert reader.recv(100) == b"\x30\x02xy"  # a short read, as recv may give
        assert reader.pending() == 0
        left.setblocking(False)
        with pytest.raises(BlockingIOError):  # nothing buffered, nothing on the socket
            reader.recv(1)
        assert reader.fileno() == left.fileno()  # the rest is the socket's
        right.close()
        assert reader.recv(1) == b""  # end of stream passes through
    finally:
        left.close()


def _publish_burst(port: int, messages: list[tuple[str, bytes]]) -> None:
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="burst-rig")
    client.max_inflight_messages_set(0)
    client.connect("127.0.0.1", port)
    client.loop_start()
    try:
        infos = [client.publish(topic, body, qos=1) for topic, body in messages]
        for info in infos:
            info.wait_for_publish(20)
    finally:
        client.loop_stop()
        client.disconnect()


async def test_a_burst_arrives_whole_in_order_and_its_batched_acks_all_count(
        mosquitto: Any) -> None:
    """3000 QoS 1 messages published while the source reads: the buffered reads see them in
    large chunks; every one is acknowledged through the batched PUBACKs, so a new session with
    the same client id gets none of them again."""
    config = MqttConfig(port=mosquitto.port, client_id="tdmon-burst", clean_session=False)
    messages = [(f"rig/B0/{('hookload', 'torque', 'bit_depth')[i % 3]}",
                 b'{"t": %d, "value": %d}' % (1_700_000_000 + i, i)) for i in range(3000)]
    async with MqttSource(config, ["rig/B0/#"], base=None) as source:
        publisher = asyncio.create_task(asyncio.to_thread(_publish_burst, mosquitto.port,
                                                          messages))
        received = []
        iterator = aiter(source)
        while len(received) < len(messages):
            raw = await asyncio.wait_for(anext(iterator), 20)
            assert raw.ack is not None and not raw.redelivered
            raw.ack()
            received.append((raw.topic, raw.payload))
        await publisher
        assert received == messages
        # the broker has the acknowledgements once a later QoS 1 publish on the same
        # connection is acknowledged: it takes one connection's packets in order (was: 0.5 s)
        assert source._client is not None
        await source._client.publish("probe/acknowledged", b"", qos=1)

    async with MqttSource(config, ["rig/B0/#"], base=None,
                          recent=RecentDeliveries()) as source:
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(anext(aiter(source)), 1.5)


async def test_qos0_results_are_all_delivered_in_order(mosquitto: Any) -> None:
    n = 3000
    got: list[int] = []
    done = threading.Event()

    def on_message(_c: Any, _u: Any, message: mqtt.MQTTMessage) -> None:
        got.append(json.loads(message.payload)["i"])
        if len(got) == n:
            done.set()

    subscribed = threading.Event()
    dashboard = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="dash")
    dashboard.on_message = on_message
    dashboard.on_subscribe = lambda *_: subscribed.set()
    dashboard.connect("127.0.0.1", mosquitto.port)
    dashboard.subscribe("rig/Q0/tdmon/#", qos=0)
    dashboard.loop_start()
    publisher = MqttPublisher(MqttConfig(port=mosquitto.port, client_id="tdmon-q0"), "rig/Q0",
                              ["model"], qos=0, queue_size=n)
    try:
        # the subscription is in place: the broker's SUBACK came (was: a 0.3 s pause)
        assert await asyncio.to_thread(subscribed.wait, 60)
        for i in range(n):
            publisher.write("/tdmon/model", 0, {"i": i})
        async with publisher.connect() as client:
            pump = asyncio.create_task(publisher.pump(client))
            assert await publisher.drain(20)
            assert await asyncio.to_thread(done.wait, 20)
            pump.cancel()
            await asyncio.gather(pump, return_exceptions=True)
        assert got == list(range(n)) and publisher.published == n and publisher.dropped == 0
    finally:
        dashboard.loop_stop()
        dashboard.disconnect()
