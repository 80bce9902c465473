"""Benchmark the live daemon on loopback: latency, throughput, memory over a soak.

The daemon runs as its own process (``python -m tdmon run``), as in production; this script
plays the rig (publishes) and the dashboard (subscribes to the results) over real MQTT
(a mosquitto it starts on a free loopback port with the shipped rig configuration,
config/mosquitto/tdmon.conf, only its port and persistence folder changed) and real Zenoh
(peer mode, loopback). The daemon records everything with its flight recorder, as on a rig;
by default each transport is then measured again with the recorder off, in the same run, for
the comparison (``--recorder on`` skips that, ``off`` measures only without it).

    .venv/bin/python benchmarks/bench_daemon.py                       # everything, 10 min soak
    .venv/bin/python benchmarks/bench_daemon.py --soak-seconds 60     # shorter soak
    .venv/bin/python benchmarks/bench_daemon.py --transport zenoh --skip-soak

Measures
- latency: 10 Hz x 8 channels; time from publishing a row's hook load to receiving the
  daemon's ``model`` result for it (p50, p99, max) [ms]
- throughput: N samples as fast as the publisher can send (8 channels); samples/s until the
  daemon's status reports all N processed, and that none was rejected or dropped
- soak: 10 Hz x 8 channels for --soak-seconds; the daemon's RSS sampled every 5 s
- with the recorder: samples and messages in the recording (read back from the files'
  summaries after the daemon stopped), and recorded bytes per input sample
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import aiomqtt
import zenoh

ROOT = Path(__file__).resolve().parents[1]
BROKER_CONF = ROOT / "config" / "mosquitto" / "tdmon.conf"
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
CHANNELS = ("hookload", "torque", "bit_depth", "hole_depth", "rpm", "flow_in", "spp", "wob")
PREFIX = "rig/B1"
#: QoS 1 messages the MQTT publisher keeps unacknowledged at most
MQTT_WINDOW = 1000


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def row(t: float, i: int) -> list[tuple[str, bytes]]:
    """One row of the 8 channels at time t (hook load first, as the worst case)."""
    bit_depth = 2000.0 + 0.01 * i
    values = {"hookload": 1100.0 + (i % 7), "torque": 15.0, "bit_depth": bit_depth,
              "hole_depth": 4000.0, "rpm": 0.0, "flow_in": 0.0, "spp": 10.0, "wob": 0.0}
    units = {"hookload": "kN", "torque": "kN*m", "bit_depth": "m", "hole_depth": "m",
             "rpm": "rpm", "flow_in": "L/min", "spp": "bar", "wob": "kN"}
    return [(f"{PREFIX}/{c}",
             json.dumps({"t": t, "value": values[c], "unit": units[c]}).encode())
            for c in CHANNELS]


class Broker:
    def __init__(self, folder: Path) -> None:
        self.port = free_port()
        folder.chmod(0o755)
        conf = folder / "mosquitto.conf"
        store = folder / f"mosquitto-store-{self.port}"
        store.mkdir()
        store.chmod(0o777)  # mosquitto drops to its own user when started as root
        lines = []
        for line in BROKER_CONF.read_text().splitlines():
            if line.startswith("listener 1883 "):
                line = f"listener {self.port} 127.0.0.1"
            elif line.startswith("persistence_location "):
                line = f"persistence_location {store}/"
            elif line.startswith(("log_dest", "log_type", "connection_messages")):
                continue
            lines.append(line)
        conf.write_text("\n".join(lines) + "\n")
        self.process = subprocess.Popen([shutil.which("mosquitto") or "/usr/sbin/mosquitto",
                                         "-c", str(conf)], stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 10
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), 0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    def stop(self) -> None:
        self.process.send_signal(signal.SIGTERM)
        self.process.wait(10)


class DaemonProcess:
    """``tdmon run`` on a daemon file in a subprocess, with its RSS readable from /proc."""

    stop_timeout = 60.0  # [s]

    def _start(self, config: Path, log: Path, tree: Path = ROOT) -> None:
        """Start ``tdmon run`` with the tdmon package of ``tree`` (a source tree: this one, or
        an older one to compare with)."""
        self.log = log
        self.stream = log.open("w")
        env = {**os.environ, "PYTHONPATH": str(tree)}
        self.process = subprocess.Popen(
            [sys.executable, "-m", "tdmon", "run", "--config", str(config),
             "--log-level", "warning"], stderr=self.stream, cwd=tree, env=env)

    def rss_mb(self) -> float:
        for line in Path(f"/proc/{self.process.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def stop(self) -> str:
        self.process.send_signal(signal.SIGTERM)
        code = self.process.wait(self.stop_timeout)
        self.stream.close()
        text = self.log.read_text()
        if code != 0:
            raise RuntimeError(f"daemon exited {code}: {text}")
        return text


class Daemon(DaemonProcess):
    """The benchmark's one-rig daemon."""

    def __init__(self, folder: Path, transport: str, port: int, recorder: bool,
                 tree: Path = ROOT, label: str = "") -> None:
        if transport == "mqtt":
            source = (f'[sources.mqtt]\nport = {port}\nclient_id = "bench-{time.time_ns()}"\n'
                      "clean_session = true\n[publish]\nmqtt = true\nqos = 0\n")
        else:
            source = (f'[sources.zenoh]\nlisten = ["tcp/127.0.0.1:{port}"]\n'
                      "[publish]\nzenoh = true\n")
        self.recordings = folder / f"recordings-{transport}-{'on' if recorder else 'off'}{label}"
        recording = (f'[recorder]\nenabled = true\noutput = "{self.recordings}"\n'
                     if recorder else "")
        config = folder / f"daemon-{transport}{label}.toml"
        config.write_text(f'prefix = "{PREFIX}"\nwell = "{WELL}"\n{source}'
                          'names = ["model", "status"]\nstatus_interval = "0.1 s"\n'
                          "[queues]\ningest = 20000\npublish = 200000\n"
                          # the channel map: the first frame waits for all eight channels
                          + "".join(f"[channels.{c}]\n" for c in CHANNELS)
                          + '[monitor]\nmethod = "aadnoy"\n' + recording)
        self._start(config, folder / f"daemon-{transport}{label}.log", tree)
        time.sleep(0.2)


class Rig:
    """Publisher and result subscriber over one transport."""

    def __init__(self) -> None:
        self.models: list[tuple[float, dict[str, Any]]] = []
        self.status: dict[str, Any] = {}
        self.send: Callable[[str, bytes], Awaitable[None]]
        #: send pre-encoded messages as fast as the transport takes them
        self.send_many: Callable[[list[tuple[str, bytes]]], Awaitable[None]]
        self.last_t = 0.0

    def next_t(self, step: float) -> float:
        """Data time of the next row: now, but never before the previous row (the daemon
        would rightly count an older row as out of order and make no frame of it)."""
        self.last_t = max(time.time(), self.last_t + step)
        return self.last_t

    def on_result(self, topic: str, payload: bytes) -> None:
        message = json.loads(payload)
        if topic.endswith("/model"):
            self.models.append((time.time(), message))
        elif topic.endswith("/status"):
            self.status = message


async def with_mqtt(port: int, body: Callable[[Rig], Awaitable[dict[str, Any]]]
                    ) -> dict[str, Any]:
    """The dashboard is an aiomqtt client; the rig publishes with paho's own network thread
    (QoS 1), because an asyncio publisher in this same process tops out near the 5,000
    messages/s we want to show the daemon can take.

    The publisher keeps at most ``WINDOW`` messages unacknowledged by counting PUBACKs itself,
    with paho's own in-flight limit off: paho walks every message it holds on each PUBACK when
    that limit is set (``_update_inflight``), which cost this script more CPU than the daemon
    spent at 5,000 messages/s."""
    import paho.mqtt.client as paho

    rig = Rig()
    publisher = paho.Client(paho.CallbackAPIVersion.VERSION2, client_id="bench-rig")
    publisher.max_inflight_messages_set(0)  # no limit in paho: the window is ours
    acked = [0]

    def on_publish(*_: Any) -> None:
        acked[0] += 1  # paho's network thread; an int store is atomic

    publisher.on_publish = on_publish
    publisher.connect("127.0.0.1", port)
    publisher.socket().setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    publisher.loop_start()
    sent = [0]

    def publish(topic: str, payload: bytes) -> None:
        info = publisher.publish(topic, payload, qos=1)
        if info.rc != paho.MQTT_ERR_SUCCESS:
            raise RuntimeError(f"publish failed: {info.rc}")
        sent[0] += 1

    async def send(topic: str, payload: bytes) -> None:
        publish(topic, payload)

    async def send_many(messages: list[tuple[str, bytes]]) -> None:
        for topic, payload in messages:
            while sent[0] - acked[0] >= MQTT_WINDOW:
                await asyncio.sleep(0.0005)
            publish(topic, payload)

    rig.send = send
    rig.send_many = send_many
    try:
        nodelay = [(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)]
        async with aiomqtt.Client("127.0.0.1", port, identifier="bench-dash",
                                  socket_options=nodelay) as dash:
            await dash.subscribe(f"{PREFIX}/tdmon/#", qos=0)

            async def listen() -> None:
                async for message in dash.messages:
                    assert isinstance(message.payload, bytes)
                    rig.on_result(str(message.topic), message.payload)

            listener = asyncio.create_task(listen())
            try:
                await asyncio.sleep(0.5)
                return await body(rig)
            finally:
                listener.cancel()
    finally:
        deadline = time.monotonic() + 10
        while acked[0] < sent[0] and time.monotonic() < deadline:
            time.sleep(0.01)
        publisher.loop_stop()
        publisher.disconnect()


async def with_zenoh(port: int, body: Callable[[Rig], Awaitable[dict[str, Any]]]
                     ) -> dict[str, Any]:
    rig = Rig()
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(conf)
    loop = asyncio.get_running_loop()
    subscriber = session.declare_subscriber(
        f"{PREFIX}/tdmon/**",
        lambda s: loop.call_soon_threadsafe(rig.on_result, str(s.key_expr),
                                            s.payload.to_bytes()))
    publishers = {c: session.declare_publisher(
        f"{PREFIX}/{c}", congestion_control=zenoh.CongestionControl.BLOCK) for c in CHANNELS}

    async def send(topic: str, payload: bytes) -> None:
        publishers[topic.rsplit("/", 1)[1]].put(payload)

    async def send_many(messages: list[tuple[str, bytes]]) -> None:
        by_topic = {f"{PREFIX}/{c}": publishers[c] for c in CHANNELS}
        for i, (topic, payload) in enumerate(messages):
            by_topic[topic].put(payload)  # blocks while the daemon holds zenoh back
            if i % 4096 == 4095:
                await asyncio.sleep(0)  # let the dashboard's results in

    rig.send = send
    rig.send_many = send_many
    try:
        deadline = time.monotonic() + 10
        while not list(session.info.peers_zid()) and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.5)
        return await body(rig)
    finally:
        subscriber.undeclare()
        session.close()


async def latency(rig: Rig, seconds: float) -> dict[str, Any]:
    rig.models.clear()
    sent: dict[float, float] = {}
    start = time.monotonic()
    i = 0
    while time.monotonic() - start < seconds:
        t = rig.next_t(0.1)
        sent[round(t, 6)] = time.time()
        for topic, payload in row(t, i):
            await rig.send(topic, payload)
        i += 1
        await asyncio.sleep(max(0.0, start + i * 0.1 - time.monotonic()))
    await asyncio.sleep(1.0)
    delays = sorted((received - sent[round(m["t"], 6)]) * 1e3 for received, m in rig.models
                    if round(m["t"], 6) in sent)
    return {"rows": i, "results": len(delays),
            "p50_ms": round(statistics.median(delays), 2),
            "p99_ms": round(delays[min(len(delays) - 1, int(0.99 * len(delays)))], 2),
            "max_ms": round(delays[-1], 2)}


async def throughput(rig: Rig, samples: int) -> dict[str, Any]:
    await asyncio.sleep(0.3)
    base = int(rig.status.get("samples_in", 0))
    rows = samples // len(CHANNELS)
    # the rig's messages, encoded before the clock starts: the script plays a rig, whose own
    # cost is not the daemon's. 10 us apart: a publisher faster than real time must not take
    # the rig clock more than the daemon's future tolerance (10 s) ahead of the wall clock, or
    # the clock guard rightly rejects the rows (at 1 ms apart 50 000 rows sent in 5 s ran 45 s
    # ahead)
    messages = [message for i in range(rows) for message in row(rig.next_t(1e-5), i)]
    started = time.perf_counter()
    await rig.send_many(messages)
    sent_s = time.perf_counter() - started
    total = rows * len(CHANNELS)
    deadline = time.monotonic() + 300
    seen, moved = -1, time.perf_counter()
    while (now_in := int(rig.status.get("samples_in", 0))) - base < total:
        if now_in != seen:
            seen, moved = now_in, time.perf_counter()
        if time.monotonic() > deadline or time.perf_counter() - moved > 10:
            break  # lost or rejected: the count will not grow any more
        await asyncio.sleep(0.02)
    elapsed = (time.perf_counter() if now_in - base >= total else moved) - started
    processed = int(rig.status.get("samples_in", 0)) - base
    return {"samples": total, "processed": processed, "seconds": round(elapsed, 2),
            "publish_seconds": round(sent_s, 2),
            "samples_per_s": round(processed / elapsed),
            "rejected": rig.status.get("rejected"), "dropped": rig.status.get("dropped"),
            "lost": total - processed}


async def soak(rig: Rig, daemon: Daemon, seconds: float) -> dict[str, Any]:
    rss: list[tuple[float, float]] = []
    start = time.monotonic()
    next_sample = start
    i = 0
    while time.monotonic() - start < seconds:
        if time.monotonic() >= next_sample:
            rss.append((round(time.monotonic() - start, 1), round(daemon.rss_mb(), 1)))
            next_sample += 5.0
            rig.models.clear()  # the bench must not be what grows
        t = rig.next_t(0.1)
        for topic, payload in row(t, i):
            await rig.send(topic, payload)
        i += 1
        await asyncio.sleep(max(0.0, start + i * 0.1 - time.monotonic()))
    rss.append((round(time.monotonic() - start, 1), round(daemon.rss_mb(), 1)))
    # judge flatness after warm-up (first 20 % of the run)
    settled = [m for s, m in rss if s >= 0.2 * seconds] or [rss[-1][1]]
    return {"seconds": seconds, "rows": i, "rss_start_mb": rss[0][1],
            "rss_after_warmup_mb": settled[0], "rss_end_mb": rss[-1][1],
            "rss_max_mb": max(m for _, m in rss),
            "growth_after_warmup_mb": round(rss[-1][1] - settled[0], 1)}


def recorded(folder: Path) -> dict[str, Any]:
    """What the daemon's recorder kept: messages per topic from the files' summaries."""
    from tdmon.record.reader import topic_counts

    counts: dict[str, int] = {}
    files = sorted(folder.glob("*.mcap"))
    for path in files:
        for topic, n in topic_counts(path).items():
            counts[topic] = counts.get(topic, 0) + n
    return {"files": len(files), "bytes": sum(p.stat().st_size for p in files),
            "samples": counts.get("/tdmon/sample", 0), "raw": counts.get("/tdmon/raw", 0),
            "messages": sum(counts.values())}


def run_transport(transport: str, args: argparse.Namespace, folder: Path,
                  recorder: bool, tree: Path = ROOT, name: str = "", run: int = 0
                  ) -> dict[str, Any]:
    broker = Broker(folder) if transport == "mqtt" else None
    port = broker.port if broker else free_port()
    daemon = Daemon(folder, transport, port, recorder, tree, f"-{name or 'this'}-{run}")
    label = f"{transport} (recorder {'on' if recorder else 'off'}{', ' + name if name else ''})"
    deadline = time.monotonic() + 30
    while "model for" not in daemon.log.read_text() and time.monotonic() < deadline:
        time.sleep(0.1)  # warning log level: wait for the process instead
        if daemon.process.poll() is not None:
            raise RuntimeError(daemon.log.read_text())
        if time.monotonic() > deadline - 28:
            break
    time.sleep(2.0)
    samples = args.mqtt_samples if transport == "mqtt" else args.zenoh_samples

    async def body(rig: Rig) -> dict[str, Any]:
        # the daemon is up once its status arrives (it also has to subscribe first)
        deadline = time.monotonic() + 60
        while not rig.status and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        out: dict[str, Any] = {}
        out["latency"] = await latency(rig, args.latency_seconds)
        print(label, "latency", out["latency"], flush=True)
        out["throughput"] = await throughput(rig, samples)
        print(label, "throughput", out["throughput"], flush=True)
        if not args.skip_soak:
            out["soak"] = await soak(rig, daemon, args.soak_seconds)
            print(label, "soak", out["soak"], flush=True)
        return out

    try:
        runner = with_mqtt if transport == "mqtt" else with_zenoh
        result = asyncio.run(runner(port, body))
    finally:
        log = daemon.stop()
        if broker:
            broker.stop()
    result["daemon_exit_summary"] = log.strip().splitlines()[-1] if log.strip() else ""
    if recorder:
        result["recording"] = kept = recorded(daemon.recordings)
        print(label, "recording", kept, flush=True)
    return result


def summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Throughput per (tree, recorder) over the rounds: every figure, and the best."""
    out: dict[str, Any] = {}
    for run in runs:
        key = f"{run['tree']}, recorder {run['recorder']}"
        out.setdefault(key, []).append(run["throughput"]["samples_per_s"])
    return {key: {"samples_per_s": rates, "best": max(rates)} for key, rates in out.items()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--transport", choices=["mqtt", "zenoh", "both"], default="both")
    parser.add_argument("--latency-seconds", type=float, default=30.0)
    parser.add_argument("--mqtt-samples", type=int, default=80_000)
    parser.add_argument("--zenoh-samples", type=int, default=400_000)
    parser.add_argument("--soak-seconds", type=float, default=600.0)
    parser.add_argument("--skip-soak", action="store_true")
    parser.add_argument("--recorder", choices=["on", "off", "both"], default="both",
                        help="the daemon records (on, as on a rig), or not (off); both: on, "
                             "then off for the comparison (default)")
    parser.add_argument("--baseline-tree", type=Path,
                        help="also run the daemon from this source tree (e.g. a `git archive` "
                             "of an older commit), alternating with this one, for a side by "
                             "side comparison")
    parser.add_argument("--rounds", type=int, default=1,
                        help="measure everything this many times, alternating")
    parser.add_argument("--json", type=Path, help="write the results here")
    args = parser.parse_args()
    results: dict[str, Any] = {"cpus": os.cpu_count()}
    trees = [("this", ROOT)]
    if args.baseline_tree:
        trees.insert(0, ("baseline", args.baseline_tree.resolve()))
    with tempfile.TemporaryDirectory(prefix="tdmon-bench-") as tmp:
        modes = {"on": [True], "off": [False], "both": [True, False]}[args.recorder]
        for transport in (["mqtt", "zenoh"] if args.transport == "both" else [args.transport]):
            runs = []
            for run in range(args.rounds):
                for name, tree in trees:
                    for recorder in modes:
                        result = run_transport(transport, args, Path(tmp), recorder, tree,
                                               name if args.baseline_tree else "", run)
                        runs.append({"tree": name, "recorder": "on" if recorder else "off",
                                     "round": run, **result})
            results[transport] = {"runs": runs, "summary": summary(runs)}
            for key, figures in results[transport]["summary"].items():
                print(f"{transport}, {key}: {figures['samples_per_s']} samples/s", flush=True)
    print(json.dumps(results, indent=2))
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
