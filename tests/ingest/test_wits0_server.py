"""The WITS0 simulator: frames built from a session's samples, served over real TCP sockets."""

from __future__ import annotations

import asyncio
import json
import os
import select
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tdmon.errors import IngestError
from tdmon.ingest.publish import csv_messages, publish, recording_messages
from tdmon.ingest.wits0_server import (
    SerialAddress,
    ServeAddress,
    ServedItem,
    Step,
    Wits0Sender,
    Wits0Server,
    build_frame,
    default_served_items,
    parse_serve_url,
    session_steps,
)

REPO = Path(__file__).resolve().parents[2]
REPLAY = REPO / "replays" / "trip-out-tight-spot.mcap"


def parse_frames(data: bytes) -> list[dict[str, str]]:
    """Frames as {code: text}, split by hand (independent of the code under test)."""
    frames: list[dict[str, str]] = []
    current: dict[str, str] | None = None
    for line in data.decode("ascii").split("\r\n"):
        if line == "&&":
            current = {}
        elif line == "!!":
            assert current is not None
            frames.append(current)
            current = None
        elif line:
            assert current is not None, line
            current[line[:4]] = line[4:]
    assert current is None, "a frame was cut off"
    return frames


def test_build_frame_known_bytes() -> None:
    # 2016-10-04T17:00:15.7Z: the fraction is cut, not rounded
    items = (ServedItem("hookload", "0114", "kN"), ServedItem("bit_depth", "0108", "ft"),
             ServedItem("torque", "0118", "kN*m"))
    frame = build_frame(1475600415.7, {"hookload": 654267.8, "bit_depth": 1000.0}, items)
    assert frame == (b"&&\r\n0105161004\r\n0106170015\r\n0114654.2678\r\n"
                     b"01083280.839895\r\n!!\r\n")  # 1000 m = 3280.839895 ft; no torque value


def test_session_steps_group_by_time_and_convert(tmp_path: Path) -> None:
    log = tmp_path / "log.csv"
    log.write_text("time_utc,hookload_kN,bit_depth_m\n"
                   "2016-10-04T17:00:00Z,654.5,100\n2016-10-04T17:00:15Z,,101\n")
    from tdmon.ingest.publish import Column

    steps = list(session_steps(csv_messages(
        log, "rig/F4", (Column("hookload", "hookload_kN", "kN"),
                        Column("bit_depth", "bit_depth_m", "m")))))
    assert steps == [Step(1475600400.0, {"hookload": 654500.0, "bit_depth": 100.0}),
                     Step(1475600415.0, {"bit_depth": 101.0})]


def test_serve_url_mistakes() -> None:
    assert parse_serve_url("tcp://127.0.0.1:5001") == ServeAddress("127.0.0.1", 5001)
    assert parse_serve_url("serial:///dev/pts/3?baud=19200") == SerialAddress("/dev/pts/3",
                                                                               19200)
    assert parse_serve_url("serial:///dev/ttyS0") == SerialAddress("/dev/ttyS0", 9600)
    for bad in ("127.0.0.1:5001", "udp://127.0.0.1:5001", "tcp://127.0.0.1", "tcp://:5001",
                "serial:///dev/ttyS0?baud=1234", "serial:///dev/ttyS0?parity=E"):
        with pytest.raises(IngestError, match="--wits0"):
            parse_serve_url(bad)


def replay_truth() -> dict[str, list[float]]:
    """Every SI value of the replay by channel, in order, straight from the payloads."""
    truth: dict[str, list[float]] = {}
    for _, topic, payload in recording_messages(REPLAY):
        truth.setdefault(topic.rsplit("/", 1)[-1], []).append(json.loads(payload)["value"])
    return truth


def check_against_replay(frames: list[dict[str, str]]) -> None:
    truth = replay_truth()
    items = {item.code: item for item in default_served_items()}
    # one frame per logged second of the replay, each with the date and time
    assert len(frames) == len(truth["hookload"]) == 1500
    assert frames[0]["0105"] == "240301" and frames[0]["0106"] == "060000"  # 2024-03-01 06:00
    assert frames[-1]["0106"] == "062459"  # 1499 s later
    received: dict[str, list[float]] = {}
    for frame in frames:
        for code, text in frame.items():
            if code in items:
                received.setdefault(items[code].channel, []).append(float(text))
    assert set(received) == set(truth)
    scale = {"hookload": 1e-3, "wob": 1e-3, "torque": 1e-3, "spp": 1e-3,
             "flow_in": 60e3, "rpm": 60 / (2 * 3.141592653589793)}
    for channel, values in truth.items():
        expected = [v * scale.get(channel, 1.0) for v in values]
        assert received[channel] == pytest.approx(expected, rel=1e-9, abs=1e-9), channel


async def read_all(port: int) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    data = await asyncio.wait_for(reader.read(), 120)
    writer.close()
    return data


async def test_two_clients_get_every_step_of_a_replay() -> None:
    frames = ((step.t, "wits0", build_frame(step.t, step.values, default_served_items()))
              for step in session_steps(recording_messages(REPLAY)))
    async with Wits0Server("127.0.0.1", 0) as server:
        clients = [asyncio.create_task(read_all(server.bound_port)) for _ in range(2)]
        await asyncio.wait_for(server.wait_for_clients(2), 30)
        sent = await publish(frames, Wits0Sender(server), speed=None)
    # leaving the server closed the connections: each client read up to EOF
    first, second = await asyncio.gather(*clients)
    assert sent == server.frames_sent == 1500
    assert first == second
    check_against_replay(parse_frames(first))


async def test_a_client_leaving_does_not_stop_the_others() -> None:
    step = Step(1475600400.0, {"hookload": 1e6})
    frame = build_frame(step.t, step.values, default_served_items())
    async with Wits0Server("127.0.0.1", 0) as server:
        stayer = asyncio.create_task(read_all(server.bound_port))
        leaver = socket.create_connection(("127.0.0.1", server.bound_port))
        await asyncio.wait_for(server.wait_for_clients(2), 30)
        await server.send(frame)
        leaver.close()
        for _ in range(20):  # the broken connection shows on a later write
            await server.send(frame)
            await asyncio.sleep(0.01)
        assert server.clients == 1
    frames = parse_frames(await stayer)
    assert len(frames) == 21 and frames[0]["0114"] == "1000"


def test_cli_serves_the_replay(free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(
        [sys.executable, "-m", "tdmon", "publish", str(REPLAY), "--wits0",
         f"tcp://127.0.0.1:{port}", "--speed", "max"],
        stderr=subprocess.PIPE, env=env, text=True)
    try:
        assert process.stderr is not None
        assert "serving WITS0" in process.stderr.readline()  # listening from here on
        with socket.create_connection(("127.0.0.1", port), timeout=120) as client:
            chunks = []
            while chunk := client.recv(65536):
                chunks.append(chunk)
        assert process.wait(120) == 0
        assert "served 1500 WITS0 frames to 1 client(s)" in process.stderr.read()
    finally:
        process.kill()
        process.wait()
    check_against_replay(parse_frames(b"".join(chunks)))


def test_cli_writes_frames_to_a_serial_line() -> None:
    # a pseudo-terminal pair stands in for the line: tdmon writes to the slave end
    master, slave = os.openpty()
    device = os.ttyname(slave)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    process = subprocess.Popen(
        [sys.executable, "-m", "tdmon", "publish", str(REPLAY), "--wits0",
         f"serial://{device}?baud=115200", "--speed", "max", "--limit", "40"],
        stderr=subprocess.PIPE, env=env, text=True)
    data = b""
    try:
        os.set_blocking(master, False)
        deadline = time.monotonic() + 120
        while data.count(b"!!\r\n") < 40 and time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 1.0)
            if ready:
                data += os.read(master, 65536)
        assert process.wait(120) == 0
        assert process.stderr is not None
        assert f"served 40 WITS0 frames to {device} at 115200 bit/s" in process.stderr.read()
    finally:
        process.kill()
        process.wait()
        os.close(master)
        os.close(slave)
    frames = parse_frames(data)
    truth = replay_truth()
    assert len(frames) == 40
    assert [float(f["0114"]) for f in frames] == pytest.approx(
        [v / 1e3 for v in truth["hookload"][:40]], rel=1e-9)
