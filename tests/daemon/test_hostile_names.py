"""Hostile rig names and first messages against the many-rigs daemon (issue 32).

A NUL in a rig name (``rig/a\\x00b/hookload``) once stopped the fleet daemon (the recorder's
folder could not be made, ``ValueError`` past the handler); a newline became a folder and a
forged log line; any topic under the root created a rig, and the 200 slots were never freed.
Names are now checked (tdmon/config/rig_names.py), a rig needs a valid first sample, refusals
are counted, and silent rigs are retired.

The fuzz tests run the real fleet daemon (``build_fleet``) on its own event loop in a thread,
fed through a real Zenoh peer session and a real mosquitto; hypothesis drives the topics and
payloads, one message per example, each waited for until the daemon has taken it.
"""

from __future__ import annotations

import asyncio
import json
import logging
import re
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import paho.mqtt.client as mqtt
import pytest
import zenoh
from daemon_support import FAST_BACKOFF, WELL_FILE, payload
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tdmon.config.daemon import DaemonConfig, parse_daemon_config
from tdmon.config.rig_names import DEFAULT_NAME_PATTERN, name_refusal, printable
from tdmon.daemon.fleet import FleetPipeline, build_fleet
from tdmon.errors import ConfigError

SAFE = re.compile(DEFAULT_NAME_PATTERN)
MONITOR = {"mu": 0.25, "band_mu": [0.2], "method": "aadnoy", "grid_step": "10 m"}


def _config(data: dict[str, Any], folder: Path) -> DaemonConfig:
    base = {"prefix": "rig", "well": str(WELL_FILE), "monitor": MONITOR,
            "calibration": {"enabled": False},
            "channels": {"hookload": {"unit": "kN"}}}
    return parse_daemon_config({**base, **data}, folder / "fleet.toml")


@pytest.mark.parametrize(("name", "refused"), [
    ("F4", False), ("rig-7.north_2", False), ("x" * 64, False),
    ("a\x00b", True), ("a\nb", True), ("..", True), (".", True), (".hidden", True),
    ("-rf", True), ("a b", True), ("a\\b", True), ("x" * 65, True), ("x" * 60_000, True),
    ("forage\u0301", True), ("\u2028", True), ("", True),
])
def test_the_name_rule(name: str, refused: bool) -> None:
    reason = name_refusal(name, SAFE)
    assert (reason is not None) == refused
    if reason is not None:
        assert len(reason) < 80 and (len(name) < 3 or name not in reason)  # no quoting


def test_a_name_is_shown_escaped_and_cut_short() -> None:
    shown = printable("a\nb\x00c\u00e9" + "y" * 10_000)
    assert "\n" not in shown and "\x00" not in shown and shown.isascii()
    assert shown.startswith("a\\x0ab\\x00c\\xe9") and shown.endswith("(10006 characters)")
    assert len(shown) < 120


class _Pipeline:
    """A stand-in for a rig's pipeline: counts what it is given."""

    recorders: tuple[Any, ...] = ()

    def __init__(self, prefix: str) -> None:
        from tdmon.daemon.pipeline import Stats
        self.prefix = prefix
        self.stats = Stats()
        self.messages: list[Any] = []
        self.flushed = False

    def process_burst(self, raws: list[Any]) -> None:
        self.messages.extend(raws)
        self.stats.messages_in += len(raws)

    def tick(self) -> None:
        pass

    def flush(self) -> None:
        self.flushed = True

    def save_state(self) -> None:
        pass


class _Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def _raw(topic: str, data: bytes) -> Any:
    from tdmon.ingest.types import RawMessage
    return RawMessage("zenoh", topic, data, 0.0)


def _fleet(tmp_path: Path, fleet: dict[str, Any], clock: _Clock
           ) -> tuple[FleetPipeline, list[str], list[Any]]:
    from tdmon.daemon.fleet import Rig
    config = _config({"sources": {"zenoh": {}}, "rigs": [{"prefix": "rig/L"}],
                      "fleet": fleet}, tmp_path)
    made: list[str] = []
    closed: list[Any] = []

    class Owned:
        def close(self) -> None:
            closed.append(self)

    def make(prefix: str, rig: Any) -> Any:
        made.append(prefix)
        return Rig(prefix, config, _Pipeline(prefix), owned=[Owned()],  # type: ignore[arg-type]
                   last_message=clock())

    return FleetPipeline(config, make, clock=clock), made, closed


GOOD = payload(1.7e9, 900.0)


def test_hostile_names_are_counted_not_kept_and_build_nothing(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    clock = _Clock()
    fleet, made, _ = _fleet(tmp_path, {"max_rigs": 3}, clock)
    hostile = ["a\x00b", "a\nERROR forged line", "..", "x" * 60_000, "\u00e9t\u00e9", "-x"]
    with caplog.at_level(logging.INFO, logger="tdmon.daemon.fleet"):
        fleet.process_burst([_raw(f"rig/{name}/hookload", GOOD) for name in hostile])
        for i in range(1000):  # 1000 distinct long names: counted, remembered nowhere
            fleet.process_burst([_raw(f"rig/{'n' * 100}{i}/hookload", GOOD)])
    assert made == ["rig/L"]
    assert sum(fleet.refusals.values()) == len(hostile) + 1000
    assert fleet.refused == set() and list(fleet.rigs) == ["rig/L"]
    assert fleet.unrouted == len(hostile) + 1000
    # remembered routes hold no long topic
    assert max(len(topic) for topic in fleet._routes) <= 256
    # one log line for all of it (a minute has not passed), escaped, short
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "\n" not in lines[0] and len(lines[0]) < 300, lines


def test_a_rig_needs_a_valid_first_sample(tmp_path: Path) -> None:
    clock = _Clock()
    fleet, made, _ = _fleet(tmp_path, {}, clock)
    fleet.process_burst([_raw("rig/B/weather", GOOD), _raw("rig/B/hookload", b"not json"),
                         _raw("rig/B/hookload", b'{"t": "x", "value": 1}')])
    assert made == ["rig/L"] and fleet.refusals == {
        "first message not a sample on a channel topic": 3}
    fleet.process_burst([_raw("rig/B/hookload", GOOD), _raw("rig/B/weather", b"junk")])
    assert made == ["rig/L", "rig/B"]
    # once the rig exists, the rest of its input is its own (the decoder rejects it there)
    assert len(fleet.rigs["rig/B"].pipeline.messages) == 2  # type: ignore[attr-defined]


def test_name_pattern_narrows_the_rule(tmp_path: Path) -> None:
    fleet, made, _ = _fleet(tmp_path, {"name_pattern": "F[0-9]+"}, _Clock())
    fleet.process_burst([_raw("rig/F12/hookload", GOOD), _raw("rig/X1/hookload", GOOD)])
    assert made == ["rig/L", "rig/F12"]
    assert fleet.refusals == {"name not matching [fleet] name_pattern": 1}


def test_silent_rigs_are_retired_and_free_their_slot(tmp_path: Path) -> None:
    clock = _Clock()
    fleet, made, closed = _fleet(tmp_path, {"max_rigs": 3, "idle_rig_timeout": "10 min"},
                                 clock)
    fleet.process_burst([_raw("rig/A/hookload", GOOD), _raw("rig/B/hookload", GOOD),
                         _raw("rig/C/hookload", GOOD)])
    assert sorted(fleet.rigs) == ["rig/A", "rig/B", "rig/L"]  # rig/L listed: 3 slots used
    assert fleet.refusals == {"[fleet] max_rigs = 3 reached": 1}
    clock.now += 300.0
    fleet.process_burst([_raw("rig/A/hookload", GOOD)])
    clock.now += 301.0  # B silent for 601 s, A for 301 s, L listed (never retired)
    fleet.tick()
    assert sorted(fleet.rigs) == ["rig/A", "rig/L"] and fleet.retired == 1
    assert len(closed) == 1  # B's own sinks closed; its pipeline flushed
    fleet.flush()  # B's counters stay in the fleet's totals
    # routed: A twice, B once (retired); unrouted: C while the slots were full
    assert fleet.stats.messages_in == 3 + fleet.unrouted and fleet.unrouted == 1
    fleet._closed = False
    fleet.process_burst([_raw("rig/C/hookload", GOOD)])
    assert sorted(fleet.rigs) == ["rig/A", "rig/C", "rig/L"]
    assert made == ["rig/L", "rig/A", "rig/B", "rig/C"]


@pytest.mark.parametrize(("fleet", "key"), [
    ({"name_pattern": "F[0-9"}, "fleet.name_pattern"),
    ({"idle_rig_timeout": "0 s"}, "fleet.idle_rig_timeout"),
    ({"idle_rig_timeout": 600}, "fleet.idle_rig_timeout"),
])
def test_fleet_limits_mistakes_name_their_key(tmp_path: Path, fleet: dict[str, Any],
                                              key: str) -> None:
    with pytest.raises(ConfigError) as caught:
        _config({"sources": {"zenoh": {}}, "fleet": fleet}, tmp_path)
    assert caught.value.key == key


# --- the fuzz: the real fleet daemon over Zenoh and MQTT -------------------------------------

HOSTILE_NAMES = ["a\x00b", "a\nb", "..", ".", "a.b/..", "x" * 5000, "\u00e9t\u00e9",
                 "\u202e", "-", "tdmonx\r"]
names = st.one_of(st.sampled_from(HOSTILE_NAMES), st.sampled_from(["A", "B", "C", "D"]),
                  st.text(min_size=1, max_size=12),
                  st.text(alphabet="x.\n\x00/", min_size=1, max_size=3000))
channels = st.sampled_from(["hookload", "torque", "bit_depth", "weather", "hookload/x"])
payloads = st.one_of(
    st.builds(lambda v: payload(time.time(), v), st.floats(0, 3000)),
    st.binary(max_size=64),
    st.builds(lambda n: b'{"t": 1.7e9, "value": 1, "pad": "' + b"x" * n + b'"}',
              st.integers(0, 20_000)),
    st.sampled_from([b"", b"{}", b"null", b'{"t": NaN, "value": 1}', b"\x00" * 10]),
)


class FleetHarness:
    """The fleet daemon on its own loop in a thread, and what it did."""

    def __init__(self, config: DaemonConfig) -> None:
        self.config = config
        self.ready = threading.Event()
        self.fleet: FleetPipeline | None = None
        self.failure: BaseException | None = None
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # reported by the test
            self.failure = exc

    async def _serve(self) -> None:
        self._stop = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        async with build_fleet(self.config, backoff=FAST_BACKOFF) as built:
            assert isinstance(built.pipeline, FleetPipeline)
            self.fleet = built.pipeline
            task = asyncio.create_task(built.daemon.run(self._stop))
            while not built.daemon.connections or not all(
                    s == "connected" for s in built.daemon.connections.values()):
                await asyncio.sleep(0.02)
            self.ready.set()
            await task

    def handled(self) -> int:
        """Input messages the daemon has taken: routed to a rig, or counted as unrouted."""
        fleet = self.fleet
        assert fleet is not None
        rigs = fleet.rigs.copy()
        return fleet.unrouted + sum(rig.pipeline.stats.messages_in for rig in rigs.values())

    def wait_handled(self, before: int, timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while self.handled() <= before:
            assert self.failure is None and self.thread.is_alive(), self.failure
            assert time.monotonic() < deadline, "the message never reached the daemon"
            time.sleep(0.002)

    def stop(self) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self.thread.join(60)


@contextmanager
def running_fleet(config: DaemonConfig) -> Iterator[FleetHarness]:
    harness = FleetHarness(config)
    harness.thread.start()
    try:
        assert harness.ready.wait(60) or harness.failure is not None, "fleet did not start"
        assert harness.failure is None, harness.failure
        yield harness
    finally:
        harness.stop()
    assert not harness.thread.is_alive() and harness.failure is None, harness.failure


def _fuzz_config(tmp_path: Path, sources: dict[str, Any]) -> DaemonConfig:
    return _config({"sources": sources, "rigs": [{"prefix": "rig/L"}],
                    "fleet": {"max_rigs": 4},
                    "recorder": {"enabled": True, "process": "inline",
                                 "output": str(tmp_path / "rec"), "flush_interval": "0.2 s"}},
                   tmp_path)


def _check_after_fuzz(harness: FleetHarness, tmp_path: Path, send: Callable[[str, bytes], None],
                      caplog: pytest.LogCaptureFixture) -> None:
    fleet = harness.fleet
    assert fleet is not None
    # the daemon still works: a sample on the listed rig is processed
    stats = fleet.rigs["rig/L"].pipeline.stats
    before = stats.samples_in
    send("rig/L/hookload", payload(time.time(), 777.0))
    deadline = time.monotonic() + 10
    while stats.samples_in == before:
        assert time.monotonic() < deadline and harness.failure is None, harness.failure
        time.sleep(0.01)
    for name in HOSTILE_NAMES:
        assert f"rig/{name}" not in fleet.rigs
    assert all(name_refusal(prefix[4:], SAFE) is None for prefix in fleet.rigs)
    assert len(fleet.rigs) <= 4 and sum(fleet.refusals.values()) > 0
    folders = [p.name for p in (tmp_path / "rec").iterdir()]
    assert "rig_L" in folders
    assert all(f.startswith("rig_") and SAFE.fullmatch(f[4:]) for f in folders), folders
    for record in caplog.records:
        text = record.getMessage()
        assert "\n" not in text and "\x00" not in text and len(text) < 1000, text[:200]


SETTINGS = settings(max_examples=120, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


def test_fuzz_fleet_over_zenoh(tmp_path: Path, free_tcp_port: Callable[[], int],
                               caplog: pytest.LogCaptureFixture) -> None:
    rig_port, daemon_port = free_tcp_port(), free_tcp_port()
    config = _fuzz_config(tmp_path, {"zenoh": {"listen": [f"tcp/127.0.0.1:{daemon_port}"],
                                               "connect": [f"tcp/127.0.0.1:{rig_port}"]}})
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{rig_port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(conf)
    block = zenoh.CongestionControl.BLOCK

    def send(topic: str, data: bytes) -> None:
        session.put(topic, data, congestion_control=block)

    caplog.set_level(logging.INFO)
    try:
        with running_fleet(config) as harness:
            probe = session.declare_publisher("rig/L/hookload")
            deadline = time.monotonic() + 60
            while not probe.matching_status.matching:
                assert time.monotonic() < deadline, "the subscription never reached the rig"
                time.sleep(0.02)
            probe.undeclare()
            sent = {"n": 0}

            @SETTINGS
            @given(name=names, channel=channels, data=payloads)
            def fuzz(name: str, channel: str, data: bytes) -> None:
                if any(chunk.startswith("@") for chunk in name.split("/")):
                    # a verbatim chunk: zenoh takes the key but `rig/**` does not match it,
                    # so it never reaches the daemon
                    return
                before = harness.handled()
                try:
                    send(f"rig/{name}/{channel}", data)
                except zenoh.ZError:
                    return  # not a key zenoh accepts: never reaches the daemon
                sent["n"] += 1
                harness.wait_handled(before)

            for name in HOSTILE_NAMES:  # every one at least once, whatever hypothesis draws
                before = harness.handled()
                with_key = f"rig/{name}/hookload"
                try:
                    send(with_key, payload(time.time(), 1.0))
                except zenoh.ZError:
                    continue
                harness.wait_handled(before)
            fuzz()
            assert sent["n"] > 50
            _check_after_fuzz(harness, tmp_path, send, caplog)
            # the issue's own keys were accepted by zenoh and refused by the daemon
            assert harness.fleet is not None
            assert harness.fleet.refusals.get(
                "name outside [A-Za-z0-9_.-] or not starting with a letter or digit", 0) >= 3
    finally:
        session.close()


def _mqtt_topic(topic: str) -> bool:
    """Whether mosquitto takes ``topic`` from a publisher: no wildcard, at most 65 535 bytes,
    and no control character (MQTT 3.1.1, 1.5.3: U+0000 must not appear, U+0001-U+001F and
    U+007F-U+009F should not; mosquitto disconnects a client that sends them)."""
    return (not any(c in "+#" or ord(c) < 0x20 or 0x7F <= ord(c) <= 0x9F for c in topic)
            and len(topic.encode()) <= 65_535)


def test_fuzz_fleet_over_mqtt(tmp_path: Path, mosquitto: Any,
                              caplog: pytest.LogCaptureFixture) -> None:
    config = _fuzz_config(tmp_path, {"mqtt": {"port": mosquitto.port, "client_id": "fleet"}})
    client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="hostile-rigs")
    client.connect("127.0.0.1", mosquitto.port)
    client.loop_start()

    def send(topic: str, data: bytes) -> None:
        client.publish(topic, data, qos=1).wait_for_publish(10)

    caplog.set_level(logging.INFO)
    try:
        with running_fleet(config) as harness:
            sent = {"n": 0}

            @SETTINGS
            @given(name=names, channel=channels, data=payloads)
            def fuzz(name: str, channel: str, data: bytes) -> None:
                topic = f"rig/{name}/{channel}"
                if not _mqtt_topic(topic):
                    return  # not an MQTT topic name: paho or the broker refuse it
                before = harness.handled()
                send(topic, data)
                sent["n"] += 1
                harness.wait_handled(before)

            for name in HOSTILE_NAMES:
                if _mqtt_topic(f"rig/{name}/hookload"):
                    before = harness.handled()
                    send(f"rig/{name}/hookload", payload(time.time(), 1.0))
                    harness.wait_handled(before)
            fuzz()
            assert sent["n"] > 50
            _check_after_fuzz(harness, tmp_path, send, caplog)
    finally:
        client.loop_stop()
        client.disconnect()


def test_a_silent_found_rig_is_retired_with_its_recording_finished(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    from tdmon.record.reader import read_messages

    rig_port, daemon_port = free_tcp_port(), free_tcp_port()
    config = _config({"sources": {"zenoh": {"listen": [f"tcp/127.0.0.1:{daemon_port}"],
                                            "connect": [f"tcp/127.0.0.1:{rig_port}"]}},
                      "fleet": {"idle_rig_timeout": "1.5 s", "max_rigs": 1},
                      "recorder": {"enabled": True, "output": str(tmp_path / "rec"),
                                   "flush_interval": "0.2 s"}}, tmp_path)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{rig_port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    session = zenoh.open(conf)

    def send(topic: str, value: float) -> None:
        session.put(topic, payload(time.time(), value),
                    congestion_control=zenoh.CongestionControl.BLOCK)

    def wait(what: str, done: Callable[[], bool]) -> None:
        deadline = time.monotonic() + 30
        while not done():
            assert time.monotonic() < deadline, what
            time.sleep(0.02)

    try:
        with running_fleet(config) as harness:
            fleet = harness.fleet
            assert fleet is not None
            probe = session.declare_publisher("rig/D/hookload")
            wait("the subscription", lambda: probe.matching_status.matching)
            probe.undeclare()
            send("rig/D/hookload", 500.0)
            wait("rig/D built", lambda: "rig/D" in fleet.rigs.copy())
            send("rig/E/hookload", 600.0)  # max_rigs = 1: refused while D holds the slot
            wait("rig/E refused", lambda: sum(fleet.refusals.values()) == 1)
            wait("rig/D retired", lambda: fleet.retired == 1)
            assert "rig/D" not in fleet.rigs.copy()
            # D's recording was closed with its sample in it
            files = sorted((tmp_path / "rec" / "rig_D").glob("*.mcap"))
            assert len(files) == 1
            samples = [m.message for m in read_messages(files[0], "/tdmon/sample")]
            assert [s["value"] for s in samples] == [500e3]
            send("rig/E/hookload", 700.0)  # the freed slot
            wait("rig/E built", lambda: "rig/E" in fleet.rigs.copy())
    finally:
        session.close()
