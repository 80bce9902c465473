"""A real daemon reading a real OPC UA server (asyncua's, on a loopback port) that plays a
bundled replay as a rig's drilling control system would: a value of bad quality, a server
restart in the middle; the recording read back and replayed."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest
from numpy.typing import NDArray

from tdmon.config.daemon import DaemonConfig, parse_daemon_config
from tdmon.daemon.build import build_daemon
from tdmon.daemon.steps.monitor import GridLoadModel
from tdmon.daemon.supervisor import Backoff
from tdmon.ingest.opcua_server import OpcUaRigServer, OpcUaSender, step_payload
from tdmon.ingest.publish import publish, recording_messages
from tdmon.ingest.wits0_server import Step, session_steps
from tdmon.record.reader import read_messages, schemas_of

REPO = Path(__file__).resolve().parents[2]
REPLAY = REPO / "replays" / "trip-out-tight-spot.mcap"
PREFIX = "sim/trip-out"
INPUT_TOPICS = ("/tdmon/raw", "/tdmon/sample", "/tdmon/rejected", "/tdmon/status")


def _curves(depths: NDArray[np.float64], mu: float) -> tuple[NDArray[np.float64], ...]:
    weight = 300.0 * depths + 500e3  # a stand-in model: the recording's inputs are the point
    return weight * (1 + mu), weight * (1 - mu), weight, 20.0 * depths * mu


def _config(tmp_path: Path, port: int, channels: list[str]) -> DaemonConfig:
    return parse_daemon_config({
        "prefix": PREFIX, "publish": {"status_interval": "0.2 s"},
        "sources": {"opcua": {
            "endpoint": f"opc.tcp://127.0.0.1:{port}", "publishing_interval": "0.1 s",
            "queue_size": 1000, "timeout": "5 s",
            "nodes": {channel: {"path": f"2:Rig/2:{channel}"} for channel in channels}}},
        "recorder": {"enabled": True, "output": str(tmp_path / "rec"), "process": "inline"},
        "align": {"stale_timeout": "20 s"}}, tmp_path / "daemon.toml")


async def _until(predicate: Callable[[], bool], what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        await asyncio.sleep(0.05)


async def _play(server: OpcUaRigServer, steps: list[Step]) -> None:
    await publish(((step.t, "opcua", step_payload(step)) for step in steps),
                  OpcUaSender(server), speed=100.0)


async def test_a_replay_through_a_bad_value_and_a_server_restart(
        tmp_path: Path, free_tcp_port: Callable[[], int],
        caplog: pytest.LogCaptureFixture) -> None:
    steps = list(session_steps(recording_messages(REPLAY)))[:300]
    channels = sorted({channel for step in steps for channel in step.values})
    config = _config(tmp_path, free_tcp_port(), channels)
    port = int(config.sources.opcua.endpoint.rsplit(":", 1)[-1])  # type: ignore[union-attr]
    bad_t = steps[150].t - 0.5  # between two steps: a sensor failing on the rig
    model = GridLoadModel.from_function(_curves, np.linspace(0, 5000, 51), 0.25, (0.1, 0.3))
    async with build_daemon(config, model=model,
                            backoff=Backoff(initial=0.1, maximum=0.5)) as built:
        stop = asyncio.Event()
        daemon = asyncio.create_task(built.daemon.run(stop))
        connections = built.daemon.connections
        try:
            async with OpcUaRigServer("127.0.0.1", port, channels=channels) as server:
                await asyncio.wait_for(server.wait_for_subscribers(1), 60)
                await _play(server, steps[:150])
                await server.write_status("hookload", bad_t, "BadSensorFailure")
                first_part = sum(len(step.values) for step in steps[:150])
                await _until(lambda: built.stats.samples_in >= first_part, "the first part")
                await _until(lambda: built.stats.rejected >= len(channels) + 1, "the bad value")
            # the server is gone (a restart of the rig's system): the daemon retries
            await _until(lambda: str(connections.get("opcua")).startswith("retrying"),
                         "the daemon to notice")
            async with OpcUaRigServer("127.0.0.1", port, channels=channels) as server:
                await asyncio.wait_for(server.wait_for_subscribers(1), 60)
                await _until(lambda: connections["opcua"] == "connected", "a new session")
                await _play(server, steps[150:])
                total = sum(len(step.values) for step in steps)
                await _until(lambda: built.stats.samples_in >= total, "the second part")
        finally:
            stop.set()
            await asyncio.wait_for(daemon, 60)
    lost = [r.getMessage() for r in caplog.records if "connection lost" in r.getMessage()]
    assert len(lost) == 2 and all(m.startswith("opcua: ") for m in lost)  # the two stops

    [recording] = (tmp_path / "rec").glob("*.mcap")
    validators = {topic: jsonschema.Draft202012Validator(schema)
                  for topic, schema in schemas_of(recording).items()}
    recorded: dict[str, list[dict[str, Any]]] = {}
    for message in read_messages(recording, INPUT_TOPICS):
        validators[message.topic].validate(message.message)  # "opcua" is a source they know
        recorded.setdefault(message.topic, []).append(message.message)

    # every value of the replay, in SI again, at its step's time (the source timestamp)
    samples = recorded["/tdmon/sample"]
    assert len(samples) == sum(len(step.values) for step in steps)
    for channel in channels:
        got = [(s["t"], s["value"]) for s in samples if s["channel"] == channel]
        want = [(step.t, step.values[channel]) for step in steps if channel in step.values]
        assert [t for t, _ in got] == [t for t, _ in want], channel
        assert [v for _, v in got] == pytest.approx([v for _, v in want], rel=1e-12), channel
        assert all(s["source"] == "opcua" for s in samples)

    # rejected: each variable's first value on each connection (no value yet), and the failure
    rejected = recorded["/tdmon/rejected"]
    reasons = [r["reason"] for r in rejected]
    waiting = [r for r in reasons if r.startswith("OPC UA status BadWaitingForInitialData")]
    assert len(waiting) == 2 * len(channels)
    [failure] = [r for r in rejected if "BadSensorFailure" in r["reason"]]
    assert failure["reason"] == ("OPC UA status BadSensorFailure (0x808C0000) from node "
                                 "2:Rig/2:hookload")
    assert failure["topic"] == f"{PREFIX}/hookload" and failure["source"] == "opcua"
    assert json.loads(failure["payload"])["t"] == bad_t
    assert len(rejected) == len(waiting) + 1

    # raw input: one per value, recorded before decoding, with what the server said
    raw = recorded["/tdmon/raw"]
    assert len(raw) == len(samples) + len(rejected)
    first = json.loads(next(r["payload"] for r in raw if r["topic"] == f"{PREFIX}/torque"
                            and "error" not in r["payload"]))
    assert first["unit"] == "kN*m" and first["time_from"] == "source"
    assert first["node"] == "2:Rig/2:torque" and first["status"] == "Good"
    statuses = [s["connections"].get("opcua", "") for s in recorded["/tdmon/status"]]
    assert any(state.startswith("retrying") for state in statuses)

    # the recording replays through the ordinary decoder: the same samples and rejections
    replay = parse_daemon_config({"prefix": PREFIX, "sources": {"mcap": {
        "path": str(recording)}}, "recorder": {"enabled": True,
                                               "output": str(tmp_path / "again"),
                                               "process": "inline"}},
        tmp_path / "replay.toml")
    async with build_daemon(replay, model=model) as built:
        await asyncio.wait_for(built.daemon.run(), 60)
    [again] = (tmp_path / "again").glob("*.mcap")
    assert [m.message for m in read_messages(again, "/tdmon/sample")] == samples
    assert [m.message for m in read_messages(again, "/tdmon/rejected")] == rejected
