"""Frozen channels: a reading that stays constant while its neighbours say it must move.

A sensor or its transmitter that fails often keeps sending its last value (a PLC holding the
last good reading, a WITS or OPC UA server repeating a stale tag). Constancy alone proves
nothing: a top-drive speed in speed control, a pump rate, a torque cell at its zero offset on a
still string, a bit depth on a hanging string all stay put legitimately, sometimes to the last
digit (Volve F-4 sends 0.0052 kN m of torque and 0.2312 rpm unchanged for five hours of tripping).
So a channel is *frozen* only when

1. its value has stayed within its resolution (:data:`FROZEN_RESOLUTION`) for the whole run,
   from the sample that began it, over at least ``samples`` of its own fresh samples, and
2. during that run its neighbours said, for at least ``time`` seconds in all, that it must
   move or that it reads something they contradict (the *evidence*, given per frame by the
   rig-state detector, which knows the neighbours: `tdmon.calib.rigstate`).

The evidence names the neighbour, so the alarm blames the channel that froze, not the one that
still moves: an RPM stuck at 100 rpm while the torque falls to its still-string zero offset
blames the RPM; a torque stuck while the RPM says the string turns blames the torque. A frozen
channel stays frozen until its value changes (a channel stuck at the value it will read again
once repaired cannot be told from a live one, so it keeps being distrusted until it moves).

Pure functions on tuples (once per channel and frame: no dataclass construction on the hot
path); :class:`FrozenChannel` describes a frozen channel for the alarm.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final, NamedTuple

from tdmon.vocabulary import FROZEN_ALARM_KINDS

__all__ = [
    "FROZEN_CHANNELS",
    "FROZEN_RESOLUTION",
    "ChannelRun",
    "FrozenChannel",
    "changing",
    "follow",
    "shown",
]

FROZEN_CHANNELS: Final[tuple[str, ...]] = tuple(FROZEN_ALARM_KINDS)
"""The channels checked, in a fixed order: those with a frozen-channel alarm kind
(`tdmon.vocabulary.FROZEN_ALARM_KINDS`)."""

FROZEN_RESOLUTION: Final[Mapping[str, float]] = MappingProxyType({
    "hookload": 100.0,          # N: load cells resolve 0.1 kN; a moving string varies by kN
    "torque": 10.0,             # N m
    "rpm": 0.01,                # rad/s, 0.1 rpm
    "bit_depth": 0.001,         # m
    "block_position": 0.001,    # m
    "flow_in": 1e-5,            # m3/s, 0.6 L/min
    "spp": 1e3,                 # Pa, 0.01 bar
    "wob": 100.0,               # N
})
"""Default resolution of each channel checked for freezing, SI: readings within this of the
run's first one count as unchanged. A frozen transmitter repeats its value exactly; these
leave room for a last digit that flickers, and stay far below what the channel moves by when
its neighbours say it must move (the daemon file can change them:
``[rig_state] frozen_resolution``)."""
#: how each channel is written in an alarm: factor from SI and unit
_SHOWN: Final[Mapping[str, tuple[float, str, str]]] = MappingProxyType({
    "hookload": (1e-3, "kN", ".0f"),
    "torque": (1e-3, "kN m", ".2f"),
    "rpm": (30.0 / math.pi, "rpm", ".1f"),
    "bit_depth": (1.0, "m", ".2f"),
    "block_position": (1.0, "m", ".2f"),
    "flow_in": (60_000.0, "L/min", ".0f"),
    "spp": (1e-5, "bar", ".1f"),
    "wob": (1e-3, "kN", ".0f"),
})


def shown(channel: str, value: float) -> str:
    """A channel's value in the units a driller reads (``"100.0 rpm"``, ``"0.80 kN m"``)."""
    factor, unit, spec = _SHOWN.get(channel, (1.0, "", "g"))
    return f"{value * factor:{spec}} {unit}".rstrip()


class ChannelRun(NamedTuple):
    """One channel's current run of unchanged readings.

    Attributes
    ----------
    since : when the run began (its first sample's frame) [s]
    low, high : the range of its readings [SI]
    sampled : time of its latest fresh sample [s]
    samples : fresh samples in the run [-]
    evidence : seconds of the run during which its neighbours said it must move [s]
    t : frame time of the last update [s]
    anchor : what a neighbour read when the run began, or whether it ever said something
        during the run (a latch, 0 or 1): the change the evidence is measured against [SI]
    frozen : declared frozen (until the value changes)
    reason : why, once frozen (the neighbours' words), else ``""``
    """

    since: float
    low: float
    high: float
    sampled: float
    samples: int
    evidence: float
    t: float
    anchor: float = -math.inf
    frozen: bool = False
    reason: str = ""


@dataclass(frozen=True, slots=True)
class FrozenChannel:
    """A channel declared frozen: its name, the value it repeats [SI], since when [s], and
    why (the neighbours that say it must move)."""

    channel: str
    value: float
    since: float
    reason: str


def follow(run: ChannelRun | None, t: float, value: float, sampled: float, resolution: float,
           evidence: bool, anchor: float, latch: bool, time: float, samples: int,
           max_step: float) -> ChannelRun:
    """One frame of a channel's run.

    Parameters
    ----------
    run : the run so far (None: the channel's first reading)
    t : frame time [s]
    value : the channel's reading on this frame [SI]
    sampled : when the channel took it [s] (a frame repeating an older sample is not fresh)
    resolution : readings within this of the run's range keep the run [SI]
    evidence : the neighbours say, on this frame, that the channel must move
    anchor : the neighbour's reading kept for a new run (or, with ``latch``, 1 when the
        neighbour says something now: the run keeps the largest)
    latch : see ``anchor``
    time : evidence needed [s]
    samples : fresh samples needed [-]
    max_step : at most this much evidence per frame [s] (a gap in the data is not evidence)

    Returns
    -------
    ChannelRun; ``frozen`` set when both counts are reached (``reason`` is left to the caller,
    which knows the neighbours)
    """
    if run is None or not (run.high - resolution <= value <= run.low + resolution):
        return ChannelRun(t, value, value, sampled, 1, 0.0, t, anchor)
    # once per channel and frame: the fields unpacked once rather than read one by one
    since, low, high, last_sampled, count, gained, last_t, kept, frozen, reason = run
    if value < low:
        low = value
    elif value > high:
        high = value
    if sampled > last_sampled:
        count += 1
        last_sampled = sampled
    if evidence and t > last_t:
        gained += min(t - last_t, max_step)
    frozen = frozen or (gained >= time and count >= samples)
    if latch and anchor > kept:
        kept = anchor
    return ChannelRun(since, low, high, last_sampled, count, gained, t, kept, frozen, reason)


def changing(run: ChannelRun | None) -> bool:
    """The channel changed at its latest sample or the one before (its run holds at most two
    samples), so it can testify against a neighbour: a live sensor's noise moves it, whatever
    its sampling interval; one repeating its value cannot blame another."""
    return run is not None and run.samples <= 2 and not run.frozen
