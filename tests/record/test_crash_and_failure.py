"""Crash safety (SIGKILL mid-stream), recovery, and an output folder that cannot be written."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from tdmon.cli import main
from tdmon.errors import RecordError
from tdmon.record import schemas
from tdmon.record.mcap_recorder import FILE_PATTERN, McapRecorder
from tdmon.record.reader import is_finished, read_messages
from tdmon.record.recover import recover_file, recover_folder

ChildRunner = Callable[..., dict[str, Any]]

RATE_HZ = 200
FLUSH_S = 1.0

# Writes sequence numbers at RATE_HZ; after each write() returns, appends the number to a side
# file, so the parent knows what the recorder accepted before the kill.
WRITER = """
import sys, time
from collections.abc import Callable
from pathlib import Path
from typing import Any
from tdmon.record.mcap_recorder import McapRecorder

folder, side = Path(sys.argv[1]), open(sys.argv[2], "w", buffering=1)
recorder = McapRecorder(folder, flush_interval_s=float(sys.argv[3]))
print(recorder.path, flush=True)
seq = 0
while True:
    t = time.time()
    recorder.write("/tdmon/sample", time.time_ns(), {"channel": "hookload", "t": t,
                   "value": float(seq), "unit": "N", "source": "mqtt", "topic": "rig/hl"})
    side.write(f"{seq}\\n")
    seq += 1
    time.sleep(1.0 / float(sys.argv[4]))
"""


def _side_count(side: Path) -> int:
    lines = side.read_text().splitlines()
    # The last line may be cut by the kill; only whole numbers count as reported.
    return sum(1 for line in lines if line.strip().isdigit())


def test_sigkilled_writer_loses_at_most_one_flush_interval(
    tmp_path: Path, repo: Path
) -> None:
    folder, side = tmp_path / "rec", tmp_path / "written.txt"
    child = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(folder), str(side), str(FLUSH_S), str(RATE_HZ)],
        cwd=repo, stdout=subprocess.PIPE, text=True,
    )
    try:
        assert child.stdout is not None
        path = Path(child.stdout.readline().strip())
        # Wait for a few flush intervals' worth of messages, then kill without warning.
        deadline = time.monotonic() + 60
        while (not side.exists() or _side_count(side) < 3 * RATE_HZ) and (
            time.monotonic() < deadline
        ):
            time.sleep(0.05)
        os.kill(child.pid, signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    reported = _side_count(side)
    assert reported >= 3 * RATE_HZ
    assert not is_finished(path)
    with pytest.raises(RecordError):
        list(read_messages(path))

    # A restarted recorder recovers the file and starts the next one.
    with McapRecorder(folder) as restarted:
        assert [r.path for r in restarted.recovered] == [path]
        new_path = restarted.path
    assert new_path is not None and new_path != path
    assert FILE_PATTERN.match(new_path.name)["seq"] == "00001"  # type: ignore[index]
    result = restarted.recovered[0]
    assert is_finished(path)
    values = [int(m.message["value"]) for m in read_messages(path)]
    assert result.messages == len(values) == result.per_topic["/tdmon/sample"]
    # Nothing out of order, no gaps: the recovered messages are a prefix of what was written.
    assert values == list(range(len(values)))
    lost = reported - len(values)
    # At most one flush interval of data lost: at RATE_HZ (sleep-paced, so never faster) that
    # is RATE_HZ * FLUSH_S messages, plus the one written while the interval elapsed.
    assert 0 <= lost <= RATE_HZ * FLUSH_S + 1, (reported, len(values))
    assert len(values) > 0


def test_recover_is_idempotent_and_cli_reports(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recorder = McapRecorder(tmp_path, background_flush=False)
    for i in range(10):
        recorder.write("/tdmon/alarm", i, {"t": 1.0, "kind": "k", "severity": "info",
                                           "message": str(i)})
    recorder.flush()
    recorder.write("/tdmon/alarm", 99, {"t": 1.0, "kind": "k", "severity": "info",
                                        "message": "never flushed"})
    path = recorder.path
    assert path is not None
    # Simulate the kill: copy what reached the disk while the writer still holds its lock.
    copy = tmp_path / "killed.mcap"
    copy.write_bytes(path.read_bytes())
    assert recover_file(path).status == "in_use"
    assert main(["recover", str(copy)]) == 0
    out = capsys.readouterr().out
    assert "recovered 10 messages" in out
    assert [m.log_time_ns for m in read_messages(copy)] == list(range(10))
    assert recover_file(copy).status == "complete"
    recorder.close()
    assert recover_folder(tmp_path) == []


def test_empty_file_left_before_first_flush_is_recovered(tmp_path: Path) -> None:
    empty = tmp_path / "tdmon_00000_20260101T000000Z.mcap"
    empty.write_bytes(b"")
    stale = tmp_path / "tdmon_00000_20260101T000000Z.mcap.recovering"
    stale.write_bytes(b"half a rewrite")
    [result] = recover_folder(tmp_path)
    assert not stale.exists()
    assert result.messages == 0 and is_finished(empty)


def test_unwritable_folder_is_a_clear_error_at_start(tmp_path: Path) -> None:
    # Running as root, permissions do not stop writes: a folder under a regular file does.
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    with pytest.raises(RecordError, match="cannot create output folder") as caught:
        McapRecorder(blocker / "recordings")
    assert isinstance(caught.value.__cause__, OSError)
    with pytest.raises(RecordError, match="free"):
        McapRecorder(tmp_path / "ok", min_free_bytes=1 << 62)


FULL_AT_START = """
import json, resource, signal, sys
from tdmon.errors import RecordError
from tdmon.record.mcap_recorder import McapRecorder
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # get EFBIG instead of being killed
resource.setrlimit(resource.RLIMIT_FSIZE, (0, resource.RLIM_INFINITY))
try:
    McapRecorder(sys.argv[1])
    print(json.dumps({"raised": None}))
except RecordError as exc:
    print(json.dumps({"raised": str(exc), "cause": type(exc.__cause__).__name__}))
"""

FULL_WHILE_RUNNING = """
import json, os, resource, signal, sys, time
from tdmon.record.mcap_recorder import McapRecorder
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
alarms = []
recorder = McapRecorder(sys.argv[1], flush_interval_s=0.01, retry_s=3600,
                        background_flush=False, on_alarm=alarms.append)
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, resource.RLIM_INFINITY))
accepted, raised = 0, None
try:
    for seq in range(5000):
        recorder.write("/tdmon/raw", time.time_ns(), {"source": "mqtt", "topic": "rig/hl",
                       "receive_time": time.time(), "payload": os.urandom(100).hex(),
                       "payload_encoding": "utf-8"})
        accepted += 1
        if seq % 50 == 0:
            time.sleep(0.011)      # let the flush interval elapse now and then
except Exception as exc:
    raised = repr(exc)
failed = recorder.error is not None
error = str(recorder.error)
stats = recorder.stats
# The disk "gets space back" and the operator asks for a retry: a new file is started.
resource.setrlimit(resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
resumed = recorder.retry()
recorder.write("/tdmon/alarm", time.time_ns(), {"t": time.time(), "kind": "k",
               "severity": "info", "message": "after"})
recorder.close()
print(json.dumps({"accepted": accepted, "raised": raised, "failed": failed, "error": error,
                  "written": stats.written, "lost": stats.lost,
                  "files": [str(p) for p in recorder.stats.files],
                  "alarms": alarms, "error_after": str(recorder.error), "resumed": resumed}))
"""


def test_full_disk_at_start_is_a_clear_error(tmp_path: Path, run_child: ChildRunner) -> None:
    result = run_child(FULL_AT_START, str(tmp_path / "rec"))
    assert result["raised"] and "cannot record to" in result["raised"]
    assert "too large" in result["raised"].lower()
    assert result["cause"] == "OSError"


def test_full_disk_while_running_alarms_and_keeps_accepting(
    tmp_path: Path, run_child: ChildRunner
) -> None:
    result = run_child(FULL_WHILE_RUNNING, str(tmp_path / "rec"))
    assert result["raised"] is None
    assert result["accepted"] == 5000
    assert result["failed"] and "File too large" in result["error"]
    assert result["lost"] > 0
    assert result["written"] + result["lost"] == result["accepted"]
    kinds = [alarm["kind"] for alarm in result["alarms"]]
    assert kinds == ["recorder_failed", "recorder_resumed"]
    for alarm in result["alarms"]:
        jsonschema.validate(alarm, schemas.TOPIC_SCHEMAS["/tdmon/alarm"])
    assert result["alarms"][0]["severity"] == "critical"
    assert result["error_after"] == "None" and result["resumed"]
    failed_file, resumed_file = (Path(p) for p in result["files"])
    assert is_finished(resumed_file)
    assert [m.message["message"] for m in read_messages(resumed_file)] == ["after"]
    # What was counted as written is exactly what the failed file recovers to.
    recovered = recover_file(failed_file)
    assert recovered.status == "recovered"
    assert recovered.messages == result["written"]


def test_cli_errors_are_one_line_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("hello")
    cases = [tmp_path / "missing.mcap", not_mcap, tmp_path]
    for target in cases:
        for argv in (["recover", str(target)], ["view", str(target), "--rrd",
                     str(tmp_path / "z.rrd")], ["report", str(target), "--out",
                     str(tmp_path / "report")]):
            assert main(argv) == 2, argv
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and err[0].startswith("tdmon: error: "), err
    assert "not an MCAP file" in _err_of(["recover", str(not_mcap)], capsys)
    assert "no such file" in _err_of(["recover", str(tmp_path / "missing.mcap")], capsys)


def _err_of(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    main(argv)
    return capsys.readouterr().err





AUTOMATIC_RETRY = """
import json, os, resource, signal, sys, time
from tdmon.record.mcap_recorder import McapRecorder
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
alarms = []
recorder = McapRecorder(sys.argv[1], flush_interval_s=0.001, retry_s=0.0,
                        background_flush=False, on_alarm=alarms.append)
resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, resource.RLIM_INFINITY))
for seq in range(3000):
    recorder.write("/tdmon/raw", time.time_ns(), {"source": "mqtt", "topic": "rig/hl",
                   "receive_time": time.time(), "payload": os.urandom(100).hex(),
                   "payload_encoding": "utf-8"})
    if seq % 20 == 0:
        time.sleep(0.002)
stats = recorder.stats
recorder.close()
print(json.dumps({"kinds": [a["kind"] for a in alarms], "files": len(stats.files),
                  "written": stats.written, "lost": stats.lost}))
"""


def test_recorder_retries_by_itself_after_a_failure(
    tmp_path: Path, run_child: ChildRunner
) -> None:
    result = run_child(AUTOMATIC_RETRY, str(tmp_path / "rec"))
    assert result["kinds"][:2] == ["recorder_failed", "recorder_resumed"]
    assert result["files"] >= 2
    assert result["written"] + result["lost"] == 3000


def test_quiet_pipeline_is_flushed_by_the_background_thread(tmp_path: Path) -> None:
    recorder = McapRecorder(tmp_path, flush_interval_s=0.05)
    try:
        for i in range(10):
            recorder.write("/tdmon/alarm", i, {"t": 1.0, "kind": "k", "severity": "info",
                                               "message": str(i)})
        path = recorder.path
        assert path is not None
        # No more writes: only the flusher thread can put the messages on disk.
        deadline = time.monotonic() + 30
        copy = tmp_path / "snapshot.mcap"
        recovered = 0
        while time.monotonic() < deadline:
            copy.write_bytes(path.read_bytes())
            recovered = recover_file(copy).messages
            if recovered == 10:
                break
            time.sleep(0.05)
        assert recovered == 10
    finally:
        recorder.close()


def test_alarm_hook_runs_on_the_writing_thread(tmp_path: Path) -> None:
    import threading

    seen: list[tuple[str, str]] = []
    recorder = McapRecorder(
        tmp_path, flush_interval_s=3600.0, background_flush=False,
        on_alarm=lambda alarm: seen.append((alarm["kind"], threading.current_thread().name)),
    )
    try:
        recorder.write("/tdmon/alarm", 1, {"t": 1.0, "kind": "k", "severity": "info",
                                           "message": "m"})
        current = recorder._file
        assert current is not None

        def broken_flush() -> None:
            raise OSError(28, "No space left on device")

        current.flush = broken_flush  # type: ignore[method-assign]
        recorder.flush_interval_s = 1e-6
        # The flusher's periodic work, on another thread, meets the failure...
        flusher = threading.Thread(target=recorder._background_tick, name="flusher")
        flusher.start()
        flusher.join()
        assert recorder.error is not None and "No space left" in str(recorder.error)
        # ... but the hook only runs on the next call from the pipeline's thread.
        assert seen == []
        recorder.write("/tdmon/alarm", 3, {"t": 1.0, "kind": "k", "severity": "info",
                                           "message": "m"})
        assert seen == [("recorder_failed", threading.current_thread().name)]
        assert recorder.stats.lost == 2
    finally:
        recorder.close()
