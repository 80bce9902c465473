"""Results whose acknowledgement never comes are sent again, on a real mosquitto.

The broker is frozen (SIGSTOP) while the publisher has a batch of QoS 1 results on the wire:
no PUBACK can come. Within ``ack_timeout`` the publisher gives the connection up (counted),
and once the broker runs again the supervisor's new connection sends the batch again: every
result arrives, at least once, in order of first arrival.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import threading
import time
from typing import Any

import paho.mqtt.client as mqtt

from tdmon.config.daemon import MqttConfig
from tdmon.daemon.supervisor import Backoff, supervise
from tdmon.ingest.mqtt import MqttPublisher
from tdmon.vocabulary import ConnectionState


async def _until(predicate: Any, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.02)


async def test_a_batch_left_unacknowledged_is_sent_again_on_a_new_connection(
        mosquitto: Any) -> None:
    n = 200
    got: list[int] = []
    lock = threading.Lock()

    def on_message(_c: Any, _u: Any, message: mqtt.MQTTMessage) -> None:
        with lock:
            got.append(json.loads(message.payload)["i"])

    subscribed = threading.Event()
    dashboard = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="dash-ack-timeout")
    dashboard.on_message = on_message
    dashboard.on_subscribe = lambda *_: subscribed.set()
    dashboard.connect("127.0.0.1", mosquitto.port)
    dashboard.subscribe("rig/T0/tdmon/#", qos=1)
    dashboard.loop_start()
    publisher = MqttPublisher(MqttConfig(port=mosquitto.port, client_id="tdmon-ack-timeout"),
                              "rig/T0", ["model"], qos=1, queue_size=n, ack_timeout=0.5)
    states: dict[str, str] = {}
    pump = asyncio.create_task(supervise(publisher.name, publisher.connect, publisher.pump,
                                         states, Backoff(initial=0.05, maximum=0.2)))
    try:
        assert await asyncio.to_thread(subscribed.wait, 60)
        await _until(lambda: states.get(publisher.name) == ConnectionState.CONNECTED, 30,
                     "the publisher's connection")
        os.kill(mosquitto.process.pid, signal.SIGSTOP)
        try:
            for i in range(n):
                publisher.write("/tdmon/model", 0, {"i": i})
            # frozen: no acknowledgement can come, the batch times out
            await _until(lambda: publisher.timeouts >= 1, 10, "the acknowledgement timeout")
            assert publisher.published == 0 and publisher.pending == n
            assert "not acknowledged within 0.5 s" in states[publisher.name]
        finally:
            os.kill(mosquitto.process.pid, signal.SIGCONT)
        assert await publisher.drain(30)
        await _until(lambda: len(set(got)) == n, 30, "every result at the dashboard")
    finally:
        pump.cancel()
        await asyncio.gather(pump, return_exceptions=True)
        dashboard.loop_stop()
        dashboard.disconnect()
    assert publisher.published == n and publisher.dropped == 0
    first_seen = list(dict.fromkeys(got))
    assert first_seen == list(range(n))
    # the batch on the wire when the broker froze may have arrived twice (at least once)
    assert n <= len(got) <= n + 64 * publisher.timeouts
