"""A broker restart in the middle of a stream loses nothing (QoS 1, persistent sessions)."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiomqtt
from daemon_support import make_config, payload, running, wait_until

TOTAL = 600
RESTART_AT = 200


def _messages(t0: float) -> list[tuple[str, bytes]]:
    """The stream, each topic numbered by ``seq`` (issue 32, fault 4: over a restart the
    broker may deliver a topic's newer messages before its backlog; no loss may be counted)."""
    out = []
    seq = {"hookload": 0, "torque": 0, "bit_depth": 0}
    for i in range(TOTAL):
        t = t0 + 0.01 * i
        if i % 50 == 7:
            out.append(("rig/T1/hookload", b'{"t": %d, "value": oops}' % i))  # must be rejected
        else:
            channel = ("hookload", "torque", "bit_depth")[i % 3]
            seq[channel] += 1
            body = json.loads(payload(t, 1000.0 + i))
            out.append((f"rig/T1/{channel}", json.dumps({**body, "seq": seq[channel]}).encode()))
    return out


async def _publish_all(broker: Any, messages: list[tuple[str, bytes]],
                       retrying: Callable[[], bool]) -> int:
    """Publish every message at QoS 1, retrying over the restart (the broker comes back once
    ``retrying()``: the daemon has failed a reconnect); returns the retries."""
    index = 0
    retries = 0
    restart: asyncio.Task[None] | None = None

    async def bounce() -> None:
        await asyncio.to_thread(broker.stop)
        # the daemon has failed a reconnect (was: a 0.7 s pause)
        await wait_until(retrying, 60, "the daemon retrying")
        await asyncio.to_thread(broker.start)

    while index < len(messages):
        try:
            async with aiomqtt.Client("127.0.0.1", broker.port, identifier="rig-restart",
                                      clean_session=False, timeout=3) as client:
                while index < len(messages):
                    if index == RESTART_AT and restart is None:
                        restart = asyncio.create_task(bounce())
                    topic, body = messages[index]
                    await client.publish(topic, body, qos=1)
                    index += 1
        except aiomqtt.MqttError:
            retries += 1  # the message in flight is sent again: at least once, maybe twice
            await asyncio.sleep(0.2)
    if restart is not None:
        await restart
    return retries


async def test_broker_restart_loses_nothing(mosquitto: Any, tmp_path: Path) -> None:
    config = make_config({
        "sources": {"mqtt": {"port": mosquitto.port, "client_id": "tdmon-restart"}},
    }, tmp_path)
    messages = _messages(time.time())
    bad = sum(1 for _, body in messages if b"oops" in body)
    started = time.monotonic()
    async with running(config, connected=("mqtt",)) as (built, sink):
        states: list[str] = []

        async def watch() -> None:
            while True:
                states.append(built.daemon.connections.get("mqtt", ""))
                await asyncio.sleep(0.05)

        watcher = asyncio.create_task(watch())
        retries = await _publish_all(
            mosquitto, messages,
            lambda: built.daemon.connections.get("mqtt", "").startswith("retrying"))
        await wait_until(
            lambda: built.stats.samples_in - built.stats.duplicates >= TOTAL - bad
            and built.stats.rejected >= bad, 20, "every message processed")
        watcher.cancel()
    seen = {(m["topic"], m["t"]) for m in sink["sample"]}
    rejected_payloads = {m["payload"] for m in sink["rejected"]}
    for topic, body in messages:
        if b"oops" in body:
            assert body.decode() in rejected_payloads
        else:
            assert (topic, json.loads(body)["t"]) in seen, f"lost {topic} {body!r}"
    # the broker really persisted its sessions, and the restart really happened
    # and that the daemon went through its backoff
    assert (mosquitto.workdir / "store" / "mosquitto.db").exists()
    assert any(s.startswith("retrying") for s in states), set(states)
    # a message re-sent over the restart arrives twice at most: counted, not double-processed
    extra_samples = len(sink["sample"]) - (TOTAL - bad)
    assert 0 <= extra_samples <= built.stats.duplicates + built.stats.out_of_order
    print(f"retries={retries} extra={extra_samples} duplicates={built.stats.duplicates} "
          f"out_of_order={built.stats.out_of_order} states={sorted(set(states))}")
    assert time.monotonic() - started < 40
    # nothing was lost, so nothing is counted lost or alarmed, whatever order it came in
    assert built.stats.seq_lost == 0
    assert not [a for a in sink["alarm"] if a["kind"] == "data_loss"], sink["alarm"]
