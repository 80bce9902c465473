"""A recorder SIGKILLed mid-write, then a real ``tdmon run`` started on the same folder: the
daemon recovers the file, says so in its log and records (and would publish) one
``recording_recovered`` alarm whose value, the seconds lost, bounds what the kill really lost.

The killed writer is a child process writing ``/tdmon/sample`` at RATE_HZ with wall-clock log
times and the daemon's flush interval; the test notes the wall time of the kill, so the real
loss is the time from the last message the recovered file holds to the kill.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import jsonschema

from tdmon.record.reader import is_finished, read_messages, schemas_of

ROOT = Path(__file__).resolve().parents[2]
RATE_HZ = 100
FLUSH_S = 1.0

WRITER = """
import sys, time
from pathlib import Path
from tdmon.record.mcap_recorder import McapRecorder

recorder = McapRecorder(Path(sys.argv[1]), flush_interval_s=float(sys.argv[2]))
print(recorder.path, flush=True)
seq = 0
while True:
    recorder.write("/tdmon/sample", time.time_ns(), {"channel": "hookload", "t": time.time(),
                   "value": float(seq), "unit": "N", "source": "mqtt", "topic": "rig/hl"})
    seq += 1
    if seq == 3 * int(sys.argv[3]):
        print("written", flush=True)
    time.sleep(1.0 / float(sys.argv[3]))
"""


def _config(folder: Path, port: int) -> Path:
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "rig/K1"
[sources.zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[recorder]
enabled = true
output = "{folder / 'rec'}"
flush_interval = "{FLUSH_S} s"
""")
    return path


def test_restart_after_a_killed_recorder_logs_and_alarms_the_seconds_lost(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    folder = tmp_path / "rec"
    writer = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(folder), str(FLUSH_S), str(RATE_HZ)],
        cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout is not None
        killed_file = Path(writer.stdout.readline().strip())
        assert writer.stdout.readline().strip() == "written"  # 3 s of messages
        time.sleep(0.37)  # somewhere inside a flush interval
        os.kill(writer.pid, signal.SIGKILL)
        killed_at = time.time()
        writer.wait(30)
    finally:
        if writer.poll() is None:
            writer.kill()
            writer.wait(30)
    assert not is_finished(killed_file)

    log = tmp_path / "daemon.log"
    with log.open("w") as err:
        daemon = subprocess.Popen(
            [sys.executable, "-m", "tdmon", "run", "--config",
             str(_config(tmp_path, free_tcp_port()))],
            cwd=ROOT, stderr=err, stdout=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while "daemon running" not in log.read_text():
            assert daemon.poll() is None, log.read_text()
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        daemon.send_signal(signal.SIGTERM)
        assert daemon.wait(60) == 0, log.read_text()
    finally:
        if daemon.poll() is None:
            daemon.kill()
            daemon.wait(30)
    text = log.read_text()
    assert "Traceback" not in text

    # the log names the file it recovered
    [line] = [x for x in text.splitlines() if "recovered the unfinished recording" in x]
    assert str(killed_file) in line and "WARNING" in line.upper()

    # the killed file is whole again, the new file holds exactly one recovery alarm
    assert is_finished(killed_file)
    last_intact = max(m.log_time_ns for m in read_messages(killed_file)) / 1e9
    [new_file] = [p for p in folder.glob("*.mcap") if p != killed_file]
    alarms = [m.message for m in read_messages(new_file, "/tdmon/alarm")]
    [alarm] = [a for a in alarms if a["kind"] == "recording_recovered"]
    jsonschema.validate(alarm, schemas_of(new_file)["/tdmon/alarm"])
    assert alarm["severity"] == "warning"
    assert str(killed_file) in alarm["message"]
    lost_s = alarm["value"]
    really_lost = killed_at - last_intact
    print(f"killed {really_lost:.2f} s after the last intact message; alarm says up to "
          f"{lost_s} s")
    # an upper bound of the real loss (a writer paced by sleep can overrun the interval by a
    # message or two), and never more than the one flush interval the writer could hold
    assert 0 < lost_s <= FLUSH_S
    assert really_lost <= lost_s + 0.2
