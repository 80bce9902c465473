"""What a connection in slips says of the hook-load measurement: the empty block's readings,
split by the block's motion.

In slips the hook carries the travelling equipment alone, so a still block reads ``B + o``
(block weight as the sensor weighs it, zero offset) and a moving one ``f(motion, e) B + o``:
a deadline sensor reads the empty block low while hoisting and high while lowering
(:mod:`tdmon.calib.measurement`). A :class:`SlipsRun` gathers one connection's steady in-slips
readings by the block's motion (from the block position's own samples); :func:`close_run` gives
the joint estimate one reading per motion seen often enough (:func:`tdmon.calib.joint.
slips_measurement`). Without a block position every reading counts as the block still.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

from tdmon.calib.rigstate import RigSample

__all__ = ["MIN_SLIPS_SAMPLES", "SlipsReading", "SlipsRun", "add_slips_sample", "close_run"]

#: Readings of one motion a connection needs before it is offered [-].
MIN_SLIPS_SAMPLES: Final = 3

#: Block speeds below this count as still [m/s].
_STILL_SPEED: Final = 0.05


@dataclass(frozen=True)
class SlipsReading:
    """One motion's readings of a connection: mean [N], standard error [N], how many, and the
    block's motion (+1 hoisting, -1 lowering, 0 still)."""

    motion: int
    mean: float
    se: float
    n: int


@dataclass(frozen=True)
class SlipsRun:
    """A connection's steady in-slips readings so far, per motion (sums of the reading and its
    square, counts), and the block position last sampled.

    Attributes
    ----------
    sums : per motion -1, 0, +1: (count, sum [N], sum of squares [N^2])
    block, block_time : the block position [m] and when it was sampled [s] (None: not yet)
    motion : the block's motion between its last two samples (None: not known yet)
    t : time of the last sample [s]
    """

    sums: tuple[tuple[int, float, float], ...] = ((0, 0.0, 0.0),) * 3
    block: float | None = None
    block_time: float | None = None
    motion: int | None = None
    t: float = 0.0


def add_slips_sample(run: SlipsRun, sample: RigSample, steady: bool) -> SlipsRun:
    """Add one in-slips sample (its reading counts only when ``steady``: no jump, no start
    or stop of the block). The block's motion comes from the block position's own samples
    (a frame repeating the last one keeps the motion); without a block position the block
    counts as still."""
    position = sample.block_position
    block, block_time, motion = run.block, run.block_time, run.motion
    if position is None or not math.isfinite(position):
        motion = 0
    else:
        time = sample.t if sample.block_time is None else sample.block_time
        if block is not None and block_time is not None and time > block_time:
            speed = (position - block) / (time - block_time)
            motion = 0 if abs(speed) < _STILL_SPEED else (1 if speed > 0 else -1)
        if block_time is None or time > block_time:
            block, block_time = position, time
    sums = run.sums
    reading = sample.hookload
    if steady and motion is not None and reading is not None and math.isfinite(reading):
        k = motion + 1
        count, total, squares = sums[k]
        sums = (*sums[:k], (count + 1, total + reading, squares + reading * reading),
                *sums[k + 1:])
    return SlipsRun(sums, block, block_time, motion, sample.t)


def close_run(run: SlipsRun, noise_floor: float) -> tuple[SlipsReading, ...]:
    """The connection's readings, one per motion with at least :data:`MIN_SLIPS_SAMPLES`;
    the standard error is the readings' spread over the square root of their count, at least
    ``noise_floor`` [N] over it (a sensor's resolution)."""
    out = []
    for k, (count, total, squares) in enumerate(run.sums):
        if count < MIN_SLIPS_SAMPLES:
            continue
        mean = total / count
        variance = max(squares / count - mean * mean, 0.0) * count / (count - 1)
        se = math.sqrt(max(variance, noise_floor**2) / count)
        out.append(SlipsReading(k - 1, mean, se, count))
    return tuple(out)
