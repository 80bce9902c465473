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

Pure apart from its own state; no I/O, no wall clock.
"""

from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass

from tdmon.ingest.types import Sample

__all__ = ["ClockGuard", "ClockJump", "ClockSettings"]


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
                # measured from the last sample on the old clock (its latency included, so
                # that a constant latency cancels out)
                before = self.offset if self._last_offset is None else self._last_offset
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
        self._ahead.clear()


def _seconds(value: float) -> str:
    """Seconds for a message: tenths below 100 s, whole seconds above."""
    return f"{value:.1f}" if abs(value) < 100 else f"{value:.0f}"
