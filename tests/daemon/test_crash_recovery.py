"""A real ``tdmon run`` process, fed over Zenoh, killed with SIGKILL mid-stream. With its
recorder in its own process (``[recorder] process = "inline"``) the file it leaves recovers with
at most one second of data lost, the restarted daemon recovers it by itself and starts a new
file, and every message written validates against its channel's JSON Schema; with the recorder
in a child process (``"child"``) the child finishes the file itself, with no more lost.

Counting: the test is the rig. It publishes hook load, torque and bit depth at 20 rows per
second (60 samples/s) with ``CongestionControl.BLOCK`` and kills the daemon right after a put,
so "published up to the kill" is exact. The daemon flushes every 0.5 s (``flush_interval``);
what it cannot have written is the unflushed tail plus what was still in flight on loopback.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest
import zenoh
from daemon_support import schema_validators

from tdmon.cli import main
from tdmon.record.reader import is_finished, read_messages, schemas_of

ROOT = Path(__file__).resolve().parents[2]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
TDMON = [sys.executable, "-m", "tdmon"]
ROWS_PER_S = 20
CHANNELS = (("hookload", "kN", 1e3), ("torque", "kN*m", 1e3), ("bit_depth", "m", 1.0))
SAMPLES_PER_S = ROWS_PER_S * len(CHANNELS)


def _config(folder: Path, port: int, process: str = "inline") -> Path:
    """The daemon's config; ``process``: where its recorder writes (``inline``: killed with
    the daemon, leaving a cut file; ``child``: in a process of its own)."""
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "rig/K1"
well = "{WELL}"
[sources.zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[recorder]
enabled = true
output = "{folder / 'rec'}"
flush_interval = "0.5 s"
process = "{process}"
[monitor]
grid_step = "50 m"
""")
    return path


def _wait_for(path: Path, text: str, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while text not in path.read_text():
        assert time.monotonic() < deadline, f"'{text}' never appeared: {path.read_text()}"
        time.sleep(0.05)


def _rig(port: int) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(conf)


def _publish(rig: zenoh.Session, row: int, t0: float) -> list[tuple[str, float]]:
    """One row; returns (channel, value in SI) of each sample put, in order."""
    t = t0 + row / ROWS_PER_S
    values = {"hookload": 900.0 + row % 50, "torque": 12.0 + 0.01 * row,
              "bit_depth": 2000.0 - 0.025 * row}
    put = []
    for channel, unit, to_si in CHANNELS:
        body = {"t": t, "value": values[channel], "unit": unit}
        rig.put(f"rig/K1/{channel}", json.dumps(body).encode(),
                congestion_control=zenoh.CongestionControl.BLOCK)
        put.append((channel, values[channel] * to_si))
    return put


def _start(config: Path, log: Path) -> subprocess.Popen[bytes]:
    err = log.open("w")
    try:
        return subprocess.Popen([*TDMON, "run", "--config", str(config)], stderr=err,
                                stdout=subprocess.DEVNULL)
    finally:
        err.close()  # the child has its own descriptor


def _validate_all(path: Path) -> int:
    stored = schema_validators(schemas_of(path))
    n = 0
    for item in read_messages(path):
        stored[item.topic].validate(item.message)
        n += 1
    return n


def _feed_and_kill(config: Path, log: Path, port: int, seconds: int, rows_after: int = 0
                   ) -> list[tuple[str, float]]:
    """Start ``tdmon run``, publish ``seconds`` of rows to it (20 rows/s, paced on the wall
    clock), SIGKILL it right after a put (mid-stream) and publish ``rows_after`` more (the rig
    does not know); returns (channel, value in SI) of every sample published before the
    kill."""
    daemon = _start(config, log)
    rig = _rig(port)
    published: list[tuple[str, float]] = []
    try:
        _wait_for(log, "daemon running")
        # the daemon's subscription has reached the rig (was: a 0.5 s pause)
        probe = rig.declare_publisher("rig/K1/hookload")
        deadline = time.monotonic() + 60
        while not probe.matching_status.matching:
            assert time.monotonic() < deadline, "the rig never met the daemon's subscription"
            time.sleep(0.05)
        probe.undeclare()
        t0 = time.time()
        started = time.monotonic()
        for row in range(seconds * ROWS_PER_S):
            published += _publish(rig, row, t0)
            time.sleep(max(0.0, started + (row + 1) / ROWS_PER_S - time.monotonic()))
        os.kill(daemon.pid, signal.SIGKILL)
        for row in range(seconds * ROWS_PER_S, seconds * ROWS_PER_S + rows_after):
            _publish(rig, row, t0)
        assert daemon.wait(10) == -signal.SIGKILL
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait(10)
        rig.close()
    return published


def _recorded_prefix(path: Path, published: list[tuple[str, float]]
                     ) -> list[tuple[str, float]]:
    """The samples in ``path``: the first of those published, in order, exactly, missing at
    most one second's worth."""
    samples = [(m.message["channel"], m.message["value"])
               for m in read_messages(path, "/tdmon/sample")]
    assert [c for c, _ in samples] == [c for c, _ in published[:len(samples)]]
    for (_, value), (_, sent) in zip(samples, published, strict=False):
        assert value == pytest.approx(sent, rel=1e-12)
    lost = len(published) - len(samples)
    print(f"published {len(published)} samples before SIGKILL, recorded {len(samples)}, "
          f"lost {lost} ({lost / SAMPLES_PER_S:.2f} s)")
    assert 0 <= lost <= SAMPLES_PER_S, f"{lost} samples lost (one second is {SAMPLES_PER_S})"
    return samples


def test_sigkilled_daemon_loses_at_most_one_second(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    config = _config(tmp_path, port)
    published = _feed_and_kill(config, tmp_path / "first.log", port, 5, rows_after=ROWS_PER_S)
    [left] = sorted((tmp_path / "rec").glob("*.mcap"))
    assert not is_finished(left), "SIGKILL leaves no footer"

    # the next start recovers the file by itself and records into a new one
    second_log = tmp_path / "second.log"
    restarted = _start(config, second_log)
    try:
        _wait_for(second_log, "daemon running")
        restarted.send_signal(signal.SIGTERM)
        assert restarted.wait(30) == 0, second_log.read_text()
    finally:
        if restarted.poll() is None:
            restarted.kill()
            restarted.wait(10)
    files = sorted((tmp_path / "rec").glob("*.mcap"))
    assert len(files) == 2 and files[0] == left
    assert "_00000_" in files[0].name and "_00001_" in files[1].name
    assert is_finished(left) and is_finished(files[1])
    assert "Traceback" not in second_log.read_text()

    # exactly what was published, in order, up to the last flush before the kill
    samples = _recorded_prefix(left, published)
    raw = list(read_messages(left, "/tdmon/raw"))
    assert len(samples) <= len(raw) <= len(samples) + 1  # a raw may precede its sample
    # results of the frames that made it are there too
    assert list(read_messages(left, "/tdmon/model"))
    # every message in both files validates against the schema stored in its channel
    assert _validate_all(left) >= len(samples) + len(raw)
    _validate_all(files[1])
    # recovering again is a no-op, and says so
    assert main(["recover", str(left)]) == 0


def test_tdmon_recover_on_a_killed_daemon_file(tmp_path: Path,
                                               free_tcp_port: Callable[[], int]) -> None:
    """The same crash without a restart: ``tdmon recover`` makes the file readable."""
    port = free_tcp_port()
    published = _feed_and_kill(_config(tmp_path, port), tmp_path / "daemon.log", port, 3)
    [left] = sorted((tmp_path / "rec").glob("*.mcap"))
    assert not is_finished(left)
    assert main(["recover", str(left)]) == 0
    assert is_finished(left)
    samples = sum(1 for _ in read_messages(left, "/tdmon/sample"))
    assert 0 <= len(published) - samples <= SAMPLES_PER_S
    _validate_all(left)


def test_sigkilled_daemon_with_its_recorder_in_a_child(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    """With ``process = "child"`` the recorder outlives the killed daemon: it sees the pipe
    close and finishes the file itself (summary and footer) with everything it was sent, so
    nothing needs recovering, and at most the daemon's unsent batch (half a flush interval)
    and what was in flight are missing."""
    port = free_tcp_port()
    published = _feed_and_kill(_config(tmp_path, port, "child"), tmp_path / "daemon.log",
                               port, 3)
    [left] = sorted((tmp_path / "rec").glob("*.mcap"))
    deadline = time.monotonic() + 30
    while not is_finished(left):  # the orphaned recorder finishing the file
        assert time.monotonic() < deadline, "the recorder's process never finished the file"
        time.sleep(0.05)
    samples = _recorded_prefix(left, published)
    assert _validate_all(left) >= 2 * len(samples)
    assert main(["recover", str(left)]) == 0  # nothing to do
