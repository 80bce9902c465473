"""The flight recorder failing: at start ``tdmon run`` says so in one line and exits 2; while
running, the daemon raises a ``recorder_failed`` alarm and keeps processing and publishing.

We run as root, so chmod does not stop writes: an unwritable folder is a path under a regular
file, and a full disk is ``RLIMIT_FSIZE`` in the daemon's process (with SIGXFSZ ignored, a write
past the limit fails with EFBIG, "File too large", as on a full file system).
"""

from __future__ import annotations

import json
import resource
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import zenoh

from tdmon.cli import main
from tdmon.record.schemas import TOPIC_SCHEMAS

ROOT = Path(__file__).resolve().parents[2]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
TDMON = [sys.executable, "-m", "tdmon"]


def _config(folder: Path, port: int, output: Path) -> Path:
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "rig/K1"
well = "{WELL}"
[sources.zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[publish]
zenoh = true
names = ["model", "alarm", "status"]
status_interval = "0.5 s"
[recorder]
enabled = true
output = "{output}"
flush_interval = "0.2 s"
[monitor]
grid_step = "50 m"
""")
    return path


def test_unwritable_output_folder_is_one_line_exit_2(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        free_tcp_port: Callable[[], int]) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    config = _config(tmp_path, free_tcp_port(), blocker / "recordings")
    assert main(["run", "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("tdmon: error: ") and "recordings" in err and "Not a directory" in err


def _limit_file_size(limit: int) -> Callable[[], None]:
    def apply() -> None:  # in the child, before exec
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of being killed
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


class _Stderr:
    """Drains a child's stderr (a pipe: a log file would count against RLIMIT_FSIZE)."""

    def __init__(self, process: subprocess.Popen[str]) -> None:
        self.lines: list[str] = []
        assert process.stderr is not None
        self._stream = process.stderr
        self._thread = threading.Thread(target=self._drain, daemon=True)
        self._thread.start()

    def _drain(self) -> None:
        for line in self._stream:
            self.lines.append(line)

    def text(self) -> str:
        return "".join(self.lines)

    def wait_for(self, text: str, timeout: float = 30) -> None:
        deadline = time.monotonic() + timeout
        while text not in self.text():
            assert time.monotonic() < deadline, f"'{text}' never appeared: {self.text()}"
            time.sleep(0.05)


def test_full_disk_at_start_is_one_line_exit_2(tmp_path: Path,
                                               free_tcp_port: Callable[[], int]) -> None:
    config = _config(tmp_path, free_tcp_port(), tmp_path / "rec")
    # nothing fits: the first write fails (with a few bytes left, a short write would only
    # show at the next flush, i.e. as a failure while running, tested below)
    done = subprocess.run([*TDMON, "run", "--config", str(config)], capture_output=True,
                          text=True, timeout=60, preexec_fn=_limit_file_size(0),
                          restore_signals=False)
    assert done.returncode == 2, done.stderr
    err = done.stderr.strip().splitlines()
    assert err[-1].startswith("tdmon: error: ") and "File too large" in err[-1], done.stderr
    assert "Traceback" not in done.stderr


def test_recorder_failing_while_running_alarms_and_results_keep_coming(  # noqa: C901  (complex today; simplify when next touched)
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    port = free_tcp_port()
    config = _config(tmp_path, port, tmp_path / "rec")
    daemon = subprocess.Popen([*TDMON, "run", "--config", str(config)], stderr=subprocess.PIPE,
                              stdout=subprocess.DEVNULL, text=True,
                              preexec_fn=_limit_file_size(96 * 1024), restore_signals=False)
    stderr = _Stderr(daemon)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    rig = zenoh.open(conf)
    # (arrival order, topic, message) on the publish side, as a dashboard sees it
    received: list[tuple[str, dict[str, Any]]] = []
    lock = threading.Lock()

    def on_result(sample: zenoh.Sample) -> None:
        with lock:
            received.append((str(sample.key_expr), json.loads(sample.payload.to_bytes())))

    subscriber = rig.declare_subscriber("rig/K1/tdmon/**", on_result)
    block = zenoh.CongestionControl.BLOCK
    row = 0

    def publish_rows(n: int) -> None:
        nonlocal row
        for _ in range(n):
            t = 1.7e9 + 0.1 * row
            for channel, value in (("hookload", 900.0 + row % 50), ("torque", 12.0),
                                   ("bit_depth", 2000.0 - 0.05 * row)):
                unit = {"hookload": "kN", "torque": "kN*m", "bit_depth": "m"}[channel]
                body = {"t": t, "value": value, "unit": unit}
                rig.put(f"rig/K1/{channel}", json.dumps(body).encode(), congestion_control=block)
            row += 1
            time.sleep(0.002)

    def alarms() -> list[dict[str, Any]]:
        with lock:
            return [m for topic, m in received if topic == "rig/K1/tdmon/alarm"
                    and m["kind"] == "recorder_failed"]

    try:
        stderr.wait_for("daemon running")
        # the daemon's subscription has reached the rig (was: a 0.5 s pause)
        probe = rig.declare_publisher("rig/K1/hookload")
        deadline = time.monotonic() + 60
        while not probe.matching_status.matching:
            assert time.monotonic() < deadline, "the rig never met the daemon's subscription"
            time.sleep(0.05)
        probe.undeclare()
        deadline = time.monotonic() + 60
        while not alarms():  # until the file reaches the size limit
            assert time.monotonic() < deadline, f"the recorder never failed: {stderr.text()}"
            publish_rows(100)
        failed_at_row = row
        with lock:
            seen_at_alarm = len(received)
        publish_rows(200)  # after the failure: these must still come back as results
        last_t = 1.7e9 + 0.1 * (row - 1)
        deadline = time.monotonic() + 20
        while True:
            with lock:
                models = [m for topic, m in received[seen_at_alarm:]
                          if topic == "rig/K1/tdmon/model"]
            if models and max(m["t"] for m in models) >= last_t - 0.15:
                break
            assert time.monotonic() < deadline, "results stopped after the recorder failed"
            time.sleep(0.05)
        # the last row's other channels may still be on their way (the model above may be the
        # row before's): stopped now, the daemon could not count what never reached it
        while True:
            with lock:
                counted = [m["samples_in"] for topic, m in received
                           if topic == "rig/K1/tdmon/status"]
            if counted and counted[-1] == 3 * row:
                break
            assert time.monotonic() < deadline, f"statuses counted {counted[-3:]} of {3 * row}"
            time.sleep(0.05)
        daemon.send_signal(signal.SIGTERM)
        assert daemon.wait(30) == 0, stderr.text()
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait(10)
        subscriber.undeclare()
        rig.close()

    [alarm] = alarms()[:1]
    jsonschema.validate(alarm, TOPIC_SCHEMAS["/tdmon/alarm"])
    assert alarm["severity"] == "critical" and "File too large" in alarm["message"]
    after = [m for topic, m in received[seen_at_alarm:] if topic == "rig/K1/tdmon/model"]
    # every row published after the failure was processed into a model result
    assert {round(m["t"], 3) for m in after} >= {
        round(1.7e9 + 0.1 * r, 3) for r in range(failed_at_row + 1, row - 1)}
    text = stderr.text()
    assert "Traceback" not in text
    assert "File too large" in text
    # the daemon's last status counted everything it was sent
    statuses = [m for topic, m in received if topic == "rig/K1/tdmon/status"]
    assert statuses[-1]["samples_in"] == 3 * row
