"""The daemon away 30 s while the rig publishes 80 messages/s, on two real brokers at once: the
shipped configuration (config/mosquitto/tdmon.conf) keeps every message; the same with a
queue of 100 messages loses most of them, and the daemon counts exactly how many from the
payloads' ``seq`` and raises ``data_loss`` alarms (one per jump in a counter, one per silence
in a channel's sampling)."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import paho.mqtt.client as mqtt
from daemon_support import make_config, running, wait_until

RATE = 80.0  # messages/s, all channels together
AWAY_S = 30.0
LIVE_S = 3.0  # published after the daemon is back: what follows the broker's queue
CHANNELS = (("hookload", "kN"), ("torque", "kN*m"), ("bit_depth", "m"))


def _config(port: int, folder: Path, client_id: str) -> Any:
    return make_config({"sources": {"mqtt": {"port": port, "client_id": client_id}}}, folder)


class Rig(threading.Thread):
    """Publishes one stream to several brokers at once, paced on the wall clock."""

    def __init__(self, ports: list[int], t0: float) -> None:
        super().__init__(daemon=True)
        self.t0 = t0
        self.clients = []
        for n, port in enumerate(ports):
            client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=f"outage-rig{n}")
            client.max_inflight_messages_set(200)
            client.connect("127.0.0.1", port)
            client.loop_start()
            self.clients.append(client)
        self.sent = 0
        self.stop_at: float | None = None
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            start = time.monotonic()
            i = 0
            while self.stop_at is None or time.monotonic() < self.stop_at:
                channel, unit = CHANNELS[i % 3]
                body = json.dumps({"t": self.t0 + i / RATE, "value": float(i), "unit": unit,
                                   "seq": i // 3 + 1})
                for client in self.clients:
                    client.publish(f"rig/T1/{channel}", body, qos=1)
                i += 1
                self.sent = i
                time.sleep(max(0.0, start + i / RATE - time.monotonic()))
        except BaseException as exc:  # reported by the test
            self.error = exc

    def close(self) -> None:
        for client in self.clients:
            client.loop_stop()
            client.disconnect()


async def test_daemon_away_30_s_at_80_per_s(
        shipped_mosquitto: Callable[..., Any], tmp_path: Path) -> None:
    good = shipped_mosquitto()
    tiny = shipped_mosquitto(max_queued_messages="100")
    configs = [_config(good.port, tmp_path, "tdmon-good"), _config(tiny.port, tmp_path,
                                                                    "tdmon-tiny")]
    for config in configs:  # the persistent sessions exist, then the daemon goes away
        async with running(config, connected=("mqtt",)):
            pass

    rig = Rig([good.port, tiny.port], time.time())
    rig.start()
    try:
        await asyncio.sleep(AWAY_S)
        async with (running(configs[0], connected=("mqtt",)) as (built_good, sink_good),
                    running(configs[1], connected=("mqtt",)) as (built_tiny, sink_tiny)):
            await asyncio.sleep(LIVE_S)
            rig.stop_at = time.monotonic()
            await asyncio.to_thread(rig.join, 30)
            published = rig.sent
            stats_good = built_good.daemon.pipeline.stats
            stats_tiny = built_tiny.daemon.pipeline.stats
            await wait_until(lambda: stats_good.samples_in >= published, 60,
                             "every message through the shipped broker")
            # the tiny broker's stream ends with the last live message
            await wait_until(lambda: any(json.loads(r["payload"])["value"] == published - 1
                                         for r in sink_tiny["raw"][-3:]), 60,
                             "the last message through the tiny broker")
    finally:
        rig.stop_at = time.monotonic()
        rig.join(30)
        rig.close()
    assert rig.error is None

    # shipped configuration: nothing lost, nothing counted as lost
    values = {json.loads(r["payload"])["value"] for r in sink_good["raw"]}
    assert values == {float(i) for i in range(published)}
    assert stats_good.seq_lost == 0 and stats_good.sampling_gaps == 0
    assert not [a for a in sink_good["alarm"] if a["kind"] == "data_loss"]

    # a queue of 100: the loss is exactly what the counters say, and alarmed
    received = {json.loads(r["payload"])["value"] for r in sink_tiny["raw"]}
    lost = published - len(received)
    print(f"published {published} at {RATE:g}/s, daemon away {AWAY_S:g} s: shipped config "
          f"lost {published - len(values)}; queue of 100 lost {lost}, counted "
          f"{stats_tiny.seq_lost} from seq, {stats_tiny.sampling_gaps} sampling gaps")
    assert lost > 1000
    assert stats_tiny.seq_lost == lost
    alarms = [a for a in sink_tiny["alarm"] if a["kind"] == "data_loss"]
    seq_alarms = [a for a in alarms if "never arrived" in a["message"]]
    gap_alarms = [a for a in alarms if a["message"].startswith("no ")]
    assert sum(a["value"] for a in seq_alarms) == lost
    assert len(seq_alarms) == 3  # one jump per topic
    assert len(gap_alarms) == 3 == stats_tiny.sampling_gaps  # one silence per channel
    status = built_tiny.daemon.pipeline.status_message({})
    assert status["seq_lost"] == lost and status["sampling_gaps"] == 3
