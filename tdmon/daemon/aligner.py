"""Align channels on the hook-load timeline.

Each channel keeps a short history of (t, value). A hook-load sample newer than the last frame
opens a pending frame at its time; the frame is emitted as soon as every channel waited for
has data at or after that time, when the next hook-load sample arrives, or after ``max_wait``
seconds (wall clock, so a late channel delays results by at most that much).

A channel is waited for (all channels, or those in ``wait_for``) while it keeps pace with the
hook load: it had a sample at or after the previous frame, not older than the stale timeout
(which must therefore exceed the rig's sampling interval). A slower channel (bit depth at 1 Hz
against hook load at 10 Hz) or a silent one is used with its age instead of holding every
frame back. Channels in ``expected`` (the rig's channel map) but never seen are waited for
during the first ``stale_timeout`` of the stream, so the first frames of a start-up are
complete.

Duplicates (same channel and time as a sample already held) are counted and ignored.
Out-of-order samples (older than the channel's newest) are counted; they still fill the history
if they fall inside it, so a late bit depth can complete a pending frame, but they never move a
frame backwards in time.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from dataclasses import dataclass

from tdmon.daemon.pipeline import Frame
from tdmon.ingest.types import Sample

#: Times closer than this are the same instant (rigs stamp with ms resolution at best).
_SAME_TIME = 1e-6


@dataclass(slots=True)
class _Pending:
    t: float
    value: float
    opened: float  # monotonic
    log_time_ns: int


class Aligner:
    """Latest-value-per-channel alignment with stale detection (see module docstring)."""

    def __init__(
        self,
        trigger: str = "hookload",
        wait_for: Iterable[str] | None = None,
        expected: Iterable[str] = (),
        stale_timeout: float = 5.0,
        max_wait: float = 0.25,
        history: int = 8,
    ) -> None:
        self.trigger = trigger
        self.wait_for = None if wait_for is None else tuple(c for c in wait_for if c != trigger)
        # channels the rig is known to send (its channel map): waited for at start-up even
        # before their first sample, so that the first frames are complete
        self.expected = tuple(c for c in expected if c != trigger)
        self.stale_timeout = stale_timeout
        self.max_wait = max_wait
        self.history = history
        self._times: dict[str, list[float]] = {}
        self._values: dict[str, list[float]] = {}
        self._pending: _Pending | None = None
        self._last_frame_t = float("-inf")
        self._first_t: float | None = None
        self.duplicates = 0
        self.out_of_order = 0

    def push(self, sample: Sample, now: float) -> list[Frame]:
        """Take one sample (``now`` is monotonic seconds); return the frames it completes."""
        if not self._store(sample):
            return []
        frames: list[Frame] = []
        if sample.channel == self.trigger and sample.t > self._last_frame_t + _SAME_TIME:
            pending = self._pending
            if pending is None or sample.t > pending.t + _SAME_TIME:
                if pending is not None:
                    frames.append(self._emit())
                self._pending = _Pending(sample.t, sample.value, now,
                                         int(sample.receive_time * 1e9))
            # an out-of-order hook load older than the pending one is kept in the history only
        if self._pending is not None and self._complete(self._pending.t):
            frames.append(self._emit())
        return frames

    def expire(self, now: float) -> list[Frame]:
        """Emit the pending frame if it has waited ``max_wait`` seconds."""
        if self._pending is not None and now - self._pending.opened >= self.max_wait:
            return [self._emit()]
        return []

    def flush(self) -> list[Frame]:
        """Emit the pending frame, whatever it still waits for (end of input)."""
        return [self._emit()] if self._pending is not None else []

    def latest(self, channel: str) -> tuple[float, float] | None:
        """(t, value) of the newest sample on ``channel``."""
        times = self._times.get(channel)
        if not times:
            return None
        return times[-1], self._values[channel][-1]

    def _store(self, sample: Sample) -> bool:
        if self._first_t is None:
            self._first_t = sample.t
        times = self._times.get(sample.channel)
        if times is None:
            self._times[sample.channel] = [sample.t]
            self._values[sample.channel] = [sample.value]
            return True
        values = self._values[sample.channel]
        newest = times[-1]
        if abs(sample.t - newest) <= _SAME_TIME:
            self.duplicates += 1
            return False
        if sample.t > newest:
            times.append(sample.t)
            values.append(sample.value)
        else:
            index = bisect.bisect_left(times, sample.t)
            if (index < len(times) and abs(times[index] - sample.t) <= _SAME_TIME) or (
                index > 0 and abs(times[index - 1] - sample.t) <= _SAME_TIME
            ):
                self.duplicates += 1
                return False
            self.out_of_order += 1
            if index == 0:
                return False  # older than anything held: too late to matter
            times.insert(index, sample.t)
            values.insert(index, sample.value)
        if len(times) > self.history:
            del times[0]
            del values[0]
        return True

    def _complete(self, t: float) -> bool:
        if self.wait_for is not None:
            channels: Iterable[str] = self.wait_for
        elif len(self._times) > len(self.expected):
            channels = self._times.keys()
        else:
            channels = {*self._times, *self.expected}
        for channel in channels:
            if channel == self.trigger:
                continue
            times = self._times.get(channel)
            if not times:
                if self._first_t is not None and t - self._first_t > self.stale_timeout:
                    continue  # never seen in a while: the rig does not send it
                return False
            newest = times[-1]
            if newest >= t - _SAME_TIME:
                continue
            if newest >= self._last_frame_t - _SAME_TIME and t - newest <= self.stale_timeout:
                return False  # it kept pace so far: its sample for t is on the way
        return True

    def _emit(self) -> Frame:
        pending = self._pending
        assert pending is not None
        self._pending = None
        self._last_frame_t = pending.t
        t = pending.t
        values: dict[str, float] = {self.trigger: pending.value}
        ages: dict[str, float] = {self.trigger: 0.0}
        stale: list[str] = []
        for channel, times in self._times.items():
            if channel == self.trigger:
                continue
            index = bisect.bisect_right(times, t + _SAME_TIME) - 1
            if index < 0:
                index = 0  # only newer data: the nearest one after t
            age = t - times[index]
            if abs(age) > self.stale_timeout:
                stale.append(channel)
                continue
            values[channel] = self._values[channel][index]
            ages[channel] = age
        return Frame(t=t, log_time_ns=pending.log_time_ns, values=values, ages=ages,
                     stale=tuple(stale))
