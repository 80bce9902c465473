"""Daemon-level fuzz through a real Zenoh link: garbage in, rejections out, daemon unharmed.

The daemon runs on its own event loop in a thread for the whole module, so hypothesis (which
drives synchronous tests) can publish one message per example and check what became of it.
"""

from __future__ import annotations

import asyncio
import json
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
import zenoh
from daemon_support import CollectSink, make_config, running
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tdmon.daemon.build import Built
from tdmon.ingest.types import RawMessage, Rejected

T0 = 1_700_000_000.0


@dataclass
class Harness:
    built: Built
    sink: CollectSink
    rig: zenoh.Session
    decoder: Any


@pytest.fixture(scope="module")
def harness(tmp_path_factory: pytest.TempPathFactory,
            free_tcp_port: Callable[[], int]) -> Iterator[Harness]:
    rig_port, daemon_port = free_tcp_port(), free_tcp_port()
    config = make_config({
        "sources": {"zenoh": {"listen": [f"tcp/127.0.0.1:{daemon_port}"],
                              "connect": [f"tcp/127.0.0.1:{rig_port}"]}},
        "align": {"max_wait": "0 s"},
    }, tmp_path_factory.mktemp("fuzz"))
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{rig_port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    rig = zenoh.open(conf)
    ready = threading.Event()
    holder: dict[str, Any] = {}

    async def serve() -> None:
        stop = asyncio.Event()
        holder["stop"] = stop
        holder["loop"] = asyncio.get_running_loop()
        async with running(config, connected=("zenoh",)) as (built, sink):
            holder["built"], holder["sink"] = built, sink
            ready.set()
            await stop.wait()

    thread = threading.Thread(target=asyncio.run, args=(serve(),), daemon=True)
    thread.start()
    assert ready.wait(20), "daemon did not start"
    # the daemon's subscription has reached the rig (was: a 0.3 s pause)
    probe = rig.declare_publisher("rig/T1/hookload")
    deadline = time.monotonic() + 60
    while not probe.matching_status.matching:
        assert time.monotonic() < deadline, "the subscription never reached the rig"
        time.sleep(0.02)
    probe.undeclare()
    built = holder["built"]
    try:
        yield Harness(built, holder["sink"], rig, built.pipeline.decoder)
    finally:
        holder["loop"].call_soon_threadsafe(holder["stop"].set)
        thread.join(30)
        rig.close()
    assert not thread.is_alive()


garbage_values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
    st.integers(10**308, 10**310), st.text(max_size=10), st.booleans(), st.none(),
    st.lists(st.integers(), max_size=3),
)
time_offsets = st.one_of(st.integers(-5, 40).map(float), st.sampled_from([math.nan, -T0, 1e12]))
units = st.sampled_from([None, "kN", "N", "klbf", "furlong", "m", "", "kN*m", "ft", "degF"])
channels = st.sampled_from(["hookload", "torque", "bit_depth", "rpm", "weather", "tdmonx"])


@st.composite
def messages(draw: st.DrawFn) -> tuple[str, bytes]:
    channel = draw(channels)
    kind = draw(st.sampled_from(["good", "good", "good", "value", "bytes", "huge", "iso"]))
    offset = draw(time_offsets)
    t: object = T0 + offset
    value: object = draw(st.floats(0, 3000)) if kind in ("good", "iso") else draw(garbage_values)
    if kind == "iso":
        t = f"2023-11-14T22:13:{int(abs(offset)) % 60:02d}Z" if offset == offset else "bad"
    body: dict[str, object] = {"t": t, "value": value}
    unit = draw(units)
    if unit is not None:
        body["unit"] = unit
    if kind == "bytes":
        return f"rig/T1/{channel}", draw(st.binary(max_size=64))
    if kind == "huge":
        body["pad"] = "x" * draw(st.integers(4000, 20_000))
    try:
        data = json.dumps(body).encode()
    except (TypeError, ValueError):
        data = repr(body).encode()
    return f"rig/T1/{channel}", data


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(message=messages())
def test_fuzz_through_zenoh(harness: Harness, message: tuple[str, bytes]) -> None:
    topic, data = message
    stats = harness.built.stats
    sink = harness.sink

    def handled() -> int:
        # the sinks are written last: once a message shows there, its counters are final
        return len(sink["sample"]) + len(sink["rejected"])

    before = (handled(), stats.samples_in, stats.rejected, len(sink["model"]))
    expected = harness.decoder.decode(RawMessage("zenoh", topic, data, 0.0))
    harness.rig.put(topic, data, congestion_control=zenoh.CongestionControl.BLOCK)
    deadline = time.monotonic() + 5
    while handled() == before[0]:
        assert time.monotonic() < deadline, "message never reached the daemon"
        time.sleep(0.001)
    if isinstance(expected, Rejected):
        assert stats.rejected == before[2] + 1
        assert stats.samples_in == before[1]
        assert harness.sink["rejected"][-1]["reason"] == expected.reason
        # nothing of it reached the model: any model result since is from accepted samples
        accepted = {m["value"] for m in harness.sink["sample"] if m["channel"] == "hookload"}
        for model in harness.sink["model"][before[3]:]:
            assert model["measured"]["hookload_N"] in accepted
    else:
        assert stats.samples_in == before[1] + 1
        assert harness.sink["sample"][-1]["value"] == expected.value


def test_after_fuzzing_only_clean_values_reached_the_model(harness: Harness) -> None:
    accepted = {(m["channel"], m["t"], m["value"]) for m in harness.sink["sample"]}
    hookloads = {value for channel, _, value in accepted if channel == "hookload"}
    for model in harness.sink["model"]:
        assert model["measured"]["hookload_N"] in hookloads
        assert all(math.isfinite(v) for v in model["hookload_N"].values())
    stats = harness.built.stats
    assert stats.messages_in == stats.samples_in + stats.rejected
    # out-of-order and duplicate hook loads were counted and made no frame out of order
    frame_times = [m["t"] for m in harness.sink["state"]]
    assert frame_times == sorted(frame_times)
    assert stats.duplicates + stats.out_of_order > 0
    assert stats.step_errors == 0 and stats.sink_errors == 0
