"""Clock jumps in the log (issue 33): a few lines with the real jump, not a warning per jump.

A daemon that has seen the present and is then fed a session of the past at 60 x real time
(``tdmon publish`` without ``--now``, or a second session into the same daemon) sees the rig
clock go back once, then run fast: every ~0.35 s of receive time the samples are more than
``future_tolerance`` ahead of the anchor and a forward jump of ~10.5 s is confirmed. It used
to log 136 warnings "rig clock went forward 1 s" in 25 s (the jump measured from the last
sample accepted, itself already ~10 s ahead). The pipeline below is the daemon's own
(decoder, clock guard, aligner); the alarms stay one per jump.
"""

from __future__ import annotations

import logging
import re

import pytest
from daemon_support import payload

from tdmon.daemon.aligner import Aligner
from tdmon.daemon.clock import ClockGuard, ClockJump, ClockSettings, JumpLog
from tdmon.daemon.pipeline import Pipeline
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.types import RawMessage, Sample
from tdmon.record.sink import MessageSink

T0 = 1_700_000_000.0
STEP = 0.5  # [s] of rig time between rows
LATENCY = 0.05  # [s]
SPEED = 60.0
CHANNELS = ("hookload", "torque", "bit_depth")


class _Alarms(MessageSink):
    """A sink keeping (receive time of the message being processed, seconds) of every clock
    jump alarm."""

    def __init__(self) -> None:
        self.receive = 0.0
        self.jumps: list[tuple[float, float]] = []

    def write(self, topic: str, log_time_ns: int, message: dict[str, object]) -> None:
        if topic == "/tdmon/alarm" and message["kind"] == "clock_jump":
            self.jumps.append((self.receive, float(message["value"])))  # type: ignore[arg-type]

    def close(self) -> None:
        pass


def _pipeline() -> tuple[Pipeline, ClockGuard, _Alarms]:
    """The pipeline, its guard and its clock jump alarms."""
    decoder = Decoder("rig", [ChannelSpec("hookload", "hookload", "kN"),
                              ChannelSpec("torque", "torque", "kN*m"),
                              ChannelSpec("bit_depth", "bit_depth", "m")])
    guard = ClockGuard(ClockSettings())
    alarms = _Alarms()
    return Pipeline(decoder, Aligner(), sinks=[alarms], clock=guard), guard, alarms


def _feed(pipeline: Pipeline, alarms: _Alarms, rows: list[tuple[float, float]]) -> None:
    """(rig time, receive time) per row; one message per channel and row."""
    for t, receive in rows:
        alarms.receive = receive
        for channel in CHANNELS:
            pipeline.process(RawMessage("zenoh", f"rig/{channel}", payload(t, 1.0), receive))


def test_a_session_of_the_past_at_60x_is_a_few_lines_with_the_real_jumps(
        caplog: pytest.LogCaptureFixture) -> None:
    pipeline, guard, alarms = _pipeline()
    live = [(T0 + STEP * i, T0 + STEP * i + LATENCY) for i in range(60)]  # 30 s at real time
    start = live[-1][1] + 1.0
    # then 25 s of receive time: a session 1 h back, at 60 x real time
    rows = int(25.0 * SPEED / STEP)
    fast = [(T0 - 3600 + STEP * j, start + STEP * j / SPEED) for j in range(rows)]
    with caplog.at_level(logging.WARNING, logger="tdmon.daemon.pipeline"):
        _feed(pipeline, alarms, live + fast)
    jumps = alarms.jumps
    lines = [r.getMessage() for r in caplog.records if "rig clock went" in r.getMessage()]

    # one alarm per jump: back once, then forward again and again
    assert jumps[0][1] == pytest.approx(-3600, abs=35)
    forward = [seconds for _, seconds in jumps[1:]]
    assert len(forward) >= 60 and pipeline.stats.clock_jumps == len(jumps)
    # each forward jump is the anchor's move: past the 10 s tolerance, not the ~0.5 s from
    # the last sample accepted
    assert all(10.0 < seconds < 12.5 for seconds in forward)
    # the guard's anchor moved by their sum
    assert guard.offset == pytest.approx(jumps[0][1] + sum(forward) - LATENCY, abs=35)

    # the log: the back jump at once, then one line per 10 s of receive time at most
    assert 2 <= len(lines) <= 4
    assert lines[0].startswith("rig clock went back 36")
    assert all(line.startswith("rig clock went forward 1") for line in lines[1:])
    summary = lines[1]
    found = re.search(r"receive time ([\d.]+)\); (\d+) clock jumps in the last ([\d.]+) s, "
                      r"([+-]\d+) s in all", summary)
    assert found is not None, summary
    # the line stands for every forward jump up to its own, and adds them up
    held = [seconds for receive, seconds in jumps[1:] if receive <= float(found.group(1))]
    assert int(found.group(2)) == len(held)
    assert 10.0 <= float(found.group(3)) <= 10.5
    assert int(found.group(4)) == round(sum(held))
    assert "running fast" in summary


def test_the_log_holds_jumps_for_its_interval_and_counts_them() -> None:
    log = JumpLog(interval=10.0)

    def jump(seconds: float, receive: float) -> ClockJump:
        return ClockJump(seconds, receive + seconds, receive, seconds)

    first = log.line(jump(11.0, 100.0))
    assert first is not None and first.startswith("rig clock went forward 11 s;")
    assert "in all" not in first
    assert [log.line(jump(11.0, 100.0 + k)) for k in range(1, 10)] == [None] * 9
    second = log.line(jump(12.0, 110.0))
    assert second is not None
    assert "; 10 clock jumps in the last 10.0 s, +111 s in all" in second
    assert log.line(jump(11.0, 115.0)) is None
    # jumps both ways are no clock running fast
    third = log.line(jump(-3600.0, 121.0))
    assert third is not None and "2 clock jumps" in third and "-3589 s in all" in third
    assert "running fast" not in third


def test_the_first_jump_is_measured_from_the_last_sample_the_next_from_the_anchor() -> None:
    """Before any jump the anchor (0) is assumed: a constant latency cancels out against the
    last sample accepted. Once a jump set it, the next is measured from it."""
    guard = ClockGuard(ClockSettings(jump_samples=2))

    def sample(t: float, receive: float, channel: str = "hookload") -> Sample:
        return Sample(channel, t, 1.0, "zenoh", f"rig/{channel}", "kN", receive)

    assert guard.check(sample(T0, T0 + 2.0)) is None  # 2 s of latency
    assert isinstance(guard.check(sample(T0 + 3600, T0 + 2.0)), str)
    first = guard.check(sample(T0 + 3600, T0 + 2.0, "torque"))
    assert isinstance(first, ClockJump) and first.seconds == pytest.approx(3600.0)
    # a sample 9 s ahead of the new anchor is accepted; the jump after it is from the anchor
    assert guard.check(sample(T0 + 3609, T0 + 2.0)) is None
    assert isinstance(guard.check(sample(T0 + 3620, T0 + 2.0)), str)
    second = guard.check(sample(T0 + 3620, T0 + 2.0, "torque"))
    assert isinstance(second, ClockJump) and second.seconds == pytest.approx(20.0)
