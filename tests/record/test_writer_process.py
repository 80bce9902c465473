"""The recorder in a child process: the same file as in-process, failures reported, no loss
when the parent dies, Ctrl-C does not cut the recording short."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from tdmon.errors import RecordError
from tdmon.ingest.types import RAW_ROW, RawMessage, raw_row_message
from tdmon.record import schemas
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import RecordedMessage, is_finished, read_messages
from tdmon.record.writer_process import RecorderProcess

ChildRunner = Callable[..., dict[str, Any]]


def _raw(i: int) -> dict[str, Any]:
    return {"source": "mqtt", "topic": "rig/hl", "receive_time": 1.7e9 + i,
            "payload": f'{{"t": {1.7e9 + i}, "value": {i}}}', "payload_encoding": "utf-8"}


def _wait_gone(pid: int, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.05)
    raise AssertionError(f"process {pid} still running after {timeout} s")


def test_same_file_as_the_recorder_in_this_process(
    tmp_path: Path, stream: list[RecordedMessage]
) -> None:
    inline, separate = tmp_path / "inline.mcap", tmp_path / "separate.mcap"
    with McapRecorder(path=inline) as recorder:
        for item in stream:
            recorder.write(item.topic, item.log_time_ns, item.message)
    # a small batch: many batches, plus the last partial one at close
    with RecorderProcess(path=separate, batch_size=97) as process:
        for item in stream:
            process.write(item.topic, item.log_time_ns, item.message)
    assert process.stats.written == recorder.stats.written == len(stream)
    assert process.stats.per_topic == recorder.stats.per_topic
    assert process.stats.lost == 0
    assert is_finished(separate)
    got = [(m.topic, m.log_time_ns, m.message) for m in read_messages(separate)]
    want = [(m.topic, m.log_time_ns, m.message) for m in read_messages(inline)]
    assert got == want
    assert process.path is None  # closed


def test_rows_made_into_messages_in_the_child(tmp_path: Path) -> None:
    """``write_rows`` (the pipeline's bursts of raw input and samples): the child makes each
    message of its row; the file is the one ``write_many`` of the made messages gives. A row
    the maker refuses is counted as unencodable and lost, the others are kept; a maker that
    cannot be sent at all loses its rows, counted, and not the rest of the batch."""
    raws = [RawMessage("mqtt", f"rig/K1/{channel}", f'{{"t": {i}, "value": {i}}}'.encode(),
                       1.7e9 + i) for i in range(600) for channel in ("hookload", "torque")]
    times = [int(raw.receive_time * 1e9) for raw in raws]
    make = partial(raw_row_message, max_bytes=64)
    inline, separate = tmp_path / "inline.mcap", tmp_path / "separate.mcap"
    with McapRecorder(path=inline) as recorder:
        recorder.write_many("/tdmon/raw", times, [make(RAW_ROW(raw)) for raw in raws])
    with RecorderProcess(path=separate, batch_size=500) as process:
        for k in range(0, len(raws), 256):  # bursts, as the pipeline hands them over
            process.write_rows("/tdmon/raw", times[k:k + 256], make,
                               [RAW_ROW(raw) for raw in raws[k:k + 256]])
        end = times[-1]  # what follows comes after, in the file's time order too
        process.write_rows("/tdmon/raw", [end + 1, end + 2], make,
                           [("mqtt", "rig/x", b"{}", 1.0), (1,)])
        process.write_rows("/tdmon/raw", [end + 3], lambda row: {"x": 1}, [("a",)])
        process.write("/tdmon/raw", end + 4, {"after": "the unsendable maker"})
        with pytest.raises(ValueError, match="2 log times for 1 rows"):
            process.write_rows("/tdmon/raw", [1, 2], make, [("a",)])
    want = [m.message for m in read_messages(inline)]
    got = [m.message for m in read_messages(separate)]
    assert got[:len(want)] == want and len(want) == len(raws)
    assert got[len(want):] == [make(("mqtt", "rig/x", b"{}", 1.0)),
                               {"after": "the unsendable maker"}]
    stats = process.stats
    assert stats.written == len(raws) + 2
    assert stats.unencodable == 2 and stats.lost == 2  # the short row, the lambda's row


def test_durable_marks_follow_the_childs_flushes(tmp_path: Path) -> None:
    """What the daemon's acknowledgements go by: a mark of what was written is durable once
    the child has flushed it into the file, after a flush asked for without waiting, or after
    the recorder's own scheduled flush."""
    path = tmp_path / "x.mcap"
    # an interval long enough that "not yet durable" holds however slow the machine is between
    # a write and the check (was: 0.4 s, a 0.2 s window)
    with RecorderProcess(path=path, flush_interval_s=4.0, batch_size=10_000) as recorder:
        for i in range(100):
            recorder.write("/tdmon/raw", 1_000 + i, _raw(i))
        mark = recorder.durable_mark()
        assert mark == 1 and not recorder.is_durable(mark)  # still in this process's batch
        recorder.request_flush()
        deadline = time.monotonic() + 20
        while not recorder.is_durable(mark):
            assert time.monotonic() < deadline, "the asked-for flush never came back"
            time.sleep(0.01)
        assert len(list(read_messages(path, allow_unfinished=True))) == 100
        for i in range(100, 150):
            recorder.write("/tdmon/raw", 1_000 + i, _raw(i))
        later = recorder.durable_mark()
        assert later == 2 and not recorder.is_durable(later)
        deadline = time.monotonic() + 20  # no request: the batch goes within half the
        while not recorder.is_durable(later):  # interval, the child flushes on its own
            assert time.monotonic() < deadline, "the scheduled flush never came back"
            time.sleep(0.02)
        assert len(list(read_messages(path, allow_unfinished=True))) == 150
    assert recorder.stats.written == 150


def test_start_up_problem_is_raised_with_the_childs_reason(tmp_path: Path) -> None:
    existing = tmp_path / "taken.mcap"
    existing.write_bytes(b"")
    with pytest.raises(RecordError, match=r"taken\.mcap: File exists"):
        RecorderProcess(path=existing)  # no overwrite
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("x")
    with pytest.raises(RecordError, match="cannot create output folder"):
        RecorderProcess(not_a_folder / "sub")


def test_killed_child_alarms_once_and_counts_the_rest_as_lost(tmp_path: Path) -> None:
    alarms: list[dict[str, Any]] = []
    recorder = RecorderProcess(path=tmp_path / "x.mcap", batch_size=10,
                               on_alarm=alarms.append)
    for i in range(50):
        recorder.write("/tdmon/raw", i, _raw(i))
    recorder.flush()
    assert recorder.stats.written == 50
    os.kill(recorder._process.pid, signal.SIGKILL)
    recorder._process.wait(10)
    for i in range(50, 250):
        recorder.write("/tdmon/raw", i, _raw(i))  # must not raise
    assert recorder.error is not None and "lost" in str(recorder.error)
    recorder.close()
    assert [a["kind"] for a in alarms] == ["recorder_failed"]
    jsonschema.validate(alarms[0], schemas.TOPIC_SCHEMAS["/tdmon/alarm"])
    stats = recorder.stats
    assert stats.lost >= 190  # all but at most one batch in flight when the child died
    assert stats.written + stats.lost >= 240


def test_sigint_to_the_child_does_not_stop_the_recording(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    recorder = RecorderProcess(path=path, batch_size=16)
    for i in range(100):
        recorder.write("/tdmon/raw", i, _raw(i))
    recorder.flush()
    os.kill(recorder._process.pid, signal.SIGINT)
    time.sleep(0.2)
    for i in range(100, 200):
        recorder.write("/tdmon/raw", i, _raw(i))
    recorder.close()
    assert recorder.error is None
    assert [m.message["receive_time"] for m in read_messages(path)] == [
        1.7e9 + i for i in range(200)]


def test_quiet_pipeline_reaches_the_file_within_the_flush_interval(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap"
    recorder = RecorderProcess(path=path, flush_interval_s=0.2)
    try:
        for i in range(3):
            recorder.write("/tdmon/raw", i, _raw(i))
        deadline = time.monotonic() + 30
        found = 0
        while time.monotonic() < deadline and found < 3:
            time.sleep(0.1)
            found = sum(1 for _ in read_messages(path, allow_unfinished=True))
        assert found == 3
    finally:
        recorder.close()


PARENT_KILLED = """
import os, signal, sys
from tdmon.record.writer_process import RecorderProcess
recorder = RecorderProcess(path=sys.argv[1], flush_interval_s=3600.0)
for i in range(1000):
    recorder.write("/tdmon/raw", i, {"source": "mqtt", "topic": "rig/hl", "receive_time": 1.0,
                   "payload": str(i), "payload_encoding": "utf-8"})
recorder.flush()
print(recorder._process.pid, flush=True)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_parent_killed_child_finishes_the_file(tmp_path: Path, repo: Path) -> None:
    path = tmp_path / "x.mcap"
    completed = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(PARENT_KILLED), str(path)],
        capture_output=True, text=True, timeout=120, cwd=repo, check=False)
    assert completed.returncode == -signal.SIGKILL, completed.stderr
    _wait_gone(int(completed.stdout.split()[0]))
    assert is_finished(path)  # summary and footer written by the orphaned child
    assert [m.message["payload"] for m in read_messages(path)] == [str(i) for i in range(1000)]


FULL_IN_THE_CHILD = """
import json, os, resource, signal, sys, time
from tdmon.record.writer_process import RecorderProcess
# inherited by the child: ignore SIGXFSZ (get EFBIG instead) and the file-size limit
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, resource.RLIM_INFINITY))
alarms = []
recorder = RecorderProcess(sys.argv[1], flush_interval_s=0.01, retry_s=3600,
                           background_flush=False, on_alarm=alarms.append, batch_size=50)
resource.setrlimit(resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
raised = None
try:
    for seq in range(5000):
        recorder.write("/tdmon/raw", time.time_ns(), {"source": "mqtt", "topic": "rig/hl",
                       "receive_time": time.time(), "payload": os.urandom(100).hex(),
                       "payload_encoding": "utf-8"})
        if seq % 50 == 0:
            time.sleep(0.011)
except Exception as exc:
    raised = repr(exc)
error = str(recorder.error)
stats = recorder.stats
# space comes back for the child, the operator asks for a retry
resource.prlimit(recorder._process.pid, resource.RLIMIT_FSIZE,
                 (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
resumed = recorder.retry()
recorder.write("/tdmon/alarm", time.time_ns(), {"t": time.time(), "kind": "k",
               "severity": "info", "message": "after"})
recorder.close()
final = recorder.stats
print(json.dumps({"raised": raised, "error": error, "written": stats.written,
                  "lost": stats.lost, "alarms": alarms, "resumed": resumed,
                  "files": [str(p) for p in final.files], "final_written": final.written}))
"""


def test_full_disk_in_the_child_alarms_here_and_resumes(
    tmp_path: Path, run_child: ChildRunner
) -> None:
    result = run_child(FULL_IN_THE_CHILD, str(tmp_path / "rec"))
    assert result["raised"] is None
    assert "File too large" in result["error"]
    assert result["lost"] > 0
    assert result["written"] + result["lost"] == 5000
    assert [a["kind"] for a in result["alarms"]] == ["recorder_failed", "recorder_resumed"]
    assert result["resumed"]
    resumed_file = Path(result["files"][-1])
    assert is_finished(resumed_file)
    assert [m.message["message"] for m in read_messages(resumed_file)] == ["after"]
    assert result["final_written"] == result["written"] + 1
