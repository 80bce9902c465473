"""Benchmark one daemon serving a fleet: 50 simulated rigs at 1 Hz x 12 channels in one process.

The fleet daemon runs as its own process (``python -m tdmon run`` on a ``[fleet]`` file: every
``rig/<name>`` is a rig from its first message, its well file ``wells/<name>.toml``, all links
to one well so that the rigs share its model), with the calibration on and a flight recording
per rig, as in production. This script plays the rigs (each sends its 12 channels once a
second, the rigs spread evenly over the second, hook load first) and the operations centre
(subscribes to every rig's results), over real Zenoh (peers on loopback) and optionally a
real mosquitto on a free loopback port.

    .venv/bin/python benchmarks/bench_fleet.py                        # Zenoh, 50 rigs, 120 s
    .venv/bin/python benchmarks/bench_fleet.py --transport mqtt --seconds 60
    .venv/bin/python benchmarks/bench_fleet.py --rigs 10 --seconds 30 --json out.json

Measures (targets from issue 16; the exit code is 1 when one is missed)
- latency: from publishing a rig's row (its hook load) to receiving that rig's ``model``
  result for the row, over every row after the warm-up (each rig's first frames build its
  pipeline): p50, p99, max [ms]; target p99 <= 100 ms
- memory: the daemon's RSS, sampled every 2 s: start, max, end [MB]; target max <= 1 GB
- losses: every published row has its ``model`` result, and each rig's last status counts all
  its samples, none rejected or dropped; target none lost
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from bench_daemon import Broker, DaemonProcess, free_port

#: A rig sent before the measured ones until the centre hears from it: the daemon is then
#: subscribed (a message sent before that would be lost with a clean MQTT session)
WARMUP_RIG = "rig/warmup"

ROOT = Path(__file__).resolve().parents[1]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
#: The 12 canonical channels, the unit each is sent in (hook load first: the worst case)
CHANNELS = {"hookload": "kN", "torque": "kN*m", "bit_depth": "m", "hole_depth": "m",
            "block_position": "m", "rpm": "rpm", "flow_in": "L/min", "spp": "bar", "wob": "kN",
            "mud_temp_in": "degC", "mud_temp_out": "degC", "mud_density": "kg/m**3"}


def values(i: int, rig: int) -> dict[str, float]:
    """Row ``i`` of rig ``rig``: tripping out at 0.3 m/s from its own depth (pick-up windows
    for the calibration), block travelling, mud circulating off."""
    bit_depth = 2500.0 + 10.0 * rig - 0.3 * i
    return {"hookload": 1150.0 + 0.05 * bit_depth + (i % 5), "torque": 0.5,
            "bit_depth": bit_depth, "hole_depth": 3000.0, "block_position": 5.0 + (0.3 * i) % 25,
            "rpm": 0.0, "flow_in": 0.0, "spp": 5.0, "wob": 0.0, "mud_temp_in": 30.0,
            "mud_temp_out": 45.0, "mud_density": 1200.0}


class FleetDaemon(DaemonProcess):
    """``tdmon run`` on a fleet file."""

    stop_timeout = 120.0  # [s]: 50 rigs flush their recordings

    def __init__(self, folder: Path, transport: str, port: int, rigs: int,
                 record: bool = True) -> None:
        wells = folder / "wells"
        wells.mkdir()
        for n in range(rigs):
            (wells / f"R{n:02d}.toml").symlink_to(WELL)
        if transport == "mqtt":
            source = (f'[sources.mqtt]\nport = {port}\nclient_id = "fleet-{time.time_ns()}"\n'
                      "clean_session = true\nqos = 1\n[publish]\nmqtt = true\nqos = 0\n")
        else:
            source = (f'[sources.zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                      "[publish]\nzenoh = true\n")
        config = folder / f"fleet-{transport}.toml"
        config.write_text(
            f'prefix = "rig"\nwell = "{WELL}"\n{source}'
            'names = ["state", "model", "estimate", "alarm", "status"]\n'
            'status_interval = "1 s"\n'
            f'[fleet]\nwells = "wells"\nmax_rigs = {rigs + 1}\n'
            f'[recorder]\nenabled = {str(record).lower()}\noutput = "{folder / "recordings"}"\n'
            '[align]\nstale_timeout = "5 s"\n'
            '[calibration]\nenabled = true\n'
            + "".join(f'[channels.{c}]\nunit = "{u}"\n' for c, u in CHANNELS.items()))
        self._start(config, folder / f"fleet-{transport}.log")


class Centre:
    """The operations centre: the receive time of every ``model`` result, the last status."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.models: dict[tuple[str, float], float] = {}
        self.status: dict[str, dict[str, Any]] = {}

    def on_result(self, topic: str, payload: bytes) -> None:
        received = time.time()
        rig, _, name = topic.rpartition("/tdmon/")
        if name not in ("model", "status"):
            return
        message = json.loads(payload)
        with self.lock:
            if name == "model":
                self.models[(rig, round(message["t"], 6))] = received
            else:
                self.status[rig] = message


def zenoh_link(port: int, centre: Centre) -> tuple[Any, Any]:
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    deadline = time.monotonic() + 60
    while True:
        try:
            session = zenoh.open(conf)
            break
        except zenoh.ZError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
    session.declare_subscriber(
        "rig/*/tdmon/**", lambda s: centre.on_result(str(s.key_expr), s.payload.to_bytes()))
    block = zenoh.CongestionControl.BLOCK

    def send(topic: str, payload: bytes) -> None:
        session.put(topic, payload, congestion_control=block)

    while not list(session.info.peers_zid()):
        time.sleep(0.1)
    return session, send


def mqtt_link(port: int, centre: Centre) -> tuple[Any, Any]:
    import paho.mqtt.client as paho

    def on_message(client: Any, userdata: Any, message: Any) -> None:
        centre.on_result(message.topic, message.payload)

    listener = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="fleet-centre")
    listener.on_message = on_message
    listener.connect("127.0.0.1", port)
    listener.subscribe("rig/+/tdmon/#", qos=0)
    listener.loop_start()
    publisher = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="fleet-rigs")
    publisher.max_inflight_messages_set(1000)
    publisher.connect("127.0.0.1", port)
    for client in (publisher, listener):  # as the daemon's own connections: no Nagle delay
        client.socket().setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    publisher.loop_start()

    def send(topic: str, payload: bytes) -> None:
        publisher.publish(topic, payload, qos=1)

    class Both:
        def close(self) -> None:
            for client in (publisher, listener):
                client.loop_stop()
                client.disconnect()

    return Both(), send


def run(transport: str, rigs: int, seconds: float, warmup: float,  # noqa: C901  (complex today; simplify when next touched)
        record: bool = True) -> dict[str, Any]:
    folder = Path(tempfile.mkdtemp(prefix="bench-fleet-"))
    broker = Broker(folder) if transport == "mqtt" else None
    port = broker.port if broker is not None else free_port()
    daemon = FleetDaemon(folder, transport, port, rigs, record)
    centre = Centre()
    link, send = (mqtt_link if transport == "mqtt" else zenoh_link)(port, centre)
    deadline = time.monotonic() + 120
    while WARMUP_RIG not in centre.status:  # the daemon is up and subscribed
        if time.monotonic() > deadline:
            raise RuntimeError("the fleet daemon did not answer in 120 s")
        t = time.time()
        for channel, unit in CHANNELS.items():
            send(f"{WARMUP_RIG}/{channel}",
                 json.dumps({"t": t, "value": values(0, 0)[channel], "unit": unit}).encode())
        time.sleep(0.5)
    published: dict[tuple[str, float], float] = {}
    load_before = os.getloadavg()[0]  # the machine is shared: say how busy it was
    rss: list[float] = [daemon.rss_mb()]
    start = time.time()
    next_rss = time.monotonic() + 2.0
    rows = int(seconds)
    try:
        for i in range(rows):
            second = start + i
            for n in range(rigs):
                at = second + n / rigs  # the rigs spread over the second
                delay = at - time.time()
                if delay > 0:
                    time.sleep(delay)
                rig = f"rig/R{n:02d}"
                t = round(time.time(), 6)
                row = values(i, n)
                published[(rig, t)] = time.time()
                for channel, unit in CHANNELS.items():
                    send(f"{rig}/{channel}",
                         json.dumps({"t": t, "value": row[channel], "unit": unit}).encode())
            if time.monotonic() >= next_rss:
                next_rss += 2.0
                rss.append(daemon.rss_mb())
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            with centre.lock:
                if all(key in centre.models for key in published):
                    break
            time.sleep(0.2)
        rss.append(daemon.rss_mb())
        time.sleep(1.5)  # one more status from every rig
    finally:
        daemon.stop()
        link.close()
        if broker is not None:
            broker.stop()
    latencies = sorted((centre.models[key] - sent) * 1e3 for key, sent in published.items()
                       if key in centre.models and sent - start >= warmup)
    missing = sum(1 for key in published if key not in centre.models)
    statuses = {rig: s for rig, s in centre.status.items() if rig != WARMUP_RIG}
    samples = {rig: s.get("samples_in") for rig, s in statuses.items()}
    expected_samples = rows * len(CHANNELS)
    short = {rig: n for rig, n in samples.items() if n != expected_samples}
    p99 = statistics.quantiles(latencies, n=100)[98] if len(latencies) >= 100 else max(latencies)
    return {
        "transport": transport, "rigs": rigs, "rate_hz": 1, "channels": len(CHANNELS),
        "seconds": rows, "rows_published": len(published), "models_missing": missing,
        "rigs_reporting": len(statuses), "rigs_short_of_samples": short,
        "rejected": sum(int(s.get("rejected", 0)) for s in statuses.values()),
        "dropped": sum(int(s.get("dropped", 0)) for s in statuses.values()),
        "latency_ms": {"rows": len(latencies), "p50": round(statistics.median(latencies), 1),
                       "p99": round(p99, 1), "max": round(latencies[-1], 1)},
        "rss_mb": {"start": round(rss[0], 1), "max": round(max(rss), 1),
                   "end": round(rss[-1], 1)},
        "load_average_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "recording_folders": (sum(1 for _ in (folder / "recordings").iterdir())
                              if record else 0),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--transport", choices=["zenoh", "mqtt", "both"], default="zenoh")
    parser.add_argument("--rigs", type=int, default=50)
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--warmup", type=float, default=10.0,
                        help="rows sent in the first seconds are left out of the latency")
    parser.add_argument("--no-recorder", action="store_true",
                        help="without the flight recordings (to see what they cost)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    transports = ["zenoh", "mqtt"] if args.transport == "both" else [args.transport]
    results = [run(t, args.rigs, args.seconds, args.warmup, not args.no_recorder)
               for t in transports]
    text = json.dumps(results, indent=2)
    print(text)
    if args.json:
        args.json.write_text(text)
    ok = all(r["latency_ms"]["p99"] <= 100 and r["rss_mb"]["max"] <= 1024
             and r["models_missing"] == 0 and not r["rigs_short_of_samples"]
             and r["rigs_reporting"] == args.rigs and r["rejected"] == 0 and r["dropped"] == 0
             for r in results)
    print("targets met" if ok else "TARGET MISSED", file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
