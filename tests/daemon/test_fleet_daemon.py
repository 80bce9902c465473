"""One daemon, many rigs: the ``[[rigs]]``/``[fleet]`` keys, and real runs over Zenoh and a real
mosquitto with three rigs, results on each rig's prefix and one recording per rig read back."""

from __future__ import annotations

import asyncio
import json
import shutil
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
import zenoh
from daemon_support import FAST_BACKOFF, WELL_FILE, CollectSink, payload, wait_until

from tdmon.config.daemon import DaemonConfig, parse_daemon_config
from tdmon.config.well import load_well_model
from tdmon.daemon.fleet import FleetPipeline, build_fleet
from tdmon.errors import ConfigError
from tdmon.model.torque_drag import torque_drag
from tdmon.record.reader import read_messages

STEPS = 8
MONITOR = {"mu": 0.25, "band_mu": [0.1, 0.2, 0.3], "method": "aadnoy", "grid_step": "1 m"}


def _fleet_config(data: dict[str, Any], folder: Path) -> DaemonConfig:
    base = {"prefix": "rig", "well": str(WELL_FILE), "monitor": MONITOR,
            "publish": {"status_interval": "0.2 s"},
            "align": {"max_wait": "3 s"},  # frames wait for their bit depth on a busy machine
            "channels": {"hookload": {"unit": "kN"}, "torque": {"unit": "kN*m"},
                         "bit_depth": {"unit": "m"}}}
    return parse_daemon_config({**base, **data}, folder / "fleet.toml")


def test_a_rig_inherits_the_file_and_replaces_only_the_keys_it_sets(tmp_path: Path) -> None:
    config = _fleet_config({
        "sources": {"zenoh": {}},
        "rigs": [{"prefix": "rig/A"},
                 {"prefix": "rig/B", "monitor": {"mu": 0.35},
                  "channels": {"hookload": {"unit": "klbf"}}}],
    }, tmp_path)
    assert config.is_fleet
    a, b = config.for_rig("rig/A", config.rigs[0]), config.for_rig("rig/B", config.rigs[1])
    assert (a.prefix, a.monitor.mu, a.channels["hookload"].unit) == ("rig/A", 0.25, "kN")
    assert b.monitor.mu == 0.35 and b.monitor.band_mu == [0.1, 0.2, 0.3]  # the rest inherited
    assert b.channels["hookload"].unit == "klbf" and b.channels["torque"].unit == "kN*m"
    assert b.well == a.well and not b.is_fleet


@pytest.mark.parametrize(("data", "key", "reason"), [
    ({"rigs": [{"prefix": "other/A"}]}, "rigs[0].prefix", "not under"),
    ({"rigs": [{"prefix": "rig/A"}, {"prefix": "rig/A"}]}, "rigs[1].prefix", "listed twice"),
    ({"rigs": [{"prefix": "rig/A"}, {"prefix": "rig/A/x"}]}, "rigs[1].prefix", "nests"),
    ({"rigs": [{"prefix": "rig/A", "monitor": {"mu": 2.0}}]}, "rigs[0].monitor.mu", ""),
    ({"rigs": [{"prefix": "rig/A", "well": "nowhere.toml"}]}, "rigs[0].well", "not found"),
    ({"fleet": {"wells": "no-such-folder"}}, "fleet.wells", "no such folder"),
    ({"fleet": {}, "rerun": {"mode": "file", "path": "x.rrd"}}, "rerun.mode", "tdmon fleet"),
])
def test_fleet_mistakes_name_their_key(tmp_path: Path, data: dict[str, Any], key: str,
                                       reason: str) -> None:
    with pytest.raises(ConfigError) as caught:
        _fleet_config({"sources": {"zenoh": {}}, **data}, tmp_path)
    assert caught.value.key == key and reason in caught.value.reason


def test_a_single_rig_file_is_no_fleet(tmp_path: Path) -> None:
    config = _fleet_config({"prefix": "rig/F4", "sources": {"zenoh": {}}}, tmp_path)
    assert not config.is_fleet and config.rigs == [] and config.fleet is None


def test_topics_route_to_their_rig_and_results_are_not_input(tmp_path: Path) -> None:
    config = _fleet_config({"sources": {"zenoh": {}}, "rigs": [{"prefix": "rig/north/A"}],
                            "fleet": {"max_rigs": 2}}, tmp_path)
    made: list[str] = []

    class Named(str):
        """A stand-in for a rig's pipeline: its prefix, without recorders."""

        recorders: tuple[Any, ...] = ()

    def make(prefix: str, rig: Any) -> Any:
        made.append(prefix)
        return type("Rig", (), {"pipeline": Named(prefix)})()

    fleet = FleetPipeline(config, make)
    sample = payload(1.7e9, 900.0)
    assert fleet._route("rig/north/A/hookload") == "rig/north/A"  # listed, two levels
    assert fleet._route("rig/B/hookload") is None  # found by topic, but no valid sample yet
    assert fleet._route("rig/B/hookload", sample) == "rig/B"  # found by its first sample
    assert fleet._route("rig/B/tdmon/state") is None  # a result, not input
    assert fleet._route("rig/A/tdmon/state", sample) is None
    assert fleet._route("rig/tdmon/status", sample) is None
    assert fleet._route("other/B/hookload", sample) is None
    assert fleet._route("rig/C/hookload", sample) is None  # max_rigs = 2 reached
    assert made == ["rig/north/A", "rig/B"]


def _sequence(t0: float, offset: float) -> list[tuple[float, float, float, float]]:
    """(t, hook load [kN], torque [kN m], bit depth [m]): picking up, each rig its own depth."""
    return [(t0 + 0.1 * i, 900.0 + 3.0 * i, 12.0 + 0.1 * i, 2000.0 + offset - 0.5 * i)
            for i in range(STEPS)]


def _check_rig(models: list[dict[str, Any]], sequence: list[tuple[float, float, float, float]],
               mu: float) -> None:
    well = load_well_model(WELL_FILE)
    by_t = {round(m["t"], 6): m for m in models}
    for t, hookload_kn, _, bit_depth in sequence:
        message = by_t[round(t, 6)]
        assert message["bit_depth_m"] == pytest.approx(bit_depth)
        assert message["measured"]["hookload_N"] == pytest.approx(hookload_kn * 1e3)
        expected = torque_drag(well, bit_depth, mu, method="aadnoy").hookload["pick_up"]
        assert message["hookload_N"]["pick_up"] == pytest.approx(expected, rel=1e-5)


def _recorded(folder: Path) -> dict[str, list[dict[str, Any]]]:
    files = sorted(folder.glob("*.mcap"))
    assert files, f"no recording in {folder}"
    by_topic: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for file in files:
        for recorded in read_messages(file):
            by_topic[recorded.topic].append(recorded.message)
    return by_topic


async def _run_fleet(config: DaemonConfig, publish: Callable[[], Any],
                     done: Callable[[], bool], extra_sinks: Sequence[Any] = ()) -> FleetPipeline:
    async with build_fleet(config, backoff=FAST_BACKOFF, extra_sinks=extra_sinks) as built:
        stop = asyncio.Event()
        task = asyncio.create_task(built.daemon.run(stop))
        try:
            await wait_until(lambda: all(state == "connected" for state in
                                         built.daemon.connections.values())
                             and bool(built.daemon.connections), 10, "connections")
            await publish()
            await wait_until(done, 20, "every rig's results")
        finally:
            stop.set()
            await asyncio.wait_for(task, 30)
    assert isinstance(built.pipeline, FleetPipeline)
    return built.pipeline


RIGS = {"rig/A": (0.25, 0.0), "rig/B": (0.35, 100.0), "rig/C": (0.25, 200.0)}


def _three_rigs(tmp_path: Path, sources: dict[str, Any], publish: dict[str, Any]
                ) -> DaemonConfig:
    wells = tmp_path / "wells"
    wells.mkdir()
    shutil.copy(WELL_FILE, wells / "C.toml")  # rig/C is found by topic, its well by name
    return _fleet_config({
        "sources": sources, "publish": {**publish, "status_interval": "0.2 s"},
        "recorder": {"enabled": True, "output": str(tmp_path / "rec"), "flush_interval": "0.2 s"},
        "rigs": [{"prefix": "rig/A"}, {"prefix": "rig/B", "monitor": {"mu": 0.35}}],
        "fleet": {"wells": "wells"},
    }, tmp_path)


def _check_three_rigs(fleet: FleetPipeline, results: dict[str, list[dict[str, Any]]],
                      sequences: dict[str, list[tuple[float, float, float, float]]],
                      tmp_path: Path) -> None:
    assert sorted(fleet.rigs) == sorted(RIGS)
    assert fleet.rigs["rig/C"].config.well == tmp_path / "wells" / "C.toml"
    for prefix, (mu, _) in RIGS.items():
        _check_rig(results[f"{prefix}/tdmon/model"], sequences[prefix], mu)
        assert results[f"{prefix}/tdmon/status"], f"no status from {prefix}"
        stats = fleet.rigs[prefix].pipeline.stats
        assert (stats.samples_in, stats.rejected) == (3 * STEPS, 0)
        recorded = _recorded(tmp_path / "rec" / prefix.replace("/", "_"))
        # the rig's own input only: its recording replays on its own
        assert {s["topic"] for s in recorded["/tdmon/sample"]} == {
            f"{prefix}/{channel}" for channel in ("hookload", "torque", "bit_depth")}
        assert len(recorded["/tdmon/sample"]) == 3 * STEPS
        _check_rig(recorded["/tdmon/model"], sequences[prefix], mu)
    assert fleet.stats.samples_in == 3 * 3 * STEPS and fleet.unrouted == 0


async def test_three_rigs_over_zenoh(tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    rig_port, daemon_port = free_tcp_port(), free_tcp_port()
    config = _three_rigs(tmp_path, {"zenoh": {"listen": [f"tcp/127.0.0.1:{daemon_port}"],
                                              "connect": [f"tcp/127.0.0.1:{rig_port}"]}},
                         {"zenoh": True})
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{rig_port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    rigs = zenoh.open(conf)
    results: dict[str, list[dict[str, Any]]] = defaultdict(list)
    sequences = {prefix: _sequence(time.time(), offset) for prefix, (_, offset) in RIGS.items()}

    async def publish() -> None:
        # the daemon's subscriptions have reached the rigs (was: a 0.3 s pause)
        probes = [rigs.declare_publisher(f"{prefix}/hookload") for prefix in sequences]
        await wait_until(lambda: all(p.matching_status.matching for p in probes), 60,
                         "the subscriptions")
        for probe in probes:
            probe.undeclare()
        block = zenoh.CongestionControl.BLOCK
        for prefix, sequence in sequences.items():
            for t, hookload, torque, bit_depth in sequence:
                for channel, value in (("hookload", hookload), ("torque", torque),
                                       ("bit_depth", bit_depth)):
                    rigs.put(f"{prefix}/{channel}", payload(t, value), congestion_control=block)

    def done() -> bool:
        return all(len(results[f"{p}/tdmon/model"]) >= STEPS for p in RIGS)

    try:
        subscriber = rigs.declare_subscriber(
            "rig/*/tdmon/**",
            lambda s: results[str(s.key_expr)].append(json.loads(s.payload.to_bytes())))
        # a sink every rig writes to, as `tdmon run` passes its status line
        shared = CollectSink()
        fleet = await _run_fleet(config, publish, done, extra_sinks=[shared])
        subscriber.undeclare()
    finally:
        rigs.close()
    _check_three_rigs(fleet, results, sequences, tmp_path)
    # every rig's model frames, as each rig recorded them
    assert len(shared["model"]) == sum(
        len(_recorded(tmp_path / "rec" / p.replace("/", "_"))["/tdmon/model"]) for p in RIGS)


async def test_three_rigs_over_mqtt(mosquitto: Any, tmp_path: Path) -> None:
    config = _three_rigs(tmp_path, {"mqtt": {"port": mosquitto.port, "client_id": "fleet"}},
                         {"mqtt": True})
    results: dict[str, list[dict[str, Any]]] = defaultdict(list)
    sequences = {prefix: _sequence(time.time(), offset) for prefix, (_, offset) in RIGS.items()}
    async with aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="ops") as ops:
        await ops.subscribe("rig/+/tdmon/#", qos=1)

        async def listen() -> None:
            async for message in ops.messages:
                assert isinstance(message.payload, bytes)
                results[str(message.topic)].append(json.loads(message.payload))

        async def publish() -> None:
            async with aiomqtt.Client("127.0.0.1", mosquitto.port, identifier="rigs") as rigs:
                for prefix, sequence in sequences.items():
                    for t, hookload, torque, bit_depth in sequence:
                        for channel, value in (("hookload", hookload), ("torque", torque),
                                               ("bit_depth", bit_depth)):
                            await rigs.publish(f"{prefix}/{channel}", payload(t, value), qos=1)

        def done() -> bool:
            return all(len(results[f"{p}/tdmon/model"]) >= STEPS for p in RIGS)

        listener = asyncio.create_task(listen())
        try:
            fleet = await _run_fleet(config, publish, done)
        finally:
            listener.cancel()
    _check_three_rigs(fleet, results, sequences, tmp_path)
