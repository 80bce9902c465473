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

Except when the rig clock went back: ``jump_samples`` hook loads in a row older than the last
frame, in increasing time (the rig clock still runs), whose offsets against their receive time
agree within ``jump_spread`` and lie more than ``jump_min`` below the offset of the last
frame's hook load, are a clock jump, not late data.
The aligner then emits its pending frame, forgets the old timeline and takes up the new one
with the samples that came since the jump (kept for this, at most ``_MAX_LATE``), so results
resume at once; the jump is reported through :meth:`Aligner.take_jumps` (docs/daemon.md,
"Clock faults"). A single hook load stamped ahead that slipped through the future tolerance
holds frames back for at most that tolerance, which is why ``jump_min`` is the same value.
"""

from __future__ import annotations

import bisect
import statistics
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from tdmon.daemon.clock import ClockJump
from tdmon.daemon.pipeline import Frame
from tdmon.ingest.types import Sample

#: Times closer than this are the same instant (rigs stamp with ms resolution at best).
_SAME_TIME = 1e-6

#: Samples kept from the new timeline while a clock jump back is being confirmed (bounded: a
#: flood of late samples must not grow memory).
_MAX_LATE = 1024

# what _store did with a sample
_DUPLICATE, _STORED, _TOO_OLD = 0, 1, 2

_NO_JUMPS: tuple[ClockJump, ...] = ()


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
        jump_samples: int = 5,
        jump_spread: float = 5.0,
        jump_min: float = 10.0,
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
        self.jump_samples = jump_samples
        self.jump_spread = jump_spread
        self.jump_min = jump_min
        # offset (t - receive time) of the hook load that opened the newest frame
        self._frame_offset: float | None = None
        # hook loads in a row that could not open a frame, in increasing time: (t, offset)
        self._refused: deque[tuple[float, float]] = deque(maxlen=jump_samples)
        # samples that may belong to a new timeline: out of order, or any since a hook load
        # was refused; cleared whenever a hook load opens a frame
        self._late: deque[Sample] = deque(maxlen=_MAX_LATE)
        self._jumps: list[ClockJump] = []
        # monotonic arrival of each channel's latest sample, and a silence of the stream
        # already reported while it lasted (see silence())
        self._arrived: dict[str, float] = {}
        self._reported: tuple[tuple[str, float], ...] = ()
        # the channels _complete looks at, kept until a channel is first seen (or forgotten):
        # worked out on every sample, the set of them cost more than the rest of the check
        self._waited: tuple[str, ...] | None = None
        # the channel the pending frame waits for, when _complete found one: until it sends
        # or a new channel is seen, the frame stays incomplete (the verdict on that channel
        # depends only on its samples, the frame's time, the last frame's and the first
        # sample's), so other channels' samples need no look (6 of a frame's 8 samples on the
        # synthetic session: 0.97 -> 0.83 us a sample)
        self._held_by: str | None = None

    def push(self, sample: Sample, now: float) -> list[Frame]:  # noqa: C901  (complex today; simplify when next touched)
        """Take one sample (``now`` is monotonic seconds); return the frames it completes."""
        channel, t = sample.channel, sample.t
        times = self._times.get(channel)
        if times is not None and t - times[-1] > _SAME_TIME:
            # what _store does with the usual sample, newer than its channel's newest, without
            # the call (once per sample; with the sample's channel and time read once: 0.85 ->
            # 0.74 us a sample)
            values = self._values[channel]
            times.append(t)
            values.append(sample.value)
            if len(times) > self.history:
                del times[0]
                del values[0]
            stored = _STORED
        else:
            stored = self._store(sample)
            if stored == _DUPLICATE:
                return []
        self._arrived[channel] = now
        frames: list[Frame] = []
        if channel == self.trigger:
            pending = self._pending
            if t > self._last_frame_t + _SAME_TIME and (
                    pending is None or t > pending.t + _SAME_TIME):
                if pending is not None:
                    frames.append(self._emit())
                self._pending = _Pending(t, sample.value, now, int(sample.receive_time * 1e9))
                self._frame_offset = t - sample.receive_time
                if self._refused:
                    self._refused.clear()
                if self._late:
                    self._late.clear()
            else:
                # an out-of-order hook load is kept in the history only, unless it confirms
                # that the rig clock went back
                self._late.append(sample)
                jump = self._refused_hookload(sample)
                if jump is not None:
                    return self._reanchor(jump, now)
        elif stored == _TOO_OLD or self._refused:
            self._late.append(sample)
        if stored == _TOO_OLD:
            return frames
        pending = self._pending
        if pending is None:
            return frames
        held_by = self._held_by
        if (held_by is None or held_by == channel) and self._complete(pending.t):
            frames.append(self._emit())
        return frames

    def take_jumps(self) -> Sequence[ClockJump]:
        """The clock jumps back seen since the last call (the pipeline raises one alarm each)."""
        if not self._jumps:
            return _NO_JUMPS
        jumps, self._jumps = self._jumps, []
        return jumps

    def _refused_hookload(self, sample: Sample) -> ClockJump | None:
        refused = self._refused
        if refused and sample.t <= refused[-1][0]:
            refused.clear()  # a clock that went back still runs forward: a new run
        refused.append((sample.t, sample.t - sample.receive_time))
        if len(refused) < self.jump_samples or self._frame_offset is None:
            return None
        offsets = [offset for _, offset in refused]
        if max(offsets) - min(offsets) > self.jump_spread:
            return None  # late data of many ages, not one clock
        new = statistics.median(offsets)
        back = self._frame_offset - new
        if back <= self.jump_min:
            return None  # a short hold-up, over within the future tolerance anyway
        return ClockJump(-back, sample.t, sample.receive_time, new)

    def _reanchor(self, jump: ClockJump, now: float) -> list[Frame]:
        """Emit the old timeline's pending frame, forget it, and replay the new one."""
        frames = self.flush()
        late = list(self._late)
        self._times.clear()
        self._values.clear()
        self._waited = None
        self._pending = None
        self._held_by = None
        self._last_frame_t = float("-inf")
        self._first_t = None
        self._frame_offset = None
        self._refused.clear()
        self._late.clear()
        self._reported = ()
        self._jumps.append(jump)
        # these samples were counted when they arrived; replaying them is not new disorder
        counts = self.duplicates, self.out_of_order
        for sample in late:
            frames.extend(self.push(sample, now))
        self.duplicates, self.out_of_order = counts
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

    def _store(self, sample: Sample) -> int:
        if self._first_t is None:
            self._first_t = sample.t
        times = self._times.get(sample.channel)
        if times is None:
            self._times[sample.channel] = [sample.t]
            self._values[sample.channel] = [sample.value]
            # a new channel changes the channels waited for (and may drop the one holding
            # the pending frame back: an expected channel never seen)
            self._waited = self._held_by = None
            return _STORED
        values = self._values[sample.channel]
        newest = times[-1]
        if abs(sample.t - newest) <= _SAME_TIME:
            self.duplicates += 1
            return _DUPLICATE
        if sample.t > newest:
            times.append(sample.t)
            values.append(sample.value)
        else:
            index = bisect.bisect_left(times, sample.t)
            if (index < len(times) and abs(times[index] - sample.t) <= _SAME_TIME) or (
                index > 0 and abs(times[index - 1] - sample.t) <= _SAME_TIME
            ):
                self.duplicates += 1
                return _DUPLICATE
            self.out_of_order += 1
            if index == 0:
                return _TOO_OLD  # older than anything held: too late to matter
            times.insert(index, sample.t)
            values.insert(index, sample.value)
        if len(times) > self.history:
            del times[0]
            del values[0]
        return _STORED

    def _complete(self, t: float) -> bool:
        waited = self._waited
        if waited is None:
            waited = self._waited = self._waited_channels()
        due = t - _SAME_TIME
        kept_pace = self._last_frame_t - _SAME_TIME
        for channel in waited:
            times = self._times.get(channel)
            if times:
                newest = times[-1]
                if newest >= due or not (newest >= kept_pace
                                         and t - newest <= self.stale_timeout):
                    continue  # here, or it lags and is used with its age
                # it kept pace so far: its sample for t is on the way
            elif self._first_t is not None and t - self._first_t > self.stale_timeout:
                continue  # never seen in a while: the rig does not send it
            if channel != waited[0]:
                # looked at first from now on: a rig sends its channels in much the same
                # order every time, and the one that held this frame back will hold the next
                # ones back as well (the verdict does not depend on the order)
                self._waited = (channel, *(c for c in waited if c != channel))
            self._held_by = channel
            return False
        return True

    def _waited_channels(self) -> tuple[str, ...]:
        """The channels a frame may wait for: ``wait_for``, else those seen and expected."""
        channels: Iterable[str]
        if self.wait_for is not None:
            channels = self.wait_for
        elif len(self._times) > len(self.expected):
            channels = self._times.keys()
        else:
            channels = {*self._times, *self.expected}
        return tuple(channel for channel in channels if channel != self.trigger)

    def _emit(self) -> Frame:
        pending = self._pending
        assert pending is not None
        self._pending = None
        self._held_by = None
        previous = self._last_frame_t
        self._last_frame_t = pending.t
        t = pending.t
        values: dict[str, float] = {self.trigger: pending.value}
        ages: dict[str, float] = {self.trigger: 0.0}
        stale: list[str] = []
        # once per frame and channel: the loop's constants in locals
        trigger, timeout, held = self.trigger, self.stale_timeout, self._values
        until = t + _SAME_TIME
        for channel, times in self._times.items():
            if channel == trigger:
                continue
            # the usual case, nothing newer than t held: the newest sample, without a search
            index = (len(times) - 1 if times[-1] <= until
                     else bisect.bisect_right(times, until) - 1)
            if index < 0:
                index = 0  # only newer data: the nearest one after t
            age = t - times[index]
            if abs(age) > timeout:
                stale.append(channel)
                continue
            values[channel] = held[channel][index]
            ages[channel] = age
        reported, self._reported = self._reported, ()
        # positional, in the order of Frame's fields (once per frame: 0.45 -> 0.24 us)
        return Frame(t, pending.log_time_ns, values, ages, tuple(stale),
                     reported or self._gap(previous, t), bool(reported))

    def silence(self, now: float) -> tuple[tuple[str, float], ...]:
        """Live: the channels gone stale in a silence of the hook load still under way, and when
        each did [s of rig time]; () when there is none or it was already returned.

        Called by the daemon's housekeeping (``now`` monotonic seconds): when no hook load has
        arrived for ``stale_timeout`` of wall time, the channels that were fresh at the last
        frame and have sent nothing for as long are returned once, so that the alarm comes
        while the data are missing; the first frame after the silence then carries them with
        ``gap_reported`` set.
        """
        timeout = self.stale_timeout
        arrived = self._arrived.get(self.trigger)
        last = self._last_frame_t
        if (self._reported or self._pending is not None or last == float("-inf")
                or arrived is None or not now - arrived > timeout):
            return ()
        gone = [(self.trigger, last + timeout)]
        for channel, times in self._times.items():
            if channel == self.trigger or not times:
                continue
            if last - times[-1] > timeout:
                continue  # already stale at the last frame: reported then
            if now - self._arrived.get(channel, float("-inf")) <= timeout:
                continue  # still sending
            gone.append((channel, times[-1] + timeout))
        self._reported = tuple(gone)
        return self._reported

    def _gap(self, previous: float, t: float) -> tuple[tuple[str, float], ...]:
        """The channels that went stale in a silence of the hook load from ``previous`` (the
        last frame) to ``t``, and when each did [s]; () without such a silence.

        A channel counts when it was fresh at ``previous`` and sent nothing until it would have
        been stale: a dropout of the whole stream is one event, named when it happened, not a
        stale channel at the frame where the data resume.
        """
        timeout = self.stale_timeout
        if previous == float("-inf") or not t - previous > timeout:
            return ()  # the first frame (of the stream, or after a re-anchor), or no silence
        gone = [(self.trigger, previous + timeout)]
        for channel, times in self._times.items():
            if channel == self.trigger:
                continue
            index = bisect.bisect_right(times, previous + _SAME_TIME) - 1
            if index < 0 or previous - times[index] > timeout:
                continue  # nothing held from before, or already stale then (reported then)
            # follow its samples through the silence: stale where one is followed by none
            # for longer than the timeout
            while index + 1 < len(times) and times[index + 1] - times[index] <= timeout:
                index += 1
            stale_at = times[index] + timeout
            if stale_at < t:
                gone.append((channel, stale_at))
        return tuple(gone)
