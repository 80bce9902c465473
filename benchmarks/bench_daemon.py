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
    .venv/bin/python benchmarks/bench_daemon.py --skip-soak --baseline-tree /tmp/base --rounds 2

``--baseline-tree`` runs the daemon also from another source tree (``git archive`` of an older
commit), alternating with this one round after round, against the same rig and dashboard.
The rig's messages are encoded before the throughput clock starts, and sent as fast as the
transport takes them: Zenoh ``put`` in a loop, MQTT raw QoS 1 packets (:class:`RigPublisher`)
with at most 1000 unacknowledged; one sample per message, as the payload contract says.

Measures
- throughput: N samples as fast as the publisher can send (8 channels); samples/s until the
  daemon's status reports all N processed, and that none was rejected or dropped; then the
  seconds until the last row's ``model`` result reached the dashboard. The rows'
  rig times are ``--row-interval`` apart (default 0.1 s, a rig's 10 Hz) and end before the
  run starts: a backlog such as a broker delivers after an outage. The steps' time windows
  (e.g. the rig state's torque average over 5 s) then hold what they would on a rig; rows
  10 us apart, as before, put the whole run into one window (``--row-interval 1e-5``)
- latency: 10 Hz x 8 channels, after the throughput and its last result (whose rig times lie
  before it); time
  from publishing a row's hook load to receiving the daemon's ``model`` result for it
  (p50, p99, max) [ms]
- soak: 10 Hz x 8 channels for --soak-seconds; the daemon's RSS sampled every 5 s
- with the recorder: samples and messages in the recording (read back from the files'
  summaries after the daemon stopped), and recorded bytes per input sample
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import math
import os
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
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

    def cpu_s(self) -> float:
        """CPU time (user + system) of the daemon process so far [s], all its threads."""
        fields = Path(f"/proc/{self.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

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


def _remaining_length(n: int) -> bytes:
    """MQTT's variable-length integer."""
    out = bytearray()
    while True:
        n, digit = divmod(n, 128)
        out.append(digit | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _mqtt_string(text: str) -> bytes:
    data = text.encode()
    return len(data).to_bytes(2, "big") + data


class RigPublisher:
    """The rig's MQTT 3.1.1 publisher: QoS 1 PUBLISH packets written on a plain socket, a thread
    counting the broker's PUBACKs, at most ``window`` messages unacknowledged.

    A publisher of the protocol's few bytes rather than paho: paho's publisher, sharing the two
    cores with the broker and the daemon, spent ~60 us of CPU per message (three ``recv`` calls
    and several objects per PUBACK, and with its in-flight limit on, a walk over every message
    it holds per PUBACK), more than half the daemon's own cost. The messages on the wire are
    the same: one sample per PUBLISH, QoS 1.
    """

    def __init__(self, port: int, window: int = 1000) -> None:
        self.window = window
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        variable = _mqtt_string("MQTT") + bytes([4, 0x02]) + (0).to_bytes(2, "big")  # clean
        body = variable + _mqtt_string(f"bench-rig-{time.time_ns()}")  # session, no keep-alive
        self.sock.sendall(b"\x10" + _remaining_length(len(body)) + body)
        connack = self.sock.recv(4)
        if len(connack) != 4 or connack[0] != 0x20 or connack[3] != 0:
            raise RuntimeError(f"broker refused the rig publisher: {connack!r}")
        self.sent = 0
        self.acked = 0  # written by the reader thread only (an int store is atomic)
        self._mid = 0
        self._reader = threading.Thread(target=self._read_acks, daemon=True)
        self._reader.start()

    def packet(self, topic: str, payload: bytes) -> bytes:
        self._mid = self._mid % 65535 + 1  # 1..65535; the window keeps reuse far apart
        body = _mqtt_string(topic) + self._mid.to_bytes(2, "big") + payload
        return b"\x32" + _remaining_length(len(body)) + body  # PUBLISH, QoS 1

    def write(self, packets: list[bytes]) -> None:
        self.sock.sendall(b"".join(packets))
        self.sent += len(packets)

    def _read_acks(self) -> None:
        pending = b""
        while True:
            try:
                data = self.sock.recv(65536)
            except OSError:
                return
            if not data:
                return
            pending += data
            # only PUBACKs come to a client that subscribes to nothing: 4 bytes each
            whole = len(pending) // 4
            if any(pending[4 * i] != 0x40 for i in range(whole)):
                raise RuntimeError("unexpected packet from the broker")
            self.acked += whole
            pending = pending[4 * whole:]

    async def send_many(self, messages: list[tuple[str, bytes]], chunk: int = 64) -> None:
        for start in range(0, len(messages), chunk):
            part = [self.packet(topic, payload)
                    for topic, payload in messages[start:start + chunk]]
            while self.sent + len(part) - self.acked > self.window:
                await asyncio.sleep(0.0005)
            self.write(part)

    def close(self) -> None:
        deadline = time.monotonic() + 10
        while self.acked < self.sent and time.monotonic() < deadline:
            time.sleep(0.01)
        with contextlib.suppress(OSError):
            self.sock.sendall(b"\xe0\x00")  # DISCONNECT
        self.sock.close()


async def with_mqtt(port: int, body: Callable[[Rig], Awaitable[dict[str, Any]]]
                    ) -> dict[str, Any]:
    """The dashboard is an aiomqtt client; the rig is a :class:`RigPublisher`."""
    rig = Rig()
    publisher = RigPublisher(port, MQTT_WINDOW)

    async def send(topic: str, payload: bytes) -> None:
        publisher.write([publisher.packet(topic, payload)])

    rig.send = send
    rig.send_many = publisher.send_many
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
        publisher.close()


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


async def throughput(rig: Rig, samples: int,
                     cpu_s: Callable[[], float] = lambda: math.nan,
                     interval: float = 0.1) -> dict[str, Any]:
    """``cpu_s``: the daemon's CPU time so far [s] (its CPU per sample is the steadier figure
    on a shared machine); ``interval``: rig time between rows [s]."""
    await asyncio.sleep(0.3)
    base = int(rig.status.get("samples_in", 0))
    rows = samples // len(CHANNELS)
    # the rig's messages, encoded before the clock starts: the script plays a rig, whose own
    # cost is not the daemon's. Their rig times end before now: sent faster than real time,
    # rows stamped from now on would take the rig clock beyond the daemon's future tolerance
    # (10 s) and the clock guard would rightly reject them
    first = time.time() - rows * interval - 1.0
    messages = [message for i in range(rows) for message in row(first + i * interval, i)]
    started = time.perf_counter()
    cpu_before = cpu_s()
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
    cpu = cpu_s() - cpu_before
    processed = int(rig.status.get("samples_in", 0)) - base
    results_s = await last_result(rig, round(first + (rows - 1) * interval, 6), started)
    return {"samples": total, "processed": processed, "seconds": round(elapsed, 2),
            "publish_seconds": round(sent_s, 2),
            "results_seconds": None if results_s is None else round(results_s, 2),
            "samples_per_s": round(processed / elapsed),
            "daemon_cpu_us_per_sample": round(cpu / max(processed, 1) * 1e6, 1),
            "rejected": rig.status.get("rejected"), "dropped": rig.status.get("dropped"),
            "lost": total - processed}


async def last_result(rig: Rig, t: float, started: float, timeout: float = 60.0
                      ) -> float | None:
    """Seconds from ``started`` (perf_counter) until the dashboard has the ``model`` result of
    the row at rig time ``t`` (None: not within ``timeout``). The daemon's status counts a
    sample once processed; its results may still be on their way, and the next measurement
    should not wait behind them."""
    deadline = time.monotonic() + timeout
    checked = 0
    while time.monotonic() < deadline:
        models = rig.models
        if any(round(m["t"], 6) == t for _, m in models[checked:]):
            return time.perf_counter() - started
        checked = len(models)
        await asyncio.sleep(0.02)
    return None


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
        # the throughput first: its rows' rig times lie in the past, and a row older than
        # the latency's would be out of order
        out["throughput"] = await throughput(rig, samples, daemon.cpu_s, args.row_interval)
        print(label, "throughput", out["throughput"], flush=True)
        out["latency"] = await latency(rig, args.latency_seconds)
        print(label, "latency", out["latency"], flush=True)
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
    """Throughput per (tree, recorder) over the rounds: every figure, and the best; with a
    baseline tree, this tree's samples/s over the baseline's, round by round (the two ran
    one after the other, under about the same load)."""
    out: dict[str, Any] = {}
    for run in runs:
        key = f"{run['tree']}, recorder {run['recorder']}"
        out.setdefault(key, []).append((run["throughput"]["samples_per_s"],
                                        run["throughput"]["daemon_cpu_us_per_sample"]))
    result: dict[str, Any] = {
        key: {"samples_per_s": [rate for rate, _ in runs],
              "best": max(rate for rate, _ in runs),
              "daemon_cpu_us_per_sample": [cpu for _, cpu in runs]}
        for key, runs in out.items()}
    for recorder in ("on", "off"):
        this, base = out.get(f"this, recorder {recorder}"), out.get(
            f"baseline, recorder {recorder}")
        if this and base:
            result[f"this / baseline, recorder {recorder}"] = {
                "samples_per_s": [round(a / b, 3) if b else None
                                  for (a, _), (b, _) in zip(this, base, strict=True)],
                "daemon_cpu_us_per_sample": [round(a / b, 3) if b else None
                                             for (_, a), (_, b) in zip(this, base, strict=True)]}
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--transport", choices=["mqtt", "zenoh", "both"], default="both")
    parser.add_argument("--latency-seconds", type=float, default=30.0)
    parser.add_argument("--mqtt-samples", type=int, default=80_000)
    parser.add_argument("--zenoh-samples", type=int, default=400_000)
    parser.add_argument("--row-interval", type=float, default=0.1,
                        help="rig time between the throughput's rows [s] (default 0.1: 10 Hz)")
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
                unit = " (ratio)" if "/" in key else ""
                print(f"{transport}, {key}: {figures['samples_per_s']} samples/s{unit}, daemon "
                      f"CPU {figures['daemon_cpu_us_per_sample']} us per sample{unit}",
                      flush=True)
    print(json.dumps(results, indent=2))
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
