"""A fleet daemon stopped and started again keeps each rig's loss counting (issue 32): what a
rig sent over Zenoh while the daemon was away is counted on that rig, from the state kept
beside its own recordings, and nothing on a rig that lost nothing. A found rig retired for
its silence saves its state before it goes.

Two runs of a real fleet daemon in this process, over a real Zenoh peer on 127.0.0.1 that
plays both rigs; the recordings are read back.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh
from daemon_support import FAST_BACKOFF, wait_until

from tdmon.config.daemon import DaemonConfig, parse_daemon_config
from tdmon.daemon.fleet import FleetPipeline, build_fleet
from tdmon.ingest.loss_state import LOSS_STATE_FILE
from tdmon.record.reader import read_messages

CHANNELS = ("hookload", "torque", "bit_depth")
RIGS = ("rig/A", "rig/B")
#: messages per topic: the first run's, those sent while the daemon is away (rig/A only),
#: the second run's
FIRST, AWAY, SECOND = 20, 7, 20
PERIOD = 0.1  # [s] between one topic's samples (rig time)


def _config(folder: Path, rig_port: int, **keys: Any) -> DaemonConfig:
    return parse_daemon_config({
        "prefix": "rig",
        "sources": {"zenoh": {"connect": [f"tcp/127.0.0.1:{rig_port}"]}},
        "publish": {"status_interval": "0.2 s"},
        "recorder": {"enabled": True, "output": str(folder / "rec"),
                     "flush_interval": "0.2 s"},
        "calibration": {"enabled": False},
        "channels": {"hookload": {"unit": "kN"}, "torque": {"unit": "kN*m"},
                     "bit_depth": {"unit": "m"}},
        "rigs": [{"prefix": prefix} for prefix in RIGS],
        **keys,
    }, folder / "fleet.toml")


def _rig_session(port: int) -> zenoh.Session:
    """The rigs' Zenoh peer, listening on ``port`` of 127.0.0.1."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(conf)


def _put(session: zenoh.Session, prefix: str, t0: float, seqs: range) -> None:
    for seq in seqs:
        for channel in CHANNELS:
            body = {"t": t0 + PERIOD * seq, "value": float(seq), "seq": seq}
            session.put(f"{prefix}/{channel}", json.dumps(body).encode(),
                        congestion_control=zenoh.CongestionControl.BLOCK)


async def _run(config: DaemonConfig, session: zenoh.Session,
               publish: Callable[[], None], samples: dict[str, int]) -> FleetPipeline:
    """One run of the fleet daemon: connected, ``publish()``, stopped once each rig took
    ``samples[prefix]`` samples."""
    async with build_fleet(config, backoff=FAST_BACKOFF) as built:
        fleet = built.pipeline
        assert isinstance(fleet, FleetPipeline)
        stop = asyncio.Event()
        task = asyncio.create_task(built.daemon.run(stop))
        try:
            probes = [session.declare_publisher(f"{prefix}/hookload") for prefix in RIGS]
            await wait_until(lambda: all(p.matching_status.matching for p in probes), 20,
                             "the daemon's subscription")
            for probe in probes:
                probe.undeclare()
            publish()
            await wait_until(lambda: all(fleet.rigs[prefix].pipeline.stats.samples_in
                                         >= samples[prefix] for prefix in RIGS), 20,
                             "every sample")
        finally:
            stop.set()
            await asyncio.wait_for(task, 30)
    return fleet


def _loss_alarms(folder: Path) -> list[dict[str, Any]]:
    return [m.message for file in sorted(folder.glob("*.mcap"))
            for m in read_messages(file, "/tdmon/alarm") if m.message["kind"] == "data_loss"]


async def test_a_restarted_fleet_counts_what_each_rig_sent_while_it_was_away(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    rig_port = free_tcp_port()
    session = _rig_session(rig_port)
    config = _config(tmp_path, rig_port)
    t0 = time.time() - 10.0  # the samples are recent, their pace the test's own
    try:
        def first() -> None:
            for prefix in RIGS:
                _put(session, prefix, t0, range(1, FIRST + 1))

        run = await _run(config, session, first, dict.fromkeys(RIGS, 3 * FIRST))
        assert [run.rigs[p].pipeline.stats.seq_lost for p in RIGS] == [0, 0]
        # away: Zenoh keeps nothing for a subscriber that is gone
        _put(session, "rig/A", t0, range(FIRST + 1, FIRST + AWAY + 1))

        def second() -> None:
            _put(session, "rig/A", t0, range(FIRST + AWAY + 1, FIRST + AWAY + SECOND + 1))
            _put(session, "rig/B", t0, range(FIRST + 1, FIRST + SECOND + 1))

        run = await _run(config, session, second, dict.fromkeys(RIGS, 3 * SECOND))
    finally:
        session.close()

    rec = tmp_path / "rec"
    for prefix in RIGS:
        assert (rec / prefix.replace("/", "_") / LOSS_STATE_FILE).is_file()
    # rig/A: exactly what it sent while the daemon was away, one alarm per topic
    assert run.rigs["rig/A"].pipeline.stats.seq_lost == 3 * AWAY
    alarms = _loss_alarms(rec / "rig_A")
    assert sorted((a["message"].split(" on ")[1].split(" ")[0], a["value"]) for a in alarms) \
        == [(f"rig/A/{channel}", AWAY) for channel in sorted(CHANNELS)]
    assert all(f"(seq {FIRST} -> {FIRST + AWAY + 1})" in a["message"] for a in alarms)
    # rig/B lost nothing: nothing counted, no alarm
    assert run.rigs["rig/B"].pipeline.stats.seq_lost == 0
    assert _loss_alarms(rec / "rig_B") == []


async def test_a_retired_rig_saves_its_state_and_goes_on_from_it(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    rig_port = free_tcp_port()
    # rig/C is found by topic and retired after 0.5 s of silence; no status meanwhile (60 s),
    # so its state file can only come from its retirement
    config = _config(tmp_path, rig_port, rigs=[], fleet={"idle_rig_timeout": "0.5 s"},
                     publish={"status_interval": "60 s"})
    session = _rig_session(rig_port)
    state_file = tmp_path / "rec" / "rig_C" / LOSS_STATE_FILE
    t0 = time.time() - 10.0
    try:
        async with build_fleet(config, backoff=FAST_BACKOFF) as built:
            fleet = built.pipeline
            assert isinstance(fleet, FleetPipeline)
            stop = asyncio.Event()
            task = asyncio.create_task(built.daemon.run(stop))
            try:
                probe = session.declare_publisher("rig/C/hookload")
                await wait_until(lambda: probe.matching_status.matching, 20,
                                 "the daemon's subscription")
                probe.undeclare()
                _put(session, "rig/C", t0, range(1, FIRST + 1))
                await wait_until(lambda: fleet.retired == 1, 20, "rig/C's retirement")
                assert "rig/C" not in fleet.rigs
                saved = json.loads(state_file.read_text())
                assert {topic: state["high"] for topic, state in saved["seq"].items()} == {
                    f"rig/C/{channel}": FIRST for channel in CHANNELS}
                # it sends again, 7 numbers per topic later (lost on the way): counted
                _put(session, "rig/C", t0, range(FIRST + AWAY + 1, FIRST + AWAY + SECOND + 1))
                await wait_until(lambda: "rig/C" in fleet.rigs and fleet.rigs[
                    "rig/C"].pipeline.stats.samples_in >= 3 * SECOND, 20, "rig/C again")
            finally:
                stop.set()
                await asyncio.wait_for(task, 30)
    finally:
        session.close()
    assert fleet.rigs["rig/C"].pipeline.stats.seq_lost == 3 * AWAY
    alarms = _loss_alarms(tmp_path / "rec" / "rig_C")
    assert sorted(a["value"] for a in alarms) == [AWAY] * 3
