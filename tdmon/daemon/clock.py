"""The rig's clock, watched against the receive time: future stamps and clock jumps.

Every sample carries the rig's time ``t``; every message carries the time it reached tdmon
(``receive_time``: the daemon's clock live, the recorded one in a replay). Their difference,
the *offset*, is the rig clock's lead over the receive clock minus the transport latency. A
sample cannot be received before it was measured, so with the rig clock where it was an offset
never rises above its usual value by more than clock jitter; latency only lowers it (a broker
backlog delivered after an outage has offsets of minus the outage, and that is not a fault).

:class:`ClockGuard` keeps the rig clock's usual offset (the *anchor*, 0 at start: both clocks
on UTC) and

* rejects a sample whose offset lies more than ``future_tolerance`` above the anchor: one
  sample stamped in the future would otherwise open a hook-load frame there and hold every
  later frame back until the rig's time caught up (docs/daemon.md, "Clock faults");
* accepts such samples as the rig's new clock once ``jump_samples`` of them came in a row, from
  at least two channels (when the rig sends two or more), with offsets within ``jump_spread``
  of each other: that is the rig clock going forward (or a rig whose clock runs ahead of UTC
  from the start), reported once as a :class:`ClockJump`.

A rig clock going back is seen by the aligner instead (:class:`tdmon.daemon.aligner.Aligner`:
hook loads older than its last frame), which reports the same :class:`ClockJump`; the
pipeline then moves the anchor here with :meth:`ClockGuard.reanchor`.

:class:`JumpLog` words the log lines of the jumps: the first at once, then at most one per
interval of receive time, counting the jumps it stands for, so that a clock running fast (a
session played faster than real time into a daemon that has seen the present) is a few lines
with the real figures, not a warning per jump (136 in 25 s before).

Pure apart from its own state; no I/O, no wall clock.
"""

from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass

from tdmon.ingest.types import Sample

__all__ = ["ClockGuard", "ClockJump", "ClockSettings", "JumpLog"]


@dataclass(frozen=True, slots=True)
class ClockSettings:
    """How the rig clock is checked (the ``[align]`` keys of the daemon file).

    Attributes
    ----------
    future_tolerance : how far a sample's offset may lie above the rig clock's usual offset
        before it is rejected [s]
    jump_samples : samples in a row, all consistently off, that make a clock jump [-]
    jump_spread : how close the offsets of those samples must be to each other [s]
    """

    future_tolerance: float = 10.0
    jump_samples: int = 5
    jump_spread: float = 5.0

    def __post_init__(self) -> None:
        if not self.future_tolerance > 0 or not self.jump_spread > 0:
            raise ValueError("future_tolerance and jump_spread must be positive")
        if self.jump_samples < 2:
            raise ValueError("jump_samples must be at least 2")


@dataclass(frozen=True, slots=True)
class ClockJump:
    """A confirmed jump of the rig clock.

    Attributes
    ----------
    seconds : how far it moved [s]: positive forward, negative back
    t : rig time of the sample that confirmed it [Unix s]
    receive_time : receive time of that sample [Unix s]
    offset : the rig clock's offset against the receive time after the jump [s]
    """

    seconds: float
    t: float
    receive_time: float
    offset: float

    @property
    def message(self) -> str:
        """The alarm text, e.g. ``"rig clock went back 3600 s; aligner re-anchored"``."""
        if self.seconds < 0:
            return f"rig clock went back {-self.seconds:.0f} s; aligner re-anchored"
        return (f"rig clock went forward {self.seconds:.0f} s; samples accepted on the new "
                f"clock")


class ClockGuard:
    """Reject future-stamped samples, confirm forward clock jumps (see the module docstring)."""

    def __init__(self, settings: ClockSettings | None = None) -> None:
        self.settings = settings or ClockSettings()
        self.offset = 0.0
        # whether ``offset`` was measured (a jump, a re-anchoring) rather than assumed (0)
        self._anchored = False
        self.jumps = 0
        self.rejected = 0
        self._channels: set[str] = set()
        self._last_offset: float | None = None  # of the last sample accepted
        # the run of samples ahead of the anchor: (offset, channel)
        self._ahead: deque[tuple[float, str]] = deque(maxlen=self.settings.jump_samples)

    def check(self, sample: Sample) -> ClockJump | str | None:
        """None: accept ``sample``; a ClockJump: accept it, the clock moved forward; a string:
        reject it for that reason."""
        offset = sample.t - sample.receive_time
        ahead = offset - self.offset
        settings = self.settings
        channels = self._channels
        if sample.channel not in channels:
            channels.add(sample.channel)
        if ahead <= settings.future_tolerance:
            self._last_offset = offset
            if self._ahead:
                self._ahead.clear()
            return None
        run = self._ahead
        run.append((offset, sample.channel))
        if len(run) == run.maxlen:
            offsets = [o for o, _ in run]
            distinct = len({c for _, c in run})
            if (max(offsets) - min(offsets) <= settings.jump_spread
                    and distinct >= min(2, len(channels))):
                new = statistics.median(offsets)
                # measured from the rig clock's usual offset once it was measured: a sample
                # accepted within the tolerance above it is no measure of the old clock (a
                # clock running fast moves the anchor ~11 s per jump while its last accepted
                # sample was already ~10 s ahead); before that, from the last sample on the
                # old clock (its latency included, so that a constant latency cancels out)
                before = (self.offset if self._anchored or self._last_offset is None
                          else self._last_offset)
                jump = ClockJump(new - before, sample.t, sample.receive_time, new)
                self._last_offset = new
                self.reanchor(new)
                self.jumps += 1
                return jump
        self.rejected += 1
        where = ("the receive time" if self.offset == 0.0
                 else f"the rig clock ({self.offset:+.0f} s from the receive time)")
        return (f"t in the future ({_seconds(ahead)} s ahead of {where}; future tolerance "
                f"{settings.future_tolerance:g} s)")

    def reanchor(self, offset: float) -> None:
        """Take ``offset`` [s] as the rig clock's usual offset from now on."""
        self.offset = offset
        self._anchored = True
        self._ahead.clear()


class JumpLog:
    """The log lines of clock jumps, at most one per ``interval`` [s] of receive time.

    The first jump is a line at once; the next ones within ``interval`` of the last line are
    held, and the first jump after it is a line that also counts the jumps held since the last
    line and their sum (the alarms are not limited: one per jump). Receive times, not the wall
    clock, keep it pure and a replay's lines those of the live run.
    """

    def __init__(self, interval: float = 10.0) -> None:
        self.interval = interval
        self._last_line: float | None = None  # receive time of the last line
        self._held: list[float] = []  # seconds of the jumps since the last line

    def line(self, jump: ClockJump) -> str | None:
        """The log line for ``jump``, or None while it is held."""
        if self._last_line is not None and jump.receive_time < self._last_line + self.interval:
            self._held.append(jump.seconds)
            return None
        text = (f"{jump.message} (rig time {jump.t:.3f}, receive time "
                f"{jump.receive_time:.3f})")
        if self._held:
            held = [*self._held, jump.seconds]
            assert self._last_line is not None
            text += (f"; {len(held)} clock jumps in the last "
                     f"{_seconds(jump.receive_time - self._last_line)} s, "
                     f"{sum(held):+.0f} s in all")
            if all(seconds > 0 for seconds in held):
                text += (": a rig clock running fast (or a session played faster than real "
                         "time after the daemon took an earlier time as the rig's clock)")
        self._held = []
        self._last_line = jump.receive_time
        return text


def _seconds(value: float) -> str:
    """Seconds for a message: tenths below 100 s, whole seconds above."""
    return f"{value:.1f}" if abs(value) < 100 else f"{value:.0f}"
