"""Replaying a recording through the daemon; bounded queues: backpressure and counted drops."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path

from daemon_support import CollectSink, linear_model, make_config
from mcap.writer import Writer

from tdmon.config.daemon import MqttConfig
from tdmon.daemon.pipeline import Emit, Frame, Stats
from tdmon.daemon.runner import run_daemon
from tdmon.ingest.mqtt import MqttPublisher


def _recording(path: Path, rows: int) -> None:
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("any", "jsonschema", b"{}")
        channels = {name: writer.register_channel(f"rig/T1/{name}", "json", schema)
                    for name in ("hookload", "bit_depth", "torque")}
        for i in range(rows):
            t = 1_700_000_000.0 + i
            for name, value in (("bit_depth", 1000.0 + i), ("torque", 5.0),
                                ("hookload", 900.0)):
                body = json.dumps({"t": t, "value": value}).encode()
                writer.add_message(channels[name], int(t * 1e9), body, int(t * 1e9))
        writer.finish()


class SlowStep:
    """Makes the pipeline slower than the source, so the ingest queue fills up."""

    name = "slow"

    def __init__(self) -> None:
        self.frames = 0

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        time.sleep(0.0005)
        self.frames += 1

    def close(self, emit: Emit) -> None:
        pass


async def test_replay_runs_to_the_end_with_a_tiny_queue(tmp_path: Path) -> None:
    path = tmp_path / "in.mcap"
    rows = 400
    _recording(path, rows)
    config = make_config({"sources": {"mcap": {"path": str(path)}},
                          "queues": {"ingest": 4}}, tmp_path)
    sink = CollectSink()
    slow = SlowStep()
    stats = await run_daemon(config, model=linear_model(), extra_sinks=[sink],
                             extra_steps=[slow])
    assert stats.samples_in == 3 * rows and stats.dropped == 0 and stats.rejected == 0
    assert slow.frames == rows == len(sink["model"])
    assert sink["status"][-1]["connections"]["mcap"] == "finished"
    assert sink["status"][-1]["samples_in"] == 3 * rows  # the last status is complete
    assert sink.closed


async def test_publisher_queue_drops_oldest_and_counts() -> None:
    stats = Stats()
    publisher = MqttPublisher(MqttConfig(), "rig/T1", ["model"], queue_size=3,
                              on_drop=stats.count_drop)
    for i in range(10):
        publisher.write("/tdmon/model", 0, {"i": i})
        publisher.write("/tdmon/sample", 0, {"i": i})  # not a published name: ignored
    assert publisher.pending == 3 and publisher.dropped == 7 and stats.dropped == 7
    assert not await publisher.drain(0.05)  # no broker: still pending


async def test_zenoh_source_and_publisher_on_one_session_do_not_deadlock(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    """Regression: results put on the session the source subscribes with were delivered
    locally inside put(), on the loop thread, which blocked once the bridge was full."""
    import zenoh
    from daemon_support import running, wait_until

    port = free_tcp_port()
    config = make_config({
        "prefix": "rig/T1",
        "sources": {"zenoh": {"listen": [f"tcp/127.0.0.1:{port}"]}},
        "publish": {"zenoh": True}, "queues": {"ingest": 8},
    }, tmp_path)
    conf = zenoh.Config()
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    rig = zenoh.open(conf)
    try:
        async with running(config, connected=("zenoh",)) as (built, _):
            # the daemon's subscription has reached the rig (was: a 0.3 s pause)
            probe = rig.declare_publisher("rig/T1/hookload")
            await wait_until(lambda: probe.matching_status.matching, 60, "the subscription")
            probe.undeclare()
            rows = 1500

            def burst() -> None:
                block = zenoh.CongestionControl.BLOCK
                for i in range(rows):
                    for name, value in (("bit_depth", 1000.0), ("torque", 5.0),
                                        ("hookload", 900.0)):
                        body = json.dumps({"t": 1_700_000_000.0 + i, "value": value})
                        rig.put(f"rig/T1/{name}", body.encode(), congestion_control=block)

            await asyncio.wait_for(asyncio.to_thread(burst), 30)
            await wait_until(lambda: built.stats.samples_in == 3 * rows, 30, "all samples")
    finally:
        rig.close()


async def test_recorder_and_rerun_sinks_from_the_config(tmp_path: Path) -> None:
    from tdmon.record.reader import read_messages

    path = tmp_path / "in.mcap"
    _recording(path, 20)
    config = make_config({"sources": {"mcap": {"path": str(path)}},
                          "recorder": {"enabled": True, "output": str(tmp_path / "rec")},
                          "rerun": {"mode": "file", "path": str(tmp_path / "views.rrd")}},
                         tmp_path)
    stats = await run_daemon(config, model=linear_model())
    assert stats.samples_in == 60
    [recording] = (tmp_path / "rec").glob("*.mcap")
    topics = [m.topic for m in read_messages(recording)]
    assert topics.count("/tdmon/raw") == 60 and topics.count("/tdmon/sample") == 60
    assert topics.count("/tdmon/model") == 20 and "/tdmon/status" in topics
    assert (tmp_path / "views.rrd").stat().st_size > 0


async def test_volve_trip_replayed_with_calibration(tmp_path: Path) -> None:
    """The real Volve F-4 trip out (replays/, imported by `tdmon import volve`), through the
    whole pipeline including back-calculation."""
    from daemon_support import WELL_FILE

    path = WELL_FILE.parents[2] / "replays" / "volve-f4-trip-out.mcap"
    count = 1241 * 9  # rows x channels of the source CSV
    config = make_config({
        "prefix": "rig/F4", "sources": {"mcap": {"path": str(path)}},
        "well": str(WELL_FILE.parent / "volve-f4.toml"),
        "calibration": {"enabled": True, "in_slips_margin": "200 kN"},
        "align": {"stale_timeout": "30 s"},  # the log is sampled every 15 s
    }, tmp_path)
    sink = CollectSink()
    stats = await run_daemon(config, extra_sinks=[sink])
    assert stats.samples_in == count and stats.rejected == 0
    assert stats.step_errors == 0 and stats.sink_errors == 0
    states = {m["state"] for m in sink["state"]}
    assert {"in_slips", "pick_up"} <= states, states
    assert len(sink["model"]) > 1000
    assert sink["estimate"], "no friction estimate from a whole trip out"
