"""Loss the daemon can see for itself: gaps in a publisher's ``seq`` counter and in a channel's
regular sampling (docs/daemon.md, "Loss the daemon can see").

Pure bookkeeping on decoded samples: :meth:`LossDetector.observe` returns the ``data_loss``
alarms a sample reveals, and the counters go into the status message.
"""

from __future__ import annotations

import asyncio
import logging
import math
import statistics
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tdmon.ingest.loss_state import read_state, write_state
from tdmon.ingest.types import Sample
from tdmon.messages import alarm_message
from tdmon.vocabulary import AlarmKind, Severity

log = logging.getLogger(__name__)

#: An interval this many times the channel's median interval is a sampling gap [-].
GAP_FACTOR = 10.0
#: ... and at least this long [s] (so a 10 Hz channel must be silent for 2 s).
GAP_MIN_S = 2.0
#: Intervals kept per channel for the median, and needed before any gap is judged.
INTERVALS_KEPT = 64
INTERVALS_NEEDED = 16
#: A channel's median is worked out again after this many new intervals [-].
_MEDIAN_EVERY = INTERVALS_KEPT // 4


@dataclass(slots=True)
class _Sampling:
    last_t: float
    intervals: deque[float] = field(default_factory=lambda: deque(maxlen=INTERVALS_KEPT))
    median: float | None = None
    since_median: int = 0
    rebase: bool = False  # the rig clock jumped: the next sample starts the timing again


#: A forward jump in a topic's ``seq`` is held open this long [s of rig time] for the missing
#: numbers to arrive before they are counted lost: a broker restarting, or a daemon restarted
#: after SIGKILL, can deliver a topic's newer messages before its backlog (mosquitto did, with
#: the backlog a few seconds behind).
SEQ_HOLD_S = 30.0
#: Jumps held open per topic at most; beyond, the oldest is judged at once (a hostile or
#: broken counter cannot make the detector keep unbounded state).
SEQ_GAPS_KEPT = 64


@dataclass(slots=True)
class _SeqGap:
    """One forward jump of a topic's ``seq``: the numbers still missing (inclusive ranges),
    and when the wait for them ends [s of rig time]."""

    before: int  # the last number before the jump
    after: int  # the number that revealed it
    deadline: float
    missing: list[list[int]]

    def take(self, seq: int) -> bool:
        """Take ``seq`` if it is one of the missing numbers; True if it was."""
        for index, (low, high) in enumerate(self.missing):
            if low <= seq <= high:
                if low == high:
                    del self.missing[index]
                elif seq == low:
                    self.missing[index][0] = seq + 1
                elif seq == high:
                    self.missing[index][1] = seq - 1
                else:
                    self.missing[index:index + 1] = [[low, seq - 1], [seq + 1, high]]
                return True
        return False

    def count(self) -> int:
        return sum(high - low + 1 for low, high in self.missing)


@dataclass(slots=True)
class _SeqState:
    high: int
    gaps: list[_SeqGap] = field(default_factory=list)


class LossDetector:
    """Count missing messages from ``seq`` and silences in regular sampling.

    ``seq`` (optional, per topic, from the publisher) should grow by one per message. A jump
    forward is held open for :data:`SEQ_HOLD_S` of rig time: a missing number that arrives
    in that time is late, not lost (``seq_late``); what is still missing then is counted in
    ``seq_lost``, with one alarm per jump giving the number. A counter that falls below half
    its highest value, to a number no open jump is waiting for, is a publisher that restarted:
    its open jumps are judged at once and it is taken as the new start. Any other step back
    (a redelivery) is ignored. :meth:`finish` judges every open jump (the end of the input).
    A channel's sample that comes more than ``GAP_FACTOR`` times its median interval
    (and at least ``GAP_MIN_S``) after the previous one is a sampling gap (``sampling_gaps``,
    one alarm per gap with the estimated number of missing samples).
    """

    def __init__(self, hold: float = SEQ_HOLD_S) -> None:
        self.hold = hold
        self.seq_lost = 0
        self.seq_gaps = 0
        self.seq_late = 0
        self.sampling_gaps = 0
        self._seq: dict[str, _SeqState] = {}
        self._sampling: dict[str, _Sampling] = {}
        self._open = 0  # jumps held open, all topics
        self._next_deadline = math.inf
        self._clock = -math.inf  # the latest rig time seen [s]
        self._state_path: Path | None = None
        self._rebase_holds = False  # the rig clock jumped while jumps were held open

    def observe(self, sample: Sample) -> list[dict[str, Any]]:
        """Take one decoded sample; the ``data_loss`` alarms it reveals (usually none)."""
        alarms: list[dict[str, Any]] = []
        if self._rebase_holds:
            self._shift_holds(sample.t - self._clock)
            self._clock = sample.t
        if sample.t > self._clock:
            self._clock = sample.t
            if sample.t >= self._next_deadline:
                alarms += self._expire(sample.t)
        if sample.seq is not None:
            alarms += self._check_seq(sample)
        # the usual sample, the next of a known channel without a gap, without a method call
        # (once per sample)
        state = self._sampling.get(sample.channel)
        if state is not None and not state.rebase and state.median is not None:
            t = sample.t
            interval = t - state.last_t
            since_median = state.since_median + 1
            if 0 < interval <= GAP_FACTOR * state.median and since_median < _MEDIAN_EVERY:
                # what _check_sampling does with it: no gap, no new median yet
                state.intervals.append(interval)
                state.last_t = t
                state.since_median = since_median
                return alarms
        alarm = self._check_sampling(sample)
        if alarm is not None:
            alarms.append(alarm)
        return alarms

    # -- the state kept across restarts (tdmon.ingest.loss_state) ----------------------------

    def keep_state(self, path: Path) -> None:
        """Keep this detector's state in ``path`` (:meth:`save`), starting from what a previous
        run left there: a restarted daemon then counts what never came while it was away."""
        self._state_path = path
        state = read_state(path)
        if state is None:
            return
        try:
            self._restore(state)
        except (KeyError, TypeError, ValueError) as exc:
            log.warning("%s: loss state not used (%s); counting loss afresh", path, exc)
            self._seq, self._sampling, self._open = {}, {}, 0
            self._next_deadline, self._clock = math.inf, -math.inf
            return
        log.info("%s: loss counting goes on from the last run (%d topics, %d jumps held "
                 "open, %d channels)", path, len(self._seq), self._open, len(self._sampling))

    def save(self) -> None:
        """Write the state to the file :meth:`keep_state` named (nothing without one). The
        daemon calls it before acknowledging messages to the broker and with every status,
        so the file never lags behind what the broker will not send again."""
        if self._state_path is None:
            return
        try:
            write_state(self._state_path, self._snapshot())
        except OSError as exc:
            log.warning("%s: cannot save the loss state: %s", self._state_path, exc)

    def _snapshot(self) -> dict[str, Any]:
        return {
            "clock": None if self._clock == -math.inf else self._clock,
            "seq": {topic: {"high": state.high,
                            "gaps": [[gap.before, gap.after, gap.deadline, gap.missing]
                                     for gap in state.gaps]}
                    for topic, state in self._seq.items()},
            "sampling": {channel: {"last_t": state.last_t, "median": state.median,
                                   "intervals": list(state.intervals)}
                         for channel, state in self._sampling.items()},
        }

    def _restore(self, state: dict[str, Any]) -> None:
        clock = state.get("clock")
        self._clock = -math.inf if clock is None else float(clock)
        self._seq = {}
        for topic, saved in state["seq"].items():
            gaps = [_SeqGap(int(before), int(after), float(deadline),
                            [[int(low), int(high)] for low, high in missing])
                    for before, after, deadline, missing in saved["gaps"][:SEQ_GAPS_KEPT]]
            self._seq[str(topic)] = _SeqState(int(saved["high"]), gaps)
        self._open = sum(len(state.gaps) for state in self._seq.values())
        self._next_deadline = min((gap.deadline for state in self._seq.values()
                                   for gap in state.gaps), default=math.inf)
        self._sampling = {}
        for channel, saved in state["sampling"].items():
            median = saved["median"]
            sampling = _Sampling(float(saved["last_t"]), median=None if median is None
                                 else float(median))
            sampling.intervals.extend(float(x) for x in saved["intervals"][-INTERVALS_KEPT:])
            self._sampling[str(channel)] = sampling

    def reanchor(self) -> None:
        """The rig clock jumped: the next interval of every channel spans the jump, so it is
        neither a gap (a clock gone forward) nor ignored for ever (a clock gone back); the
        jumps held open keep what is left of their hold, counted on the new clock."""
        for state in self._sampling.values():
            state.rebase = True
        self._rebase_holds = self._open > 0

    def _check_seq(self, sample: Sample) -> list[dict[str, Any]]:
        seq = sample.seq
        assert seq is not None
        state = self._seq.get(sample.topic)
        if state is None:
            self._seq[sample.topic] = _SeqState(seq)
            return []
        high = state.high
        if seq == high + 1:
            state.high = seq
            return []
        alarms: list[dict[str, Any]] = []
        if seq > high:
            if len(state.gaps) >= SEQ_GAPS_KEPT:
                alarms += self._judge(sample.topic, state, [state.gaps[0]], sample.t)
            state.gaps.append(_SeqGap(high, seq, sample.t + self.hold,
                                      [[high + 1, seq - 1]]))
            self._open += 1
            self._next_deadline = min(self._next_deadline, sample.t + self.hold)
            state.high = seq
            return alarms
        for gap in state.gaps:
            if gap.take(seq):
                self.seq_late += 1
                if not gap.missing:
                    state.gaps.remove(gap)
                    self._open -= 1
                return alarms
        if seq < high // 2:  # the publisher restarted its counter
            alarms += self._judge(sample.topic, state, list(state.gaps), sample.t)
            state.high = seq
        return alarms

    def _judge(self, topic: str, state: _SeqState, gaps: list[_SeqGap], t: float
               ) -> list[dict[str, Any]]:
        """Count ``gaps`` of ``topic`` lost (what is still missing of each) and close them."""
        alarms = []
        for gap in gaps:
            state.gaps.remove(gap)
            self._open -= 1
            missing = gap.count()
            self.seq_lost += missing
            self.seq_gaps += 1
            alarms.append(alarm_message(
                t, AlarmKind.DATA_LOSS, Severity.WARNING,
                f"{missing} message(s) on {topic} never arrived (seq {gap.before} -> "
                f"{gap.after})", value=missing))
        return alarms

    def _expire(self, now: float) -> list[dict[str, Any]]:
        """Judge the jumps whose hold ended by rig time ``now``."""
        alarms = []
        upcoming = math.inf
        for topic, state in self._seq.items():
            if not state.gaps:
                continue
            due = [gap for gap in state.gaps if gap.deadline <= now]
            alarms += self._judge(topic, state, due, now)
            upcoming = min([upcoming, *(gap.deadline for gap in state.gaps)])
        self._next_deadline = upcoming
        return alarms

    def _shift_holds(self, shift: float) -> None:
        """Move every held jump's deadline by ``shift`` [s] (the rig clock jumped)."""
        self._rebase_holds = False
        for state in self._seq.values():
            for gap in state.gaps:
                gap.deadline += shift
        self._next_deadline += shift

    def finish(self) -> list[dict[str, Any]]:
        """The end of the input: every jump still open is judged now; its alarms."""
        alarms = []
        t = self._clock if self._open else 0.0
        for topic, state in self._seq.items():
            alarms += self._judge(topic, state, list(state.gaps), t)
        self._next_deadline = math.inf
        return alarms

    def _check_sampling(self, sample: Sample) -> dict[str, Any] | None:
        state = self._sampling.get(sample.channel)
        if state is None:
            self._sampling[sample.channel] = _Sampling(sample.t)
            return None
        if state.rebase:
            state.last_t, state.rebase = sample.t, False
            return None
        interval = sample.t - state.last_t
        if interval <= 0:
            return None  # duplicate or out of order: the aligner counts those
        state.last_t = sample.t
        median = state.median
        alarm = None
        if (median is not None and interval > GAP_FACTOR * median
                and interval >= GAP_MIN_S):
            self.sampling_gaps += 1
            missing = max(1, round(interval / median) - 1) if median > 0 else 1
            alarm = alarm_message(
                sample.t, AlarmKind.DATA_LOSS, Severity.WARNING,
                f"no {sample.channel} samples for {interval:.1f} s (usually every "
                f"{median:.3g} s): about {missing} missing", value=missing)
        else:
            # a gap stays out of the median, so a second gap is judged against the same rate
            state.intervals.append(interval)
            state.since_median += 1
            if len(state.intervals) >= INTERVALS_NEEDED and (
                    median is None or state.since_median >= _MEDIAN_EVERY):
                state.median = statistics.median(state.intervals)
                state.since_median = 0
        return alarm


#: A stretch of drops is alarmed once per this many seconds, with its count [s].
DROP_ALARM_INTERVAL = 5.0


class DropAlarm:
    """Messages a full queue had to drop: each counted at once (``count``), and one
    ``data_loss`` alarm (``emit``) per :data:`DROP_ALARM_INTERVAL` while drops go on, with how
    many were dropped since the last alarm. Call :meth:`add` on the event loop's thread."""

    def __init__(self, what: str, count: Callable[[int], None],
                 emit: Callable[[dict[str, Any]], None],
                 interval: float = DROP_ALARM_INTERVAL) -> None:
        self.what = what
        self.count = count
        self.emit = emit
        self.interval = interval
        self.dropped = 0
        self.alarms = 0
        self._unreported = 0
        self._timer: asyncio.TimerHandle | None = None

    def add(self, n: int = 1) -> None:
        self.dropped += n
        self._unreported += n
        self.count(n)
        if self._timer is None:
            self._timer = asyncio.get_running_loop().call_later(self.interval, self.report)

    def report(self) -> None:
        """Alarm what was dropped since the last alarm (nothing: no alarm)."""
        self._timer = None
        n, self._unreported = self._unreported, 0
        if n:
            self.alarms += 1
            self.emit(alarm_message(
                time.time(), AlarmKind.DATA_LOSS, Severity.WARNING,
                f"{n} message(s) dropped: {self.what}", value=n))
