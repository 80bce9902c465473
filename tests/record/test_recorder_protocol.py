"""The in-process and the child-process recorder meet one Recorder protocol."""

from __future__ import annotations

from pathlib import Path

import pytest

from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import is_finished, read_messages
from tdmon.record.sink import Recorder, RecorderStats
from tdmon.record.writer_process import RecorderProcess

TOPIC = "/truth/hookload"


def _record_three(recorder: Recorder) -> tuple[Path | None, RecorderStats]:
    """Everything the daemon and the replay driver use of a recorder, through the protocol."""
    recorder.register_topic(TOPIC, {"type": "object"})
    for i in range(3):
        recorder.write(TOPIC, 1_700_000_000_000_000_000 + i, {"t": float(i), "value": 10 * i})
    recorder.flush()
    assert recorder.error is None
    assert recorder.retry()  # recording: nothing to retry, still True
    path = recorder.path
    recorder.close()
    recorder.close()  # idempotent
    assert recorder.path is None
    return path, recorder.stats


@pytest.mark.parametrize("recorder_type", [McapRecorder, RecorderProcess])
def test_both_recorders_meet_the_protocol(
        tmp_path: Path, recorder_type: type[McapRecorder] | type[RecorderProcess]) -> None:
    out = tmp_path / "out.mcap"
    path, stats = _record_three(recorder_type(path=out, flush_interval_s=5.0))
    assert path == out
    assert (stats.written, stats.lost, stats.per_topic.get(TOPIC)) == (3, 0, 3)
    assert is_finished(out)
    assert [m.message["value"] for m in read_messages(out, TOPIC)] == [0, 10, 20]
