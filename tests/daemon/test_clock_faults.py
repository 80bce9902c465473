"""Clock faults (issue 13, item 1): a future-stamped sample or a rig clock jump never stalls the
results silently.

The pipeline tests feed a recording with the fault injected through the daemon's own pipeline
(the replay driver: real decoder, clock guard, aligner, monitor and MCAP recorder) and read the
flight recording back. The rig sends hook load, torque and bit depth every 0.5 s with 50 ms of
latency; the fault sits at rig time +60 s of a 120 s session.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
import zenoh
from daemon_support import WELL_FILE, make_config, payload, running, wait_until
from mcap.writer import Writer

from tdmon.config.daemon import load_daemon_config
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.clock import ClockGuard, ClockSettings
from tdmon.daemon.pipeline import Pipeline
from tdmon.errors import ConfigError
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.types import RawMessage, Sample
from tdmon.record.reader import read_messages
from tdmon.replay.driver import replay

T0 = 1_700_000_000.0
STEP = 0.5  # [s] between samples of one channel
N = 240  # samples per channel: 120 s
FAULT = 120  # index of the first faulty sample (rig time T0 + 60 s)
LATENCY = 0.05  # [s]
DAY = 86400.0
CHANNELS = ("hookload", "torque", "bit_depth")


def _value(channel: str, i: int) -> float:
    # pulling out of hole: hook load [kN], torque [kN m], bit depth [m]
    return {"hookload": 900.0 + 0.1 * i, "torque": 12.0, "bit_depth": 2000.0 - 0.1 * i}[channel]


def _session(stamp: Any = None) -> list[tuple[float, str, float, float]]:
    """(receive time, channel, t, value) in arrival order; ``stamp(i, channel, t)`` returns
    the rig's stamp for the true time t (default: the true time)."""
    rows = []
    for i in range(N):
        true_t = T0 + STEP * i
        for channel in CHANNELS:
            t = true_t if stamp is None else stamp(i, channel, true_t)
            rows.append((true_t + LATENCY, channel, t, _value(channel, i)))
    return rows


def _write_input(path: Path, rows: list[tuple[float, str, float, float]]) -> None:
    """A flight recording's /tdmon/raw messages: what the daemon received, and when."""
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("raw", "jsonschema", b"{}")
        channel_id = writer.register_channel("/tdmon/raw", "json", schema)
        for receive_time, channel, t, value in rows:
            record = {"source": "mqtt", "topic": f"rig/T1/{channel}",
                      "receive_time": receive_time, "payload": payload(t, value).decode(),
                      "payload_encoding": "utf-8"}
            ns = int(receive_time * 1e9)
            writer.add_message(channel_id, ns, json.dumps(record).encode(), ns)
        writer.finish()


def _replay(tmp_path: Path, rows: list[tuple[float, str, float, float]]
            ) -> dict[str, list[dict[str, Any]]]:
    source, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    _write_input(source, rows)
    config = make_config({"well": str(WELL_FILE), "monitor": {"grid_step": "5 m"},
                          "sources": {"mcap": {"path": str(source)}}}, tmp_path)
    result = asyncio.run(replay(source, config, out, separate_writer=False))
    assert result.step_errors == 0 and result.sink_errors == 0
    recorded: dict[str, list[dict[str, Any]]] = {}
    for message in read_messages(out):
        recorded.setdefault(message.topic, []).append(message.message)
    return recorded


def _models_by_hookload(recorded: dict[str, list[dict[str, Any]]]) -> list[float]:
    return [m["t"] for m in recorded.get("/tdmon/model", [])]


def _alarms(recorded: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    return [a for a in recorded.get("/tdmon/alarm", []) if a["kind"] == "clock_jump"]


def test_a_clean_session_has_a_result_per_hook_load_and_no_alarm(tmp_path: Path) -> None:
    recorded = _replay(tmp_path, _session())
    assert len(recorded["/tdmon/model"]) == N
    assert "/tdmon/rejected" not in recorded and _alarms(recorded) == []


@pytest.mark.parametrize("ahead", [20.0, 30 * DAY])
def test_one_hook_load_stamped_ahead_is_rejected_and_results_go_on(
        tmp_path: Path, ahead: float) -> None:
    def stamp(i: int, channel: str, t: float) -> float:
        return t + ahead if (i, channel) == (FAULT, "hookload") else t

    recorded = _replay(tmp_path, _session(stamp))
    rejected = recorded["/tdmon/rejected"]
    assert len(rejected) == 1
    assert rejected[0]["reason"].startswith("t in the future (")
    assert json.loads(rejected[0]["payload"])["t"] == pytest.approx(T0 + STEP * FAULT + ahead)
    # a rejected sample is no clock jump: no alarm
    assert _alarms(recorded) == []
    # every other hook load made its result, in time order: nothing was held back
    models = _models_by_hookload(recorded)
    expected = [T0 + STEP * i for i in range(N) if i != FAULT]
    assert models == pytest.approx(expected)


@pytest.mark.parametrize("jump", [-3600.0, 3600.0])
def test_a_clock_jump_raises_one_alarm_and_results_resume(tmp_path: Path, jump: float) -> None:
    def stamp(i: int, channel: str, t: float) -> float:
        return t + jump if i >= FAULT else t

    recorded = _replay(tmp_path, _session(stamp))
    alarms = _alarms(recorded)
    assert len(alarms) == 1
    alarm = alarms[0]
    direction = "back" if jump < 0 else "forward"
    assert alarm["message"].startswith(f"rig clock went {direction} 3600 s;")
    assert alarm["severity"] == "warning" and alarm["value"] == pytest.approx(jump)
    models = _models_by_hookload(recorded)
    # the results in the order they were recorded: the old clock's, then the new one's
    split = next(k for k in range(1, len(models)) if abs(models[k] - models[k - 1]) > 1000)
    before, after = models[:split], models[split:]
    # every hook load before the jump made its result
    assert before == pytest.approx([T0 + STEP * i for i in range(FAULT)])
    # results resume on the new clock within a few samples (5 per channel at most: 2.5 s)
    first_after = (min(after) - (T0 + jump)) / STEP
    assert FAULT <= first_after <= FAULT + 5
    assert after[-1] == pytest.approx(T0 + jump + STEP * (N - 1))
    # and every hook load after that made one
    assert len(after) == N - round(first_after)
    rejected = recorded.get("/tdmon/rejected", [])
    if jump > 0:
        # the forward jump's first samples, until confirmed, are rejected with the reason
        assert 1 <= len(rejected) <= 4
        assert all(r["reason"].startswith("t in the future (") for r in rejected)
    else:
        assert rejected == []  # going back loses nothing: the samples are replayed


def test_clock_back_then_a_spike_on_the_new_clock_is_still_rejected() -> None:
    """After the guard learns the new offset, the tolerance applies around it."""
    decoder = Decoder("rig", [ChannelSpec("hookload", "hookload", "kN"),
                              ChannelSpec("torque", "torque", "kN*m"),
                              ChannelSpec("bit_depth", "bit_depth", "m")])
    aligner = Aligner()
    guard = ClockGuard(ClockSettings())
    pipeline = Pipeline(decoder, aligner, clock=guard)

    def send(channel: str, t: float, receive: float) -> None:
        pipeline.process(RawMessage("mqtt", f"rig/{channel}", payload(t, 1.0), receive))

    for i in range(N):
        true_t = T0 + STEP * i
        t = true_t - 3600 if i >= FAULT else true_t
        for channel in CHANNELS:
            spike = 20.0 if (i, channel) == (FAULT + 20, "hookload") else 0.0
            send(channel, t + spike, true_t + LATENCY)
    assert pipeline.stats.clock_jumps == 1
    assert guard.offset == pytest.approx(-3600 - LATENCY)
    assert pipeline.stats.rejected_reasons == {"t in the future": 1}


class _Rig:
    """The rig's side of a live test: publishes payloads over MQTT (QoS 1) or Zenoh (blocking)."""

    def __init__(self, put: Callable[[str, bytes], Awaitable[None]]) -> None:
        self.put = put


@asynccontextmanager
async def _live(transport: str, tmp_path: Path, mosquitto_port: int | None,
                free_tcp_port: Callable[[], int]) -> AsyncIterator[tuple[Any, Any, _Rig]]:
    """A daemon on a real mosquitto or a real Zenoh peer session, and the rig's publisher."""
    common = {"well": str(WELL_FILE), "align": {"max_wait": "3 s"}}
    if transport == "mqtt":
        config = make_config({"sources": {"mqtt": {"port": mosquitto_port,
                                                   "client_id": "tdmon-clock"}}, **common},
                             tmp_path)
        async with (running(config, connected=("mqtt",)) as (built, sink),
                    aiomqtt.Client("127.0.0.1", mosquitto_port, identifier="rig") as client):
            async def put_mqtt(topic: str, data: bytes) -> None:
                await client.publish(topic, data, qos=1)

            yield built, sink, _Rig(put_mqtt)
        return
    rig_port, daemon_port = free_tcp_port(), free_tcp_port()
    config = make_config({"sources": {"zenoh": {
        "listen": [f"tcp/127.0.0.1:{daemon_port}"],
        "connect": [f"tcp/127.0.0.1:{rig_port}"]}}, **common}, tmp_path)
    rig_conf = zenoh.Config()
    rig_conf.insert_json5("mode", '"peer"')
    rig_conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{rig_port}"]))
    rig_conf.insert_json5("scouting/multicast/enabled", "false")
    rig_conf.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(rig_conf)
    try:
        async with running(config, connected=("zenoh",)) as (built, sink):
            # the daemon's subscription has reached the rig (was: a 0.3 s pause)
            probe = session.declare_publisher("rig/T1/hookload")
            await wait_until(lambda: probe.matching_status.matching, 60, "the subscription")
            probe.undeclare()

            async def put_zenoh(topic: str, data: bytes) -> None:
                session.put(topic, data, congestion_control=zenoh.CongestionControl.BLOCK)

            yield built, sink, _Rig(put_zenoh)
    finally:
        session.close()


@pytest.mark.parametrize("transport", ["mqtt", "zenoh"])
async def test_clock_faults_live(transport: str, mosquitto: Any, tmp_path: Path,
                                 free_tcp_port: Callable[[], int]) -> None:
    """A live daemon on mosquitto and on Zenoh: a +30 day hook load is rejected, a rig clock
    going back an hour raises one alarm, and model results come back on the new clock."""
    async with _live(transport, tmp_path, mosquitto.port, free_tcp_port) as (built, sink, rig):
        async def send(i: int, clock: float = 0.0) -> float:
            # the rig stamps with its clock (``clock`` off the true time), all three channels
            # of one step with one time, the hook load last so that each frame is complete
            t = time.time() + clock
            for channel in ("bit_depth", "torque", "hookload"):
                unit = {"hookload": "kN", "torque": "kN*m", "bit_depth": "m"}[channel]
                await rig.put(f"rig/T1/{channel}", payload(t, _value(channel, i), unit))
            await asyncio.sleep(0.02)
            return t

        for i in range(10):
            await send(i)
        await wait_until(lambda: len(sink["model"]) >= 10, 20, "results before the faults")
        await rig.put("rig/T1/hookload", payload(time.time() + 30 * DAY, 950.0, "kN"))
        for i in range(10, 20):
            await send(i)
        await wait_until(lambda: len(sink["model"]) >= 20, 20, "results after the spike")
        assert [r["reason"][:15] for r in sink["rejected"]] == ["t in the future"]
        assert [a for a in sink["alarm"] if a["kind"] == "clock_jump"] == []
        # the rig clock goes back an hour
        stamps = [await send(i, -3600.0) for i in range(20, 40)]
        await wait_until(lambda: len(sink["model"]) >= 40, 20, "results after the jump")
    jumps = [a for a in sink["alarm"] if a["kind"] == "clock_jump"]
    assert len(jumps) == 1
    assert jumps[0]["message"] == "rig clock went back 3600 s; aligner re-anchored"
    # every hook load on the new clock made its result, those that confirmed the jump too
    assert [m["t"] for m in sink["model"][20:]] == stamps
    assert len(sink["model"]) == 40 and len(sink["rejected"]) == 1
    assert built.stats.clock_jumps == 1


# -- item 8 through the daemon: the config's limits reach the decoder ------------------------

def test_misleading_samples_are_recorded_as_rejected_with_their_reason(tmp_path: Path) -> None:
    faults = {(30, "hookload"): ("t", 0.0),  # a rig clock never set: 1970
              (31, "bit_depth"): ("value", -50.0),  # a sign mistake
              (32, "bit_depth"): ("value", 2000.0 / 0.3048)}  # feet sent as metres: 6562 m
    rows = []
    for receive_time, channel, t, value in _session():
        i = round((receive_time - LATENCY - T0) / STEP)
        field, bad = faults.get((i, channel), (None, None))
        rows.append((receive_time, channel, bad if field == "t" else t,
                     bad if field == "value" else value))
    recorded = _replay(tmp_path, rows)
    reasons = [r["reason"] for r in recorded["/tdmon/rejected"]]
    # the well file's hole reaches 4223.6 m; 500 m beyond is allowed by default
    assert reasons == [
        "t before the earliest accepted time (1970-01-01T00:00:00Z < 2000-01-01: a rig clock "
        "that was never set)",
        "value -50 below the bit_depth minimum -2 m",
        "beyond the well: bit_depth 6561.68 m > 4723.6 m (the well's total depth 4223.6 m + "
        "500 m)"]
    assert len(recorded["/tdmon/model"]) == N - 1  # all but the 1970 hook load
    assert max(m["bit_depth_m"] for m in recorded["/tdmon/model"]) <= 2000.0
    assert min(m["bit_depth_m"] for m in recorded["/tdmon/model"]) >= 0.0


def _config(data: dict[str, Any], folder: Path) -> Any:
    return make_config({"sources": {"mqtt": {}}, **data}, folder)


def test_clock_keys_of_the_daemon_file(tmp_path: Path) -> None:
    file = tmp_path / "daemon.toml"
    file.write_text('''prefix = "rig/T1"
[sources.mqtt]
[align]
future_tolerance = "1 min"
clock_jump_samples = 8
clock_jump_spread = "2 s"
earliest_time = 2010-01-01        # a TOML date
[channels.bit_depth]
beyond_well = "100 ft"
min = "-1 m"
''')
    config = load_daemon_config(file)
    assert config.align.future_tolerance == 60.0
    assert config.align.clock_jump_samples == 8 and config.align.clock_jump_spread == 2.0
    assert config.align.earliest_time == 1_262_304_000.0
    assert config.depth_margins() == {"bit_depth": pytest.approx(30.48), "hole_depth": 500.0}
    specs = {spec.channel: spec for spec in config.channel_specs()}
    assert specs["bit_depth"].minimum == -1.0 and specs["hole_depth"].minimum == -2.0
    assert specs["block_position"].minimum == -2.0 and specs["hookload"].minimum is None
    assert _config({"align": {"earliest_time": "2016-10-04T17:00:00+02:00"}},
                   tmp_path).align.earliest_time == 1_475_593_200.0
    assert _config({}, tmp_path).align.earliest_time == 946_684_800.0  # 2000-01-01


@pytest.mark.parametrize(("data", "key", "words"), [
    ({"channels": {"hookload": {"beyond_well": "10 m"}}}, "channels.hookload.beyond_well",
     "only depths"),
    ({"align": {"earliest_time": "last year"}}, "align.earliest_time", "not ISO 8601"),
    ({"align": {"clock_jump_samples": 1}}, "align.clock_jump_samples", "2"),
    ({"align": {"future_tolerance": "0 s"}}, "align.future_tolerance", "0"),
])
def test_clock_key_mistakes_name_the_key(tmp_path: Path, data: dict[str, Any], key: str,
                                         words: str) -> None:
    with pytest.raises(ConfigError) as error:
        _config(data, tmp_path)
    assert key in str(error.value) and words in str(error.value)


# -- what is not a clock jump ----------------------------------------------------------------

def _hookload(t: float, receive_time: float) -> Sample:
    return Sample("hookload", t, 1e6, "mqtt", "rig/hookload", "N", receive_time)


def test_late_hook_loads_of_many_ages_are_no_clock_jump() -> None:
    aligner = Aligner()
    frames = [f for i in range(20) for f in aligner.push(_hookload(T0 + i, T0 + i), 0.0)]
    # a backlog of old hook loads, delivered now: out of order, offsets 15-55 s apart
    for age in (60, 20, 45, 30, 75, 50, 35):
        frames += aligner.push(_hookload(T0 + 19 - age, T0 + 20), 0.0)
    assert aligner.take_jumps() == () and aligner.out_of_order == 7
    assert [f.t for f in frames] == sorted(f.t for f in frames)


def test_a_clock_back_by_less_than_the_tolerance_is_a_hold_up_not_a_jump() -> None:
    aligner = Aligner(jump_min=10.0)
    for i in range(20):
        aligner.push(_hookload(T0 + i, T0 + i), 0.0)
    frames = []
    for i in range(20, 40):  # the rig clock 8 s back: frames wait until t passes T0 + 19
        frames += aligner.push(_hookload(T0 + i - 8, T0 + i), 0.0)
    assert aligner.take_jumps() == ()
    assert [f.t for f in frames] == [T0 + i - 8 for i in range(28, 40)]


def test_a_clock_back_by_more_than_the_tolerance_is_one_jump() -> None:
    aligner = Aligner(jump_min=10.0, jump_samples=5)
    for i in range(20):
        aligner.push(_hookload(T0 + i, T0 + i), 0.0)
    frames = []
    for i in range(20, 40):
        frames += aligner.push(_hookload(T0 + i - 12.5, T0 + i), 0.0)
    jumps = aligner.take_jumps()
    assert [(j.seconds, j.offset) for j in jumps] == [(-12.5, -12.5)]
    assert jumps[0].message == "rig clock went back 12 s; aligner re-anchored"
    # every hook load on the new clock made its frame, those that confirmed the jump too
    assert [f.t for f in frames] == [T0 + i - 12.5 for i in range(20, 40)]
