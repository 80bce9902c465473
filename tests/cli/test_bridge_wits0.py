"""``tdmon bridge wits0``: a WITS0 server (the simulator) in, tdmon's payloads out on a real
MQTT broker and a real Zenoh peer; reconnection after the feed is lost."""

from __future__ import annotations

import asyncio
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
import zenoh

from tdmon.channels import CHANNELS
from tdmon.config.daemon import ZenohConfig
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.publish import recording_messages
from tdmon.ingest.types import RawMessage, Rejected, Sample
from tdmon.ingest.wits0 import item_map
from tdmon.ingest.wits0_server import Wits0Server, build_frame, session_steps
from tdmon.ingest.zenoh_io import open_session

REPO = Path(__file__).resolve().parents[2]
REPLAY = REPO / "replays" / "trip-out-tight-spot.mcap"
PREFIX = "sim/bridged"
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def replay_truth() -> list[tuple[int, str, float]]:
    """(whole second, channel, SI value) of every replay sample, in the order sent."""
    return [(math.floor(t), topic.rsplit("/", 1)[-1], json.loads(payload)["value"])
            for t, topic, payload in recording_messages(REPLAY)]


def start_bridge(port: int, *output: str, limit: int) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "tdmon", "bridge", "wits0", "--wits0", f"tcp://127.0.0.1:{port}",
         "--prefix", PREFIX, "--limit", str(limit), *output],
        stderr=subprocess.PIPE, env=ENV, text=True)


async def serve_replay(server: Wits0Server, steps: list[Any]) -> None:
    await asyncio.wait_for(server.wait_for_clients(1), 60)
    items = item_map("metric")
    for step in steps:
        await server.send(build_frame(step, items))


def check_payloads(received: list[tuple[str, bytes]], truth: list[tuple[int, str, float]]
                   ) -> None:
    """Every sample arrives once on <prefix>/<channel>, and the daemon's own decoder takes it
    (`tdmon run` consumes the bridge unchanged)."""
    decoder = Decoder(PREFIX, [ChannelSpec(channel, channel) for channel in CHANNELS])
    samples = []
    for topic, payload in received:
        sample = decoder.decode(RawMessage("test", topic, payload, 0.0))
        assert isinstance(sample, Sample), sample
        samples.append(sample)
    assert len(samples) == len(truth)
    # frames keep the order of the channels within a step: compare per channel in time order
    for channel in {c for _, c, _ in truth}:
        got = [(s.t, s.value) for s in samples if s.channel == channel]
        want = [(float(second), value) for second, c, value in truth if c == channel]
        assert [t for t, _ in got] == [t for t, _ in want], channel
        for (_, a), (_, b) in zip(got, want, strict=True):
            assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9), (channel, a, b)


async def test_bridge_to_mqtt(mosquitto: Any) -> None:
    truth = replay_truth()
    steps = list(session_steps(recording_messages(REPLAY)))
    received: list[tuple[str, bytes]] = []
    async with aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="bridge-test") as client:
        await client.subscribe(f"{PREFIX}/#", qos=1)
        async with Wits0Server("127.0.0.1", 0) as server:
            bridge = start_bridge(server.bound_port, "--mqtt", f"127.0.0.1:{mosquitto.port}",
                                  limit=len(truth) + 1)
            try:
                await serve_replay(server, steps)
                # a frame with no item of the map: the feed rejects it, the bridge passes that on
                await server.send(b"&&\r\n0105240301\r\n0106070000\r\n01991\r\n!!\r\n")

                async def collect() -> None:
                    async for message in client.messages:
                        received.append((str(message.topic), bytes(message.payload)))
                        if len(received) == len(truth) + 1:
                            return

                await asyncio.wait_for(collect(), 120)
                assert await asyncio.to_thread(bridge.wait, 60) == 0
                assert bridge.stderr is not None
                assert f"bridged {len(truth) + 1} messages" in bridge.stderr.read()
            finally:
                bridge.kill()
                bridge.wait()
    rejects = [(topic, payload) for topic, payload in received if topic == f"{PREFIX}/wits0"]
    assert len(rejects) == 1
    topic, payload = rejects[0]
    received.remove(rejects[0])
    assert json.loads(payload)["error"] == "no item of the frame is mapped to a channel"
    # a consuming daemon rejects it (no channel has that topic) and records why
    rejected = Decoder(PREFIX, [ChannelSpec(c, c) for c in CHANNELS]).decode(
        RawMessage("mqtt", topic, payload, 0.0))
    assert isinstance(rejected, Rejected) and "unknown topic" in rejected.reason
    check_payloads(received, truth)


async def test_bridge_to_zenoh_and_reconnect_after_the_feed_is_lost(
        free_tcp_port: Any) -> None:
    truth = replay_truth()
    steps = list(session_steps(recording_messages(REPLAY)))
    half = len(steps) // 2
    zenoh_port = free_tcp_port()
    session = await asyncio.to_thread(open_session, ZenohConfig(
        mode="peer", listen=[f"tcp/127.0.0.1:{zenoh_port}"]))
    received: list[tuple[str, bytes]] = []
    done = threading.Event()

    def on_sample(sample: zenoh.Sample) -> None:  # a zenoh thread
        received.append((str(sample.key_expr), sample.payload.to_bytes()))
        if len(received) == len(truth):
            done.set()

    subscriber = session.declare_subscriber(f"{PREFIX}/**", on_sample)
    try:
        wits_port = free_tcp_port()
        bridge = start_bridge(wits_port, "--zenoh-connect", f"tcp/127.0.0.1:{zenoh_port}",
                              limit=len(truth))
        try:
            # the rig's server goes away after half the session and comes back on its port
            async with Wits0Server("127.0.0.1", wits_port) as server:
                await serve_replay(server, steps[:half])
                await _until(lambda: len(received) >= sum(len(s.values) for s in steps[:half]))
            async with Wits0Server("127.0.0.1", wits_port) as server:
                await serve_replay(server, steps[half:])
                assert await asyncio.to_thread(done.wait, 120)
            assert await asyncio.to_thread(bridge.wait, 60) == 0
            assert bridge.stderr is not None
            log = bridge.stderr.read()
            assert "retrying" in log  # the supervisor saw the feed end
        finally:
            bridge.kill()
            bridge.wait()
    finally:
        subscriber.undeclare()
        await asyncio.to_thread(session.close)
    check_payloads(received, truth)


async def _until(condition: Any, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.05)


def test_simulator_to_the_daemon_recording(tmp_path: Path, free_tcp_port: Any) -> None:
    """`tdmon publish --wits0` -> `tdmon run` with a [sources.wits0] TCP client -> the flight
    recording holds every sample of the replay, at its second, with its value."""
    from tdmon.record.reader import read_messages

    port = free_tcp_port()
    config = tmp_path / "wits0.toml"
    config.write_text(f"""
prefix = "sim/trip-out"
well = "{REPO / 'replays/scenarios/wells/example-7-1-glydril.toml'}"
[sources.wits0]
mode = "tcp-client"
host = "127.0.0.1"
port = {port}
[recorder]
enabled = true
output = "{tmp_path / 'rec'}"
[align]
stale_timeout = "20 s"
""")
    log = tmp_path / "daemon.log"
    simulator = subprocess.Popen(
        [sys.executable, "-m", "tdmon", "publish", str(REPLAY), "--wits0",
         f"tcp://127.0.0.1:{port}", "--speed", "max"],
        stderr=subprocess.PIPE, env=ENV, text=True)
    try:
        assert simulator.stderr is not None
        assert "serving WITS0" in simulator.stderr.readline()
        with log.open("w") as err:
            daemon = subprocess.Popen([sys.executable, "-m", "tdmon", "run", "--config",
                                       str(config)], stderr=err, env=ENV)
            try:
                assert simulator.wait(120) == 0
                assert "served 1500 WITS0 frames to 1 client(s)" in simulator.stderr.read()
                # the simulator closed the connection once done: the source says so, and a
                # graceful stop processes everything that arrived before it
                deadline = time.monotonic() + 60
                while "connection closed by the rig" not in log.read_text():
                    assert time.monotonic() < deadline, log.read_text()
                    time.sleep(0.1)
                daemon.send_signal(signal.SIGTERM)
                assert daemon.wait(60) == 0, log.read_text()
            finally:
                if daemon.poll() is None:
                    daemon.kill()
                    daemon.wait()
    finally:
        if simulator.poll() is None:
            simulator.kill()
            simulator.wait()
    text = log.read_text()
    truth = replay_truth()
    assert f"stopped: {len(truth)} samples, 0 rejected, 0 dropped" in text, text
    samples = [m.message for path in (tmp_path / "rec").glob("*.mcap")
               for m in read_messages(path, "/tdmon/sample")]
    assert len(samples) == len(truth)
    for channel in {c for _, c, _ in truth}:
        got = [(s["t"], s["value"]) for s in samples if s["channel"] == channel]
        want = [(float(second), value) for second, c, value in truth if c == channel]
        assert [t for t, _ in got] == [t for t, _ in want], channel
        assert [v for _, v in got] == pytest.approx([v for _, v in want], rel=1e-12), channel


async def test_bridge_from_a_daemon_file(mosquitto: Any, tmp_path: Path) -> None:
    """--config: the feed from [sources.wits0] (field units there), the output from
    [publish.mqtt], the prefix from the file."""
    steps = list(session_steps(recording_messages(REPLAY)))[:20]
    expected = sum(len(step.values) for step in steps)
    received: list[tuple[str, bytes]] = []
    async with aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="bridge-test") as client:
        await client.subscribe("rig/from-file/#", qos=1)
        async with Wits0Server("127.0.0.1", 0) as server:
            config = tmp_path / "bridge.toml"
            config.write_text(f"""
prefix = "rig/from-file"
[sources.wits0]
host = "127.0.0.1"
port = {server.bound_port}
units = "field"
[publish.mqtt]
host = "127.0.0.1"
port = {mosquitto.port}
client_id = "bridge-from-file"
[channels.hookload]
topic = "HKLD"
unit = "kN"
""")
            bridge = subprocess.Popen(
                [sys.executable, "-m", "tdmon", "bridge", "wits0", "--config", str(config),
                 "--limit", str(expected)], stderr=subprocess.PIPE, env=ENV, text=True)
            try:
                await asyncio.wait_for(server.wait_for_clients(1), 60)
                items = item_map("field")
                for step in steps:
                    await server.send(build_frame(step, items))

                async def collect() -> None:
                    async for message in client.messages:
                        received.append((str(message.topic), bytes(message.payload)))
                        if len(received) == expected:
                            return

                await asyncio.wait_for(collect(), 120)
                assert await asyncio.to_thread(bridge.wait, 60) == 0
            finally:
                bridge.kill()
                bridge.wait()
    first = {topic: json.loads(payload) for topic, payload in reversed(received)}
    # the replay's first hook load, 1479516 N, went out in klbf and came back in N, on the
    # file's own topic for the channel ([channels.hookload] topic), as its daemon reads it
    assert "rig/from-file/hookload" not in first
    assert math.isclose(first["rig/from-file/HKLD"]["value"], 1479516.0, rel_tol=1e-12)
    assert first["rig/from-file/HKLD"]["unit"] == "N"
    assert first["rig/from-file/HKLD"]["wits"].startswith("0114332.6")  # 332.6... klbf


def test_bridge_mistakes_are_one_line_and_exit_2(tmp_path: Path) -> None:
    cases = [
        ([], "say where the feed is"),
        (["--wits0", "udp://127.0.0.1:5001", "--mqtt", "127.0.0.1:1883"], "--wits0"),
        (["--wits0", "tcp://127.0.0.1:5001"], "say where to publish"),
        (["--wits0", "tcp://127.0.0.1:5001", "--mqtt", "nowhere"], "--mqtt must be HOST:PORT"),
        (["--wits0", "tcp://127.0.0.1:5001", "--prefix", "rig/#"], "--prefix: prefix 'rig/#'"),
    ]
    for args, expected in cases:
        result = subprocess.run(
            [sys.executable, "-m", "tdmon", "bridge", "wits0", *args],
            capture_output=True, text=True, env=ENV, timeout=60)
        assert result.returncode == 2, (args, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert expected in result.stderr, result.stderr


def test_bridge_stops_on_sigterm_while_the_rig_is_away(mosquitto: Any,
                                                       free_tcp_port: Any) -> None:
    bridge = start_bridge(free_tcp_port(), "--mqtt", f"127.0.0.1:{mosquitto.port}", limit=10)
    try:
        assert bridge.stderr is not None
        # nobody listens on the feed's port: the supervisor says so and waits to retry
        while "retrying" not in (line := bridge.stderr.readline()):
            assert line, "the bridge ended before retrying"
        bridge.send_signal(signal.SIGTERM)
        assert bridge.wait(60) == 0
        assert "bridged 0 messages" in bridge.stderr.read()
    finally:
        bridge.kill()
        bridge.wait()
