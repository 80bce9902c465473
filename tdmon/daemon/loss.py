"""Loss the daemon can see for itself: gaps in a publisher's ``seq`` counter and in a channel's
regular sampling (docs/daemon.md, "Loss the daemon can see").

Pure bookkeeping on decoded samples: :meth:`LossDetector.observe` returns the ``data_loss``
alarms a sample reveals, and the counters go into the status message.
"""

from __future__ import annotations

import asyncio
import statistics
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from tdmon.ingest.types import Sample
from tdmon.messages import alarm_message
from tdmon.vocabulary import AlarmKind, Severity

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


class LossDetector:
    """Count missing messages from ``seq`` and silences in regular sampling.

    ``seq`` (optional, per topic, from the publisher) should grow by one per message; a jump
    of n + 1 means n messages never arrived (counted in ``seq_lost``, one alarm with n). A
    counter that falls to below half its last value is a publisher that restarted: it is
    taken as the new start. A smaller step back (a redelivery, an out-of-order message) is
    ignored. A channel's sample that comes more than ``GAP_FACTOR`` times its median interval
    (and at least ``GAP_MIN_S``) after the previous one is a sampling gap (``sampling_gaps``,
    one alarm per gap with the estimated number of missing samples).
    """

    def __init__(self) -> None:
        self.seq_lost = 0
        self.seq_gaps = 0
        self.sampling_gaps = 0
        self._seq: dict[str, int] = {}
        self._sampling: dict[str, _Sampling] = {}

    def observe(self, sample: Sample) -> list[dict[str, Any]]:
        """Take one decoded sample; the ``data_loss`` alarms it reveals (usually none)."""
        alarms: list[dict[str, Any]] = []
        if sample.seq is not None:
            alarm = self._check_seq(sample)
            if alarm is not None:
                alarms.append(alarm)
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

    def reanchor(self) -> None:
        """The rig clock jumped: the next interval of every channel spans the jump, so it is
        neither a gap (a clock gone forward) nor ignored for ever (a clock gone back)."""
        for state in self._sampling.values():
            state.rebase = True

    def _check_seq(self, sample: Sample) -> dict[str, Any] | None:
        seq = sample.seq
        assert seq is not None
        last = self._seq.get(sample.topic)
        if last is None or seq > last or seq < last // 2:
            self._seq[sample.topic] = seq
        if last is None or seq <= last + 1:
            return None
        missing = seq - last - 1
        self.seq_lost += missing
        self.seq_gaps += 1
        return alarm_message(
            sample.t, AlarmKind.DATA_LOSS, Severity.WARNING,
            f"{missing} message(s) on {sample.topic} never arrived (seq {last} -> {seq})",
            value=missing)

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
