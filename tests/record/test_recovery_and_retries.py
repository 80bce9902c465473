"""Recovery at start-up is reported (log line, ``recording_recovered`` alarm with the seconds
lost), and a recorder retrying on a full disk leaves no empty files behind."""

from __future__ import annotations

import json
import logging
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from tdmon.record import schemas
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import is_finished, read_messages
from tdmon.record.recover import RecoveryResult, recovery_alarm, seconds_lost

ChildRunner = Callable[..., dict[str, Any]]


def _killed_recording(folder: Path, flush_s: float, n: int) -> tuple[Path, int]:
    """A recorder in a child process writes ``n`` messages (log times 1 ms apart from 10 s ago),
    flushes, writes one more and is SIGKILLed: a footer-less file with ``n`` intact messages."""
    script = f"""
import os, signal, sys, time
from tdmon.record.mcap_recorder import McapRecorder
recorder = McapRecorder(sys.argv[1], flush_interval_s={flush_s}, background_flush=False)
t0 = time.time_ns() - 10_000_000_000
for i in range({n} + 1):
    if i == {n}:
        recorder.flush()
    recorder.write("/tdmon/alarm", t0 + i * 1_000_000, {{"t": t0 / 1e9, "kind": "band",
                   "severity": "info", "message": str(i)}})
print(recorder.path, t0 + ({n} - 1) * 1_000_000, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""
    done = subprocess.run([sys.executable, "-c", script, str(folder)], capture_output=True,
                          text=True, timeout=120, check=False)
    assert done.returncode == -signal.SIGKILL, done.stderr
    path, last_ns = done.stdout.split()
    return Path(path), int(last_ns)


def test_recorder_start_logs_and_alarms_each_recovered_file(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    killed, last_ns = _killed_recording(tmp_path, 2.5, 30)
    assert not is_finished(killed)
    alarms: list[dict[str, Any]] = []
    with caplog.at_level(logging.WARNING, logger="tdmon.record.mcap_recorder"):
        recorder = McapRecorder(tmp_path, flush_interval_s=0.5, on_alarm=alarms.append,
                                background_flush=False)
    try:
        [result] = recorder.recovered
        assert result.messages == 30 and result.last_log_time_ns == last_ns
        # the killed file's own flush interval, from its metadata, not the new recorder's
        assert result.flush_interval_s == 2.5
        [record] = [r for r in caplog.records if "recovered the unfinished" in r.getMessage()]
        assert record.levelno == logging.WARNING and str(killed) in record.getMessage()
        assert alarms == []  # reported on the caller's thread, at the first write
        recorder.write("/tdmon/status", time.time_ns(), {"t": time.time(), "samples_in": 0,
                       "rejected": 0, "dropped": 0, "lag_s": None, "connections": {}})
        [alarm] = alarms
    finally:
        recorder.close()
    jsonschema.validate(alarm, schemas.TOPIC_SCHEMAS["/tdmon/alarm"])
    assert alarm["kind"] == "recording_recovered" and alarm["severity"] == "warning"
    # restarted more than 2.5 s after the last message: the bound is the killed file's interval
    assert alarm["t"] - last_ns / 1e9 > 2.5
    assert alarm["value"] == 2.5
    assert "30 messages kept" in alarm["message"]
    assert is_finished(killed)


def test_seconds_lost_is_the_smaller_of_the_window_and_the_time_since() -> None:
    result = RecoveryResult(path=Path("x.mcap"), status="recovered",
                            last_log_time_ns=1_700_000_000_000_000_000, flush_interval_s=2.0)
    # restarted 10 s later: at most the window the writer could hold
    assert seconds_lost(result, 1.0, now=1_700_000_010.0) == 2.0
    # restarted 0.5 s after the last intact message: the crash cannot be later than that
    assert seconds_lost(result, 1.0, now=1_700_000_000.5) == 0.5
    # log times ahead of the clock (a replayed future stamp) say nothing: the window
    assert seconds_lost(result, 1.0, now=1_600_000_000.0) == 2.0
    # no metadata, no message: the recorder's own interval
    bare = RecoveryResult(path=Path("x.mcap"), status="recovered")
    assert seconds_lost(bare, 1.5, now=1.0) == 1.5
    alarm = recovery_alarm(bare, 1.5, now=1_700_000_000.0)
    assert alarm["value"] == 1.5 and "no message was intact" in alarm["message"]


FULL_DISK_RETRIES = """
import json, resource, signal, sys, time
from pathlib import Path
from tdmon.record.mcap_recorder import McapRecorder
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # get EFBIG instead of being killed
folder = Path(sys.argv[1])
alarms = []
recorder = McapRecorder(folder, flush_interval_s=0.001, retry_s=0.0, background_flush=False,
                        on_alarm=alarms.append)
first = recorder.path
# the disk is full from now on: every retry (retry_s = 0: at every write) opens a new file
resource.setrlimit(resource.RLIMIT_FSIZE, (0, resource.RLIM_INFINITY))
for i in range(300):
    recorder.write("/tdmon/alarm", time.time_ns(), {"t": time.time(), "kind": "band",
                   "severity": "info", "message": "x" * 100})
    time.sleep(0.002)
during = sorted((p.name, p.stat().st_size) for p in folder.iterdir())
stats = recorder.stats
resource.setrlimit(resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
resumed = recorder.retry()
recorder.write("/tdmon/alarm", time.time_ns(), {"t": time.time(), "kind": "band",
               "severity": "info", "message": "after"})
recorder.close()
print(json.dumps({"first": str(first), "during": during, "failures": stats.failures,
                  "lost": stats.lost, "resumed": resumed, "files": [str(p) for p in
                  recorder.stats.files], "kinds": [a["kind"] for a in alarms],
                  "after": sorted((p.name, p.stat().st_size) for p in folder.iterdir())}))
"""


def test_retries_on_a_full_disk_leave_no_empty_files(
        tmp_path: Path, run_child: ChildRunner) -> None:
    folder = tmp_path / "rec"
    result = run_child(FULL_DISK_RETRIES, str(folder))
    assert result["failures"] >= 1 and result["lost"] > 0
    # hundreds of retries, each creating a file it could not write a header to: none is left
    assert [name for name, size in result["during"] if size == 0] == []
    assert [name for name, _ in result["during"]] == [Path(result["first"]).name]
    assert result["resumed"] and result["kinds"] == ["recorder_failed", "recorder_resumed"]
    first, resumed = (Path(p) for p in result["files"])
    assert all(size > 0 for _, size in result["after"])
    assert sorted(name for name, _ in result["after"]) == sorted([first.name, resumed.name])
    assert [m.message["message"] for m in read_messages(resumed)] == ["after"]
    # the failed file (a valid header, no footer) is kept for recovery
    assert not is_finished(first)


def test_a_header_written_file_is_never_removed(tmp_path: Path, run_child: ChildRunner) -> None:
    """Only the recorder's own empty files go: a 0-byte .mcap another run left (killed before
    its first flush) is recovered, not deleted."""
    left = tmp_path / "tdmon_00000_20260101T000000Z.mcap"
    left.write_bytes(b"")
    with McapRecorder(tmp_path, background_flush=False) as recorder:
        assert [r.path for r in recorder.recovered] == [left]
    assert left.exists() and is_finished(left)
    assert json.loads(json.dumps(recovery_alarm(recorder.recovered[0], 1.0)))["value"] == 1.0
