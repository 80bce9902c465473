"""Replay-based CI: every replay in replays/ through the daemon's pipeline, against its
expectations; coverage of rig states and alarm kinds; determinism; the command line."""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from functools import cache
from pathlib import Path

import pytest

from tdmon.cli import main
from tdmon.config.daemon import load_daemon_config
from tdmon.config.expectations import load_expectations
from tdmon.record.digest import summarize
from tdmon.record.reader import read_messages, topic_counts
from tdmon.replay.driver import ReplayResult, replay
from tdmon.replay.expectations import Check, check_replay, failed, find_expectations
from tdmon.replay.session import STATES
from tdmon.vocabulary import AlarmKind

from .conftest import REPO

REPLAYS = sorted((REPO / "replays").glob("*.mcap"))

#: Every alarm kind the daemon can raise: tdmon/calib/alarms.py (band, limit_*,
#: friction_jump, sensor_*), tdmon/calib/estimator.py (window_rejected, block_weight,
#: weight_check) and tdmon/record/mcap_recorder.py (recorder_failed, recorder_resumed,
#: recording_recovered).
DAEMON_ALARM_KINDS = frozenset(AlarmKind)
#: Kinds no replay can raise: the recorder's own failure needs a failing file system, its
#: recovery a killed recorder (tests/record/test_crash_and_failure.py and
#: tests/daemon/test_recovery_alarm.py cover them), a clock jump a rig clock that moves
#: (tests/daemon/test_clock_faults.py).
NOT_FROM_REPLAYS = frozenset({"recorder_failed", "recorder_resumed", "recording_recovered",
                              "clock_jump"})


@cache
def _replayed(name: str, out_dir: Path) -> tuple[ReplayResult, list[Check]]:
    """Replay once per test session (the coverage test reuses the per-replay runs)."""
    path = REPO / "replays" / name
    expectations_file = find_expectations(path)
    assert expectations_file is not None, f"{name}: no replays/expectations/{path.stem}.toml"
    expectations = load_expectations(expectations_file)
    config = load_daemon_config(expectations.config_path)
    out = out_dir / f"{path.stem}.out.mcap"
    result = asyncio.run(replay(path, config, out))
    checks = check_replay(expectations, out, non_finite_published=result.non_finite)
    return result, checks


@pytest.fixture(scope="session")
def replayed(tmp_path_factory: pytest.TempPathFactory
             ) -> Callable[[str], tuple[ReplayResult, list[Check]]]:
    out_dir = tmp_path_factory.mktemp("replayed")
    return lambda name: _replayed(name, out_dir)


@pytest.mark.parametrize("path", REPLAYS, ids=lambda p: p.stem)
def test_replay_meets_its_expectations(
        path: Path, replayed: Callable[[str], tuple[ReplayResult, list[Check]]]) -> None:
    result, checks = replayed(path.name)
    assert result.step_errors == 0 and result.sink_errors == 0 and result.dropped == 0
    assert result.messages_in > 0 and result.frames > 0
    bad = failed(checks)
    assert not bad, "\n".join(c.line() for c in bad)


def test_replays_cover_every_state_and_alarm_kind(
        replayed: Callable[[str], tuple[ReplayResult, list[Check]]]) -> None:
    """Across the replays' outputs every rig state is reported and every alarm kind the daemon
    can raise (bar the recorder's own) is raised, and an expectation requires each alarm."""
    states: set[str] = set()
    alarms: set[str] = set()
    required: set[str] = set()
    for path in REPLAYS:
        result, checks = replayed(path.name)
        states |= set(result.state_shares)
        alarms |= set(result.alarms)
        required |= {c.measured.split(" at ")[0] for c in checks
                     if c.name.startswith("alarm ") and c.passed}
    assert set(STATES) <= states, f"states never reported: {set(STATES) - states}"
    assert alarms <= DAEMON_ALARM_KINDS, f"unlisted alarm kinds: {alarms - DAEMON_ALARM_KINDS}"
    missing = DAEMON_ALARM_KINDS - NOT_FROM_REPLAYS - alarms
    assert not missing, f"alarm kinds no replay raises: {sorted(missing)}"
    # window_rejected is bookkeeping, not an event anyone expects: raised, not required
    unrequired = DAEMON_ALARM_KINDS - NOT_FROM_REPLAYS - {"window_rejected"} - required
    assert not unrequired, f"alarm kinds no expectation requires: {sorted(unrequired)}"


def test_a_replays_recording_spans_the_rig_time_of_its_input(
        replayed: Callable[[str], tuple[ReplayResult, list[Check]]]) -> None:
    """Log times are rig time (the inputs' recorded receive times), not the seconds the replay
    took: the recording spans the session, and the last status carries its end."""
    name = "trip-out-tight-spot.mcap"
    result, _ = replayed(name)
    inputs = [m.log_time_ns for m in read_messages(REPO / "replays" / name, "/tdmon/raw")]
    recorded = list(read_messages(result.out))
    log_times = [m.log_time_ns for m in recorded]
    assert max(inputs) - min(inputs) > 20 * 60 * 10**9  # a 25-minute session
    assert (min(log_times), max(log_times)) == (min(inputs), max(inputs))
    status = [m for m in recorded if m.topic == "/tdmon/status"][-1]
    assert status.log_time_ns == max(inputs)
    assert status.message["t"] == pytest.approx(max(inputs) / 1e9)


def test_same_replay_twice_gives_identical_estimates(tmp_path: Path) -> None:
    """Twice, once recording from a child process (the default) and once in-process: the
    estimate streams, and every other recorded message bar the wall-clock status, agree."""
    path = REPO / "replays" / "trip-out-tight-spot.mcap"
    expectations = load_expectations(find_expectations(path))  # type: ignore[arg-type]
    config = load_daemon_config(expectations.config_path)
    streams = []
    for run, separate in (("a", True), ("b", False)):
        out = tmp_path / f"{run}.mcap"
        asyncio.run(replay(path, config, out, separate_writer=separate))
        streams.append([(m.topic, m.log_time_ns, m.message) for m in read_messages(out)
                        if m.topic != "/tdmon/status"])
    estimates = [item for item in streams[0] if item[0] == "/tdmon/estimate"]
    assert len(estimates) > 50
    assert estimates == [item for item in streams[1] if item[0] == "/tdmon/estimate"]
    assert streams[0] == streams[1]


def test_paced_replay_ends_by_itself_with_every_sample(tmp_path: Path) -> None:
    """--speed N keeps the live daemon's wall-clock housekeeping and still stops at the end."""
    path = REPO / "replays" / "trip-in-noisy.mcap"  # 16 min of rig time: about 1 s at 1000x
    config = load_daemon_config(REPO / "config" / "daemon" / "replay-sim-trip-in.toml")
    advanced: list[int] = []
    result = asyncio.run(replay(path, config, tmp_path / "o.mcap", speed=1000.0,
                                progress=advanced.append))
    assert result.samples == 965 and result.dropped == 0 and result.frames > 100
    assert sum(advanced) == 965  # the progress bar's steps add up to the input
    assert 0.9 < result.wall_s < 30
    statuses = list(read_messages(tmp_path / "o.mcap", "/tdmon/status"))
    assert len(statuses) >= 1 and statuses[-1].message["connections"]["mcap"] == "finished"


def test_cli_replay_check_summary_and_rrd(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    path = REPO / "replays" / "trip-in-noisy.mcap"
    out, rrd = tmp_path / "out.mcap", tmp_path / "out.rrd"
    code = main(["replay", str(path), "--out", str(out), "--rrd", str(rrd), "--check",
                 "--json"])
    summary = json.loads(capsys.readouterr().out)
    assert code == 0
    assert summary["messages_in"] == summary["samples"] == 965
    # the engineer's numbers, gathered while replaying, are those of the recording read back
    read_back = summarize([out])
    assert {key: summary[key] for key in read_back} == read_back
    assert read_back["friction"] and read_back["alarm_summary"]
    inline = tmp_path / "inline.mcap"
    config = REPO / "config" / "daemon" / "replay-sim-trip-in.toml"
    assert main(["replay", str(path), "--config", str(config), "--out", str(inline),
                 "--recorder", "inline", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["messages_in"] == 965
    assert topic_counts(inline) == topic_counts(out)
    assert summary["estimates"]["window"] > 0 and summary["alarms"]["sensor_stale"] > 0
    assert abs(sum(summary["state_shares"].values()) - 1.0) < 1e-3
    assert all(c["passed"] or c["known_issue"] for c in summary["checks"])
    assert rrd.stat().st_size > 0
    topics = {m.topic for m in read_messages(out)}
    assert {"/tdmon/raw", "/tdmon/sample", "/tdmon/state", "/tdmon/model", "/tdmon/estimate",
            "/tdmon/alarm", "/tdmon/status"} <= topics


def test_cli_replay_fails_on_a_missed_expectation(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path = REPO / "replays" / "trip-in-noisy.mcap"
    text = (REPO / "replays" / "expectations" / "trip-in-noisy.toml").read_text()
    strict = tmp_path / "strict.toml"
    strict.write_text(
        text.replace('"../', f'"{REPO}/replays/expectations/../')
        .replace("messages = 965", "messages = 966")
        + '\n[[friction]]\noperation = "slack_off"\nmin = 0.5\nmax = 0.6\n')
    code = main(["replay", str(path), "--out", str(tmp_path / "o.mcap"), "--check",
                 str(strict), "--no-progress"])
    out = capsys.readouterr().out
    assert code == 1
    assert "FAIL decoded samples: 965 (expected 966); -1" in out
    assert "FAIL friction slack_off: median" in out and "median off by" in out


def test_cli_replay_user_mistakes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = REPO / "replays" / "trip-in-noisy.mcap"
    config = REPO / "config" / "daemon" / "replay-sim-trip-in.toml"
    assert main(["replay", str(path), "--config", str(config), "--out",
                 str(tmp_path / "o.mcap"), "--speed", "fast"]) == 2
    assert "--speed" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "none.mcap"), "--config", str(config), "--out",
                 str(tmp_path / "o.mcap")]) == 2
    assert "replay not found" in capsys.readouterr().err
    assert main(["replay", str(path), "--out", str(tmp_path / "o.mcap")]) == 2
    assert "--config" in capsys.readouterr().err


def test_ctrl_c_stops_a_replay_with_a_finished_recording(tmp_path: Path) -> None:
    """SIGINT (Ctrl-C): what was read is processed and recorded, the file is finished, the
    summary says so, exit 130."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "o.mcap"
    path = REPO / "replays" / "trip-in-noisy.mcap"  # 16 min of rig time: ~16 s at 60x
    process = subprocess.Popen(
        [sys.executable, "-c", "import sys; from tdmon.cli import main; sys.exit(main())",
         "replay", str(path), "--config",
         str(REPO / "config" / "daemon" / "replay-sim-trip-in.toml"), "--out", str(out),
         "--speed", "60", "--json"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    deadline = time.monotonic() + 60
    while not out.exists() and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(1.5)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "replay interrupted after" in stderr
    summary = json.loads(stdout)
    assert summary["interrupted"] is True
    assert 0 < summary["messages_in"] < 965
    counts = topic_counts(out)  # a finished file: no recovery needed
    assert counts["/tdmon/raw"] == summary["messages_in"]
    assert "Traceback" not in stderr and "never retrieved" not in stderr
