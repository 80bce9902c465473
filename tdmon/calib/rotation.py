"""Whether the string turns, from the surface torque: its still-string zero offset and a margin.

A surface RPM reading alone is not evidence of rotation: a frozen RPM channel keeps reporting
the last speed after the string stops, and the hangs, pulls and runs that follow are then taken
for rotation off bottom, back-reaming and reaming, whose torque gives a friction near zero. A
string that turns off bottom carries a torque above the torque sensor's zero offset (what it
reads on a still string); so rotation needs that torque as well, whenever a torque channel is
there (docs/back-calculation.md, "Rig state").

* The zero offset is learnt from the torque while the string is known to be still: in slips,
  or with the RPM (a channel not judged frozen) below the rotating speed. It is the median of
  the last :data:`STILL_SAMPLES` such samples (a make-up spike in slips moves a median little)
  and their spread the scaled median absolute deviation.
* The torque *level* is the mean of the torque's own samples in the last ``average`` seconds
  (at 1 s sampling five samples, at 15 s the latest one), so a torque a few noise deviations
  above the offset is told from it within seconds.
* The string turns by its torque when the level exceeds the offset by
  ``max(floor, sigmas * spread / sqrt(n))`` (n: samples in the level); once turning, half that
  keeps it turning (hysteresis: a level near the margin does not flicker the state). Before any
  still sample has been seen the offset is unknown: then the level must exceed
  ``max(floor, fraction * peak)``, ``peak`` the highest level since the string was last known
  still, so a string that stops turning (the level falls to a fifth of its rotating level)
  stops being called rotating even when the recording began mid-rotation.

A rotation whose torque cannot be told from the still string's (a shallow near-vertical hole:
67 N m of friction torque under 100 N m of sensor noise) is not called rotating: its torque
carries no friction, and its hangs and moves are left out of the windows while the RPM says
otherwise (`tdmon.calib.rigstate`).

Pure functions on a small named tuple (updated once per frame).
"""

from __future__ import annotations

import math
from itertools import repeat
from operator import sub
from typing import Final, NamedTuple

__all__ = ["STILL_SAMPLES", "TorqueZero", "torque_turning"]

#: still-string torque samples the zero offset is the median of [-]
STILL_SAMPLES: Final = 60
#: most torque samples the level averages, whatever the window's length [-]: 5 s at 50 Hz,
#: far above what a rig's torque channel sends; a faster feed (or a backlog of samples
#: microseconds apart) averages its latest ones instead of making each frame's cost grow
#: with the window
RECENT_SAMPLES: Final = 256


class TorqueZero(NamedTuple):
    """What the torque evidence remembers.

    Attributes
    ----------
    still : the last still-string torque samples [N m]
    offset : their median, the sensor's zero offset [N m] (None: no still sample yet)
    spread : their scaled median absolute deviation [N m]
    recent : the torque's own samples of the last ``average`` seconds, at most
        :data:`RECENT_SAMPLES` of them, (time [s], value [N m])
    peak : highest level since the string was last known still [N m]
    turning : the torque said the string turns on the previous frame
    """

    still: tuple[float, ...] = ()
    offset: float | None = None
    spread: float = 0.0
    recent: tuple[tuple[float, float], ...] = ()
    peak: float = 0.0
    turning: bool = False


def _middle(ordered: list[float]) -> float:
    """The median of sorted values (as `statistics.median`: the mean of the two middle ones
    for an even count)."""
    n = len(ordered)
    half = n // 2
    return ordered[half] if n % 2 else (ordered[half - 1] + ordered[half]) / 2


def _learn(zero: TorqueZero, torque: float) -> tuple[tuple[float, ...], float, float]:
    """The still samples with ``torque`` added (the oldest dropped past
    :data:`STILL_SAMPLES`), their median and scaled median absolute deviation."""
    still = zero.still
    kept = (*still[-(STILL_SAMPLES - 1):], torque)
    if (len(still) == STILL_SAMPLES and zero.offset is not None and still[0] == torque
            and math.copysign(1.0, still[0]) == math.copysign(1.0, torque)):
        # the sample dropped is the one added (a still string's torque often repeats one
        # reading for hours): the same values, the same median and spread
        return kept, zero.offset, zero.spread
    middle = _middle(sorted(kept))
    spread = 1.4826 * _middle(sorted(map(abs, map(sub, kept, repeat(middle)))))
    return kept, middle, spread


def torque_turning(zero: TorqueZero, torque: float, sampled: float, known_still: bool,
                   average: float, floor: float, sigmas: float, fraction: float
                   ) -> TorqueZero:
    """One frame of the torque evidence.

    Parameters
    ----------
    zero : the memory so far
    torque : surface torque on this frame [N m]
    sampled : when the torque channel took it [s] (an older sample repeated by the aligner
        is not counted again)
    known_still : the string is known to be still (in slips, or a trusted RPM below the
        rotating speed)
    average : the level is the mean of the samples of the last this many seconds [s]
    floor : smallest margin above the offset [N m]
    sigmas : margin in standard deviations of the level's noise [-]
    fraction : without an offset, the level must exceed this share of the peak [-]

    Returns
    -------
    TorqueZero, whose ``turning`` says whether the torque shows rotation on this frame
    """
    still, offset, spread = zero.still, zero.offset, zero.spread
    recent = zero.recent
    if not recent or sampled > recent[-1][0]:
        start = sampled - average
        kept = recent[-(RECENT_SAMPLES - 1):]
        recent = (*(item for item in kept if item[0] > start), (sampled, torque))
        if known_still:
            still, offset, spread = _learn(zero, torque)
    n = len(recent)
    try:
        level = math.fsum(value for _, value in recent) / n
    except OverflowError:  # torques near the float limit (garbage): their sum is infinite
        level = math.copysign(math.inf, sum(value for _, value in recent))
    peak = 0.0 if known_still else max(zero.peak, level)
    if offset is not None:
        margin = max(floor, sigmas * spread / math.sqrt(n))
        turning = level > offset + (0.5 * margin if zero.turning else margin)
    else:
        turning = not known_still and level > max(floor, fraction * peak)
    return TorqueZero(still, offset, spread, recent, peak, turning)
