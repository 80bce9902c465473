"""A real daemon reading WITS0: from a rig's server (tcp-client), pushed to by the rig
(tcp-server), on a serial line (a pseudo-terminal pair); the recording read back."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from daemon_support import CollectSink, linear_model, make_config, running, wait_until

from tdmon.config.daemon import DaemonConfig
from tdmon.daemon.build import build_daemon
from tdmon.ingest.wits0 import ItemOverride, encode_sample_frame, item_map
from tdmon.record.reader import read_messages, schemas_of

T0 = 1_700_000_000.0
ITEMS = item_map("metric")


def _values(i: int) -> dict[str, float]:
    """SI values of frame i (exactly representable after the metric conversions)."""
    return {"hookload": 1_000_000.0 + 10_000.0 * i, "torque": 20_000.0 + 500.0 * i,
            "bit_depth": 2000.0 + 0.5 * i, "mud_temp_in": 40.0 + i}


def _frames(n: int, start: int = 0) -> list[bytes]:
    return [encode_sample_frame(T0 + i, _values(i), ITEMS) for i in range(start, start + n)]


BAD_FRAME = b"&&\r\n0105231114\r\n0106221420\r\n0114abc\r\n01\r\n01181.5\r\n!!\r\n"
GARBAGE = b"NOT WITS\r\n"


def _config(tmp_path: Path, wits0: dict[str, Any]) -> DaemonConfig:
    return make_config({"sources": {"wits0": wits0},
                        "recorder": {"enabled": True, "output": str(tmp_path / "rec")}},
                       tmp_path)


def _recorded(tmp_path: Path) -> dict[str, list[dict[str, Any]]]:
    """The recording's messages by topic, each checked against its recorded schema."""
    [recording] = (tmp_path / "rec").glob("*.mcap")
    schemas = schemas_of(recording)
    out: dict[str, list[dict[str, Any]]] = {}
    for message in read_messages(recording):
        jsonschema.validate(message.message, schemas[message.topic])
        out.setdefault(message.topic, []).append(message.message)
    return out


def _check_samples(samples: list[dict[str, Any]], frames: range) -> None:
    by_key = {(s["channel"], s["t"]): s for s in samples}
    for i in frames:
        for channel, value in _values(i).items():
            sample = by_key[(channel, T0 + i)]
            assert sample["value"] == pytest.approx(value, rel=1e-12), (channel, i)
            assert sample["source"] == "wits0"


def _check_rejections(recorded: dict[str, list[dict[str, Any]]]) -> None:
    rejected = recorded["/tdmon/rejected"]
    errors = {json.loads(r["payload"])["error"]: r for r in rejected}
    bad_value = errors["item 0114 (hookload): value 'abc' is not a number"]
    assert bad_value["topic"] == "rig/T1/hookload"
    assert bad_value["reason"] == "'value' must be a number, got str"
    short = errors["line '01' is too short for a four-digit code and a value"]
    assert short["topic"] == "rig/T1/wits0" and short["reason"].startswith("unknown topic")
    assert errors["bytes outside a frame (no '&&' before them)"]["source"] == "wits0"
    # the good line of the bad frame still made a sample (1.5 kN m at the frame's time)
    torque = [s for s in recorded["/tdmon/sample"] if s["t"] == T0 + 60]
    assert [(s["channel"], s["value"]) for s in torque] == [("torque", pytest.approx(1500.0))]


@contextlib.asynccontextmanager
async def _rig_server(on_connect: Callable[[asyncio.StreamWriter, int], Any]
                      ) -> AsyncIterator[tuple[int, list[int]]]:
    """A rig's WITS server on a free loopback port; ``on_connect(writer, n)`` for the
    n-th connection (from 1)."""
    connections: list[int] = []

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        connections.append(len(connections) + 1)
        try:
            await on_connect(writer, len(connections))
            await reader.read()  # hold the connection until the daemon drops it
        except (ConnectionError, OSError):
            pass
        finally:
            writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    try:
        yield port, connections
    finally:
        server.close()
        with contextlib.suppress(Exception):
            await asyncio.wait_for(server.wait_closed(), 5)


async def test_tcp_client_reads_a_rig_server_and_records_samples_and_rejections(
        tmp_path: Path) -> None:
    frames = _frames(20)

    async def send(writer: asyncio.StreamWriter, n: int) -> None:
        # frames cut at odd places, garbage and a frame with bad lines in between
        data = GARBAGE + b"".join(frames[:10]) + BAD_FRAME + b"".join(frames[10:])
        for start in range(0, len(data), 37):
            writer.write(data[start:start + 37])
            await writer.drain()

    async with _rig_server(send) as (port, _):
        config = _config(tmp_path, {"mode": "tcp-client", "host": "127.0.0.1", "port": port})
        async with running(config, connected=("wits0",)) as (built, _):
            await wait_until(lambda: built.stats.samples_in >= 20 * 4 + 1, 30, "samples")
    recorded = _recorded(tmp_path)
    _check_samples(recorded["/tdmon/sample"], range(20))
    _check_rejections(recorded)
    raw = recorded["/tdmon/raw"]
    # every frame is in the raw record, whole, on its first message
    frames_seen = [json.loads(r["payload"]).get("frame") for r in raw]
    for frame in frames:
        assert frame.decode() in frames_seen
    assert BAD_FRAME.decode() in frames_seen
    assert all(r["source"] == "wits0" for r in raw)
    assert len(raw) == len(recorded["/tdmon/sample"]) + len(recorded["/tdmon/rejected"])

    # the recording replays through the ordinary decoder: the same samples and rejections
    [recording] = (tmp_path / "rec").glob("*.mcap")
    replay = make_config({"sources": {"mcap": {"path": str(recording)}}}, tmp_path)
    sink = CollectSink()
    async with build_daemon(replay, model=linear_model(), extra_sinks=[sink]) as built:
        await asyncio.wait_for(built.daemon.run(), 60)
    assert sink["sample"] == recorded["/tdmon/sample"]
    assert sink["rejected"] == recorded["/tdmon/rejected"]


async def test_a_silent_feed_times_out_and_the_daemon_reconnects(tmp_path: Path) -> None:
    async def send(writer: asyncio.StreamWriter, n: int) -> None:
        writer.write(b"".join(_frames(2, start=2 * (n - 1))))
        await writer.drain()  # then silence

    async with _rig_server(send) as (port, connections):
        config = _config(tmp_path, {"mode": "tcp-client", "host": "127.0.0.1", "port": port,
                                    "timeout": "0.5 s"})
        async with running(config, connected=("wits0",)) as (built, _):
            await wait_until(lambda: len(connections) >= 3, 30, "two reconnects")
            await wait_until(lambda: built.stats.samples_in >= 3 * 2 * 4, 30, "samples")
    _check_samples(_recorded(tmp_path)["/tdmon/sample"], range(6))


async def test_tcp_server_takes_the_rig_push_and_a_new_connection_replaces_the_old(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    config = _config(tmp_path, {"mode": "tcp-server", "port": port})
    async with running(config, connected=("wits0",)) as (built, _):
        _, first = await asyncio.open_connection("127.0.0.1", port)
        frames = _frames(5)
        first.write(b"".join(frames[:3]) + frames[3][:20])  # cut inside frame 3
        await first.drain()
        await wait_until(lambda: built.stats.samples_in >= 12, 30, "first connection")
        _, second = await asyncio.open_connection("127.0.0.1", port)
        # the rest of frame 3 would be garbage on a fresh stream; the new stream starts clean
        second.write(frames[4] + BAD_FRAME)
        await second.drain()
        await wait_until(lambda: built.stats.samples_in >= 16, 30, "second connection")
        with contextlib.suppress(ConnectionError, OSError):
            first.write(b"".join(_frames(3, start=10)))  # the old connection is no longer read
            await first.drain()
        await asyncio.sleep(0.2)
        for writer in (first, second):
            writer.close()
    recorded = _recorded(tmp_path)
    samples = recorded["/tdmon/sample"]
    _check_samples(samples, range(3))
    _check_samples(samples, range(4, 5))
    assert not [s for s in samples if s["t"] in (T0 + 3, T0 + 10, T0 + 11, T0 + 12)]
    # the frame cut by the new connection is recorded, rejected
    cut = [json.loads(r["payload"]) for r in recorded["/tdmon/rejected"]]
    assert [c["frame"] for c in cut if c["error"] == "stream ended inside a frame (no '!!')"
            ] == [frames[3][:20].decode()]


async def test_serial_through_a_pseudo_terminal(tmp_path: Path) -> None:
    master, slave = os.openpty()
    try:
        config = _config(tmp_path, {"mode": "serial", "device": os.ttyname(slave),
                                    "baud_rate": 19200})
        async with running(config, connected=("wits0",)) as (built, _):
            data = b"".join(_frames(8))
            for start in range(0, len(data), 50):
                os.write(master, data[start:start + 50])
                await asyncio.sleep(0)
            await wait_until(lambda: built.stats.samples_in >= 8 * 4, 30, "serial samples")
    finally:
        os.close(master)
        os.close(slave)
    _check_samples(_recorded(tmp_path)["/tdmon/sample"], range(8))


def test_the_example_rig_config_loads(tmp_path: Path) -> None:
    from tdmon.config.daemon import load_daemon_config

    path = Path(__file__).resolve().parents[2] / "config" / "daemon" / "wits0-rig.toml"
    config = load_daemon_config(path)
    wits0 = config.sources.wits0
    assert wits0 is not None and wits0.mode == "tcp-client" and wits0.port is not None
    # the commented item example is valid too: uncommented, 0115 in kN feeds the hook load
    text = "\n".join(line[2:] if line.startswith(("# [", "# channel", "# unit")) else line
                     for line in path.read_text().splitlines())
    example = tmp_path / "wits0-example.toml"
    example.write_text(text)
    section = load_daemon_config(example).sources.wits0
    assert section is not None
    items = item_map(section.units, {code: ItemOverride(item.channel, item.unit)
                                     for code, item in section.items.items()})
    assert "0114" not in items and items["0115"].to_si(1.5) == 1500.0


def test_config_mistakes_name_their_key(tmp_path: Path) -> None:
    from tdmon.errors import ConfigError

    with pytest.raises(ConfigError, match=r"sources.wits0: .*needs host and port"):
        make_config({"sources": {"wits0": {"mode": "tcp-client"}}}, tmp_path)
    with pytest.raises(ConfigError, match=r"sources.wits0.timezone: .*unknown time zone"):
        make_config({"sources": {"wits0": {"mode": "tcp-server", "port": 1,
                                           "timezone": "Mars/Olympus"}}}, tmp_path)
    with pytest.raises(ConfigError, match="unknown channel 'hook'"):
        make_config({"sources": {"wits0": {"mode": "tcp-server", "port": 1,
                                           "items": {"0114": {"channel": "hook"}}}}}, tmp_path)


async def test_an_unknown_wits_unit_is_a_config_error_at_start(tmp_path: Path) -> None:
    from tdmon.daemon.build import build_daemon
    from tdmon.errors import ConfigError

    config = make_config({"sources": {"wits0": {"mode": "tcp-server", "port": 1,
                                                "items": {"0114": {"unit": "KGF"}}}}}, tmp_path)
    with pytest.raises(ConfigError, match=r"sources.wits0.items: item 0114: unknown WITS unit"):
        async with build_daemon(config):
            pass
