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
from tdmon.ingest.wits0 import FrameParser, WitsFrame, decode_frame, item_map
from tdmon.ingest.wits0_server import (
    SerialAddress,
    ServeAddress,
    Step,
    Wits0Sender,
    Wits0Server,
    build_frame,
    parse_serve_url,
    session_steps,
)

REPO = Path(__file__).resolve().parents[2]
REPLAY = REPO / "replays" / "trip-out-tight-spot.mcap"


def parse_frames(data: bytes) -> list[WitsFrame]:
    """The frames of a stream, with the codec's parser fed in uneven pieces as reads come."""
    parser = FrameParser()
    frames = []
    for start in range(0, len(data), 1000):
        frames.extend(parser.feed(data[start:start + 1000]))
    frames.extend(parser.close())
    assert all(isinstance(f, WitsFrame) and f.error is None and not f.errors for f in frames)
    return frames  # type: ignore[return-value]


def test_build_frame_known_bytes() -> None:
    # 2016-10-04T17:00:15.7Z: the fraction is cut, not rounded; KDN is 10 kN; no torque value
    frame = build_frame(Step(1475600415.7, {"hookload": 654250.0, "bit_depth": 1000.0}),
                        item_map("metric"))
    assert frame == (b"&&\r\n0105161004\r\n0106170015\r\n011465.425\r\n"
                     b"01081000.0\r\n!!\r\n")


def test_build_frame_field_units_and_decimals() -> None:
    frame = build_frame(Step(0.0, {"hookload": 1e6, "bit_depth": 1000.0, "mud_temp_in": 20.0}),
                        item_map("field"), decimals=2)
    lines = frame.decode().split("\r\n")
    # 1 kip = 4448.2216152605 N, 1 ft = 0.3048 m, 20 degC = 68 degF (independent numbers)
    assert lines[1:3] == ["0105700101", "0106000000"]
    assert sorted(lines[3:6]) == sorted([f"0114{1e6 / 4448.2216152605:.2f}",
                                         f"0108{1000 / 0.3048:.2f}", "013468.0"])


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


def check_against_replay(frames: list[WitsFrame]) -> None:
    truth = replay_truth()
    items = item_map("metric")
    # one frame per logged second of the replay, each with the date and time
    assert len(frames) == len(truth["hookload"]) == 1500
    decoded = [decode_frame(frame, items, receive_time=0.0) for frame in frames]
    assert all(d.time_from == "wits" for d in decoded)
    assert decoded[0].t == 1709272800.0  # 2024-03-01T06:00:00Z (the replay's 06:00:00.2)
    assert [d.t for d in decoded] == [1709272800.0 + k for k in range(1500)]
    received: dict[str, list[float]] = {}
    for frame in decoded:
        for item in frame.items:
            received.setdefault(item.channel, []).append(item.value)
    assert set(received) == set(truth)
    for channel, values in truth.items():
        assert received[channel] == pytest.approx(values, rel=1e-12, abs=1e-12), channel


async def read_all(port: int) -> bytes:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    data = await asyncio.wait_for(reader.read(), 120)
    writer.close()
    return data


async def test_two_clients_get_every_step_of_a_replay() -> None:
    items = item_map("metric")
    frames = ((step.t, "wits0", build_frame(step, items))
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
    frame = build_frame(Step(1475600400.0, {"hookload": 1e6}), item_map("metric"))
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
    assert len(frames) == 21 and frames[0].lines[2].text == "0114100.0"  # 1000 kN in KDN


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
    items = item_map("metric")
    hookload = [item.value for frame in frames
                for item in decode_frame(frame, items, 0.0).items if item.channel == "hookload"]
    assert hookload == pytest.approx(truth["hookload"][:40], rel=1e-12)


async def test_a_client_that_reads_nothing_is_dropped_and_the_others_keep_going() -> None:
    frame = build_frame(Step(1475600400.0, {"hookload": 1e6, "bit_depth": 2500.0}),
                        item_map("metric"))
    received = 0

    async def keep_reading(port: int) -> None:
        nonlocal received
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        while chunk := await reader.read(65536):
            received += len(chunk)
        writer.close()

    stuck = socket.socket()
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    # the reading client must never look stuck, even on a loaded machine (was: 0.5 s)
    async with Wits0Server("127.0.0.1", 0, drain_timeout=5.0) as server:
        reading = asyncio.create_task(keep_reading(server.bound_port))
        stuck.connect(("127.0.0.1", server.bound_port))  # and never reads
        await asyncio.wait_for(server.wait_for_clients(2), 30)
        sent = 0
        while server.clients == 2:
            assert sent < 1_000_000, "the stuck client was never dropped"
            await server.send(frame)
            sent += 1
        for _ in range(100):  # the reader is served on
            await server.send(frame)
        sent += 100
    await asyncio.wait_for(reading, 60)
    stuck.close()
    assert received == sent * len(frame)
