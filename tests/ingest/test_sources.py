"""MCAP replay, the Zenoh bridge's backpressure, and the supervisor's reconnect loop."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from types import SimpleNamespace

import pytest
import zenoh
from mcap.writer import Writer

from tdmon.config.daemon import ZenohConfig
from tdmon.daemon.supervisor import Backoff, supervise
from tdmon.errors import IngestError
from tdmon.ingest import mcap_source
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.types import RawMessage, raw_message
from tdmon.ingest.zenoh_io import ZenohSource, key_expr_for, open_session


def _write_mcap(path: Path, raw: bool, n: int = 50, finish: bool = True) -> None:
    stream = path.open("wb")
    writer = Writer(stream)
    writer.start()
    schema = writer.register_schema("any", "jsonschema", b"{}")
    if raw:
        channel = writer.register_channel("/tdmon/raw", "json", schema)
        other = writer.register_channel("/tdmon/sample", "json", schema)
    else:
        channel = writer.register_channel("rig/F4/hookload", "json", schema)
        other = writer.register_channel("/tdmon/state", "json", schema)
    for i in range(n):
        t_ns = 1_700_000_000_000_000_000 + i * 20_000_000  # 50 Hz
        body = json.dumps({"t": t_ns / 1e9, "value": float(i)}).encode()
        if raw:
            payload = body if i % 2 else b"\xff\x00binary"
            data = json.dumps(raw_message(RawMessage("mqtt", "rig/F4/hookload", payload,
                                                     t_ns / 1e9))).encode()
        else:
            data = body
        writer.add_message(channel, t_ns, data, t_ns)
        writer.add_message(other, t_ns, b"{}", t_ns)
    if finish:
        writer.finish()
    stream.close()


async def _read(source: McapSource) -> list[RawMessage]:
    async with source:
        return [raw async for raw in source]


@pytest.mark.parametrize("raw", [True, False])
async def test_mcap_source_as_fast_as_possible(tmp_path: Path, raw: bool) -> None:
    path = tmp_path / "rec.mcap"
    _write_mcap(path, raw)
    messages = await _read(McapSource(path))
    assert len(messages) == 50  # derived topics are not replayed
    assert all(m.topic == "rig/F4/hookload" for m in messages)
    if raw:
        assert messages[0].payload == b"\xff\x00binary" and messages[0].source == "mqtt"
    assert json.loads(messages[1].payload)["value"] == 1.0


async def test_mcap_source_paced(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "rec.mcap"
    _write_mcap(path, raw=False, n=26)  # 0.5 s of data
    # the source's clock and waits on a clock of the test's own: its waits add up exactly,
    # whatever the machine's load (a wall-clock bound failed on a loaded machine)
    clock = [100.0]

    async def sleep(delay: float) -> None:
        clock[0] += delay

    monkeypatch.setattr(mcap_source, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    monkeypatch.setattr(mcap_source, "asyncio", SimpleNamespace(sleep=sleep))
    messages = await _read(McapSource(path, speed=2.0))
    assert len(messages) == 26 and clock[0] - 100.0 == pytest.approx(0.25, abs=1e-9)


async def test_mcap_source_reads_a_file_without_footer(tmp_path: Path) -> None:
    path = tmp_path / "killed.mcap"
    _write_mcap(path, raw=False, n=10, finish=False)
    data = path.read_bytes()
    assert len(await _read(McapSource(path))) <= 10
    path.write_bytes(data[: len(data) // 2])
    await _read(McapSource(path))  # truncated mid-record: no exception


async def test_mcap_source_missing_file(tmp_path: Path) -> None:
    with pytest.raises(IngestError, match="cannot open recording"):
        await _read(McapSource(tmp_path / "none.mcap"))


async def test_zenoh_bridge_applies_backpressure_and_loses_nothing(
        free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    session = open_session(ZenohConfig(listen=[f"tcp/127.0.0.1:{port}"]))
    rig = open_session(ZenohConfig(connect=[f"tcp/127.0.0.1:{port}"]))
    n = 3000
    try:
        async with ZenohSource(session, key_expr_for("rig/Z"), ("rig/Z/tdmon/",),
                               max_buffer=50) as source:
            # the source's subscription has reached the rig (was: a 0.3 s pause)
            probe = rig.declare_publisher("rig/Z/hookload")
            deadline = time.monotonic() + 60
            while not probe.matching_status.matching:
                assert time.monotonic() < deadline, "the subscription never reached the rig"
                await asyncio.sleep(0.02)
            probe.undeclare()

            def publish() -> None:
                block = zenoh.CongestionControl.BLOCK
                rig.put("rig/Z/tdmon/model", b"{}", congestion_control=block)  # ignored
                for i in range(n):
                    rig.put("rig/Z/hookload", str(i).encode(), congestion_control=block)

            publisher = asyncio.create_task(asyncio.to_thread(publish))
            received = []
            async for raw in source:
                received.append(int(raw.payload))
                if len(received) % 500 == 0:
                    await asyncio.sleep(0.05)  # a slow consumer: the callback must wait
                if len(received) == n:
                    break
            await publisher
        assert received == list(range(n))
    finally:
        rig.close()
        session.close()


async def test_supervisor_backs_off_then_connects_and_finishes() -> None:
    attempts = 0
    states: list[str] = []
    seen: dict[str, str] = {}

    @contextlib.asynccontextmanager
    async def connect() -> AsyncIterator[int]:
        nonlocal attempts
        attempts += 1
        if attempts < 3:
            raise IngestError(f"refused #{attempts}")
        yield attempts

    async def work(connection: int) -> None:
        states.append(seen["src"])

    started = time.monotonic()
    await asyncio.wait_for(
        supervise("src", connect, work, seen, Backoff(initial=0.05, maximum=0.1), finite=True),
        5)
    assert attempts == 3 and states == ["connected"] and seen["src"] == "finished"
    assert time.monotonic() - started >= 0.1  # 0.05 + 0.1 of backoff


async def test_supervisor_retries_a_lost_connection_until_cancelled() -> None:
    seen: dict[str, str] = {}
    runs = 0

    @contextlib.asynccontextmanager
    async def connect() -> AsyncIterator[None]:
        yield None

    async def work(connection: None) -> None:
        nonlocal runs
        runs += 1
        raise IngestError("connection lost")

    task = asyncio.create_task(supervise("src", connect, work, seen,
                                         Backoff(initial=0.01, maximum=0.02)))
    deadline = time.monotonic() + 60  # five retries, however slow the machine (was: 0.3 s)
    while runs < 5:
        assert time.monotonic() < deadline and not task.done()
        await asyncio.sleep(0.01)
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    assert runs >= 5 and seen["src"].startswith("retrying")
