"""A daemon SIGKILLed on a Zenoh feed and restarted (issue 32, fault 5): Zenoh keeps nothing for
a subscriber that is gone, so what the rig sent meanwhile is in no recording. Before, the
restarted run started its ``seq`` and sampling history afresh and said nothing (8 636 of 27 001
samples lost, ``seq_lost`` 0, no alarm). Now it goes on from the loss state kept beside the
recordings: the gap across its absence is counted and alarmed.

A real ``tdmon run`` (Zenoh source, MCAP recorder) connects to the test's Zenoh peer, which
plays the rig; the recordings are read back.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from tdmon.config.daemon import ZenohConfig
from tdmon.ingest.zenoh_io import zenoh_config
from tdmon.record.reader import read_messages
from tests.conftest import free_port

RATE = 60.0  # samples/s, the three channels together
CHANNELS = (("hookload", "kN"), ("torque", "kN*m"), ("bit_depth", "m"))
TO_SI = {"hookload": 1e3, "torque": 1e3, "bit_depth": 1.0}
#: [s] the status interval and the recorder's flush: how far apart the saved loss state and
#: the recording can be when the daemon is killed
SAVE_S = 0.2


def _config(folder: Path, endpoint: str) -> Path:
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "rig/Z1"
[sources.zenoh]
connect = ["{endpoint}"]
[publish]
status_interval = "{SAVE_S} s"
[recorder]
enabled = true
output = "{folder / 'rec'}"
flush_interval = "{SAVE_S} s"
[channels]
hookload = {{unit = "kN"}}
torque = {{unit = "kN*m"}}
bit_depth = {{unit = "m"}}
""")
    return path


def _start(config: Path, log: Path) -> subprocess.Popen[bytes]:
    with log.open("w") as err:
        process = subprocess.Popen([sys.executable, "-m", "tdmon", "run", "--config",
                                    str(config)], stderr=err, stdout=subprocess.DEVNULL,
                                   env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    _wait_for(lambda: "daemon running" in log.read_text(), 60, "the daemon to start")
    return process


def _wait_for(predicate: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


class Rig(threading.Thread):
    """A Zenoh peer listening on ``endpoint`` and publishing the three channels with their
    ``seq``, paced on the wall clock."""

    def __init__(self, endpoint: str) -> None:
        super().__init__(daemon=True)
        self.session = zenoh.open(zenoh_config(ZenohConfig(mode="peer", listen=[endpoint])))
        self.sent = 0
        self.stopping = threading.Event()

    def run(self) -> None:
        start, t0 = time.monotonic(), time.time()
        i = 0
        while not self.stopping.is_set():
            channel, unit = CHANNELS[i % 3]
            body = {"t": t0 + i / RATE, "value": float(i), "unit": unit, "seq": i // 3 + 1}
            self.session.put(f"rig/Z1/{channel}", json.dumps(body).encode())
            i += 1
            self.sent = i
            time.sleep(max(0.0, start + i / RATE - time.monotonic()))

    def stop(self) -> None:
        self.stopping.set()
        self.join(5)
        self.session.close()


def _published_numbers(path: Path) -> set[int]:
    """The rig's message numbers (its ``i``) of the samples recorded in ``path``."""
    return {round(m.message["value"] / TO_SI[m.message["channel"]])
            for m in read_messages(path, "/tdmon/sample")}


def test_sigkill_on_zenoh_counts_the_gap_across_the_restart(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    rig = Rig(endpoint)
    rig.start()
    config = _config(tmp_path, endpoint)
    try:
        first = _start(config, tmp_path / "first.log")
        time.sleep(3.0)
        os.kill(first.pid, signal.SIGKILL)
        first.wait(10)
        sent_at_kill = rig.sent
        time.sleep(3.0)  # away: Zenoh keeps nothing for it
        second = _start(config, tmp_path / "second.log")
        time.sleep(3.0)
        second.send_signal(signal.SIGTERM)
        assert second.wait(30) == 0, (tmp_path / "second.log").read_text()
    finally:
        rig.stop()

    files = sorted((tmp_path / "rec").glob("*.mcap"))
    assert len(files) == 2
    first_file, second_file = files
    first_run, second_run = _published_numbers(first_file), _published_numbers(second_file)
    recorded = first_run | second_run
    # the absence: from the killed run's last recorded sample to the restarted run's first
    absent = set(range(max(first_run) + 1, min(second_run))) - recorded
    assert len(absent) > 2 * RATE  # seconds of samples in no recording
    alarms = [m.message for m in read_messages(second_file, "/tdmon/alarm")
              if m.message["kind"] == "data_loss" and "never arrived" in m.message["message"]]
    status = [m.message for m in read_messages(second_file, "/tdmon/status")][-1]
    counted = status["seq_lost"]
    print(f"sent {rig.sent} ({sent_at_kill} when killed); {len(absent)} in no recording; "
          f"counted {counted} in {len(alarms)} alarms")
    # one alarm per topic, all of it counted: the numbers after the last saved state, which
    # is at most a status interval (and a flush) away from the end of the killed recording
    assert len(alarms) == 3
    assert sum(a["value"] for a in alarms) == counted
    assert abs(counted - len(absent)) <= 2 * SAVE_S * RATE, (counted, len(absent))
    # the first run left no false alarm behind
    assert not [m for m in read_messages(first_file, "/tdmon/alarm")
                if m.message["kind"] == "data_loss"]
