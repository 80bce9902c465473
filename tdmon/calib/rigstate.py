"""Rig-state detection from surface channels, one sample at a time.

The state of a sample comes from (docs/back-calculation.md, "Rig state"): hook load against
the block weight (in slips when the string hangs in the slips and the hook carries only the
travelling equipment), the axial velocity of the string (from the block position when the rig
sends it, otherwise from the bit depth), rotation, flow or standpipe pressure, and bit depth
against hole depth. A sample is *steady* when its state has lasted a settling time, the string
does not accelerate and the hook load did not jump since the previous sample: this keeps
break-over peaks at the start of a pull, accelerations and the last sample before the slips out
of every estimate. A string hanging off bottom without axial motion (static, circulating,
rotating off bottom) must moreover have held its hook load within a tolerance of the hang's
mean for the settling time, so that a hang being set in the slips (a fall of a few per cent per
sample, each step within the sample-to-sample limit) is never taken as a static hang.

Pure functions on a frozen :class:`DetectorState`; :func:`detect_series` runs them over arrays.
State names are those of the daemon's ``state`` message (docs/architecture.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.vocabulary import MOVING_STATES, RigState

__all__ = [
    "HANGING_STATES",
    "MOVING_STATES",
    "STATES",
    "Detection",
    "DetectorState",
    "RigSample",
    "RigStateThresholds",
    "classify",
    "detect",
    "detect_series",
]

STATES: tuple[RigState, ...] = tuple(RigState)
"""Rig states, as in the ``state`` message of docs/architecture.md."""

_RPM = 2.0 * math.pi / 60.0  # rad/s per rev/min


@dataclass(frozen=True)
class RigStateThresholds:
    """Thresholds of the detector, SI.

    Attributes
    ----------
    block_weight : travelling-equipment weight the hook load includes [N]
    in_slips_margin : hook load up to ``block_weight + in_slips_margin`` means in slips [N]
    moving_speed : axial speed above which the string moves [m/s]
    rotating_speed : surface rotation above which the string rotates [rad/s]
        (Volve reports a 0.23 rev/min offset on a still string)
    circulating_flow : flow in above which mud circulates [m3/s]
    circulating_pressure : standpipe pressure above which mud circulates, used without flow [Pa]
    on_bottom : bit within this of the hole depth is on bottom [m]
    settle_time : a state must have lasted this long before its samples are steady [s]
    max_acceleration : steady samples accelerate less than this [m/s2]
    max_hookload_step : steady samples differ from the previous one by less than
        ``max(max_hookload_step, max_hookload_step_fraction * hook load)`` [N]
    max_hookload_step_fraction : see above [-]
    max_gap : a longer gap between samples restarts the state (no steady sample across it) [s]
    max_speed : a block or bit-depth velocity above this is a glitch (depth reset, spike) and
        is not used [m/s]
    velocity_disagreement : block and bit-depth velocities further apart than this disagree;
        the one closer to the previous velocity is used [m/s]
    drilling_wob : with a weight-on-bit channel, rotating on bottom needs more than this [N]
    on_bottom_with_wob : with weight on bit, the bit counts as on bottom this far off the
        reported hole depth (hole-depth channels are coarse) [m]
    settle_samples : a state must also have lasted this many samples (this one included)
        before its samples are steady [-]
    hang_tolerance : in a hanging state (:data:`HANGING_STATES`: the string hangs off bottom
        without axial motion) a sample is steady only when every hook load since the hang
        began, this one included, lay within ``max(hang_tolerance, hang_tolerance_fraction *
        hook load)`` of the mean of the hang's earlier samples, for ``settle_time`` and
        ``settle_samples``; a sample further off starts the hang again from itself [N]
    hang_tolerance_fraction : see above [-] (4 %: twice the 2 % noise of the noisy synthetic
        replays; the first sample of a hang being set in the slips on the Volve F-4 trip out,
        1408 -> 1346 kN, lies 4.4 % below the hang's mean)
    """

    block_weight: float = 0.0
    in_slips_margin: float = 150e3
    moving_speed: float = 0.05
    rotating_speed: float = 5.0 * _RPM
    circulating_flow: float = 100.0 / 60_000.0
    circulating_pressure: float = 10e5
    on_bottom: float = 0.5
    settle_time: float = 5.0
    max_acceleration: float = 0.05
    max_hookload_step: float = 20e3
    max_hookload_step_fraction: float = 0.05
    max_gap: float = 60.0
    max_speed: float = 2.0
    velocity_disagreement: float = 0.25
    drilling_wob: float = 10e3
    on_bottom_with_wob: float = 30.0
    settle_samples: int = 1
    hang_tolerance: float = 20e3
    hang_tolerance_fraction: float = 0.04


HANGING_STATES: frozenset[RigState] = frozenset(
    {RigState.STATIC, RigState.CIRCULATING, RigState.ROTATING_OFF_BOTTOM})
"""States in which the string hangs off bottom without axial motion: their hook load is the
static hang the weight check and the rotating windows read, so it must have settled (the
slips being set pull it down 1410 -> 1344 -> 1035 kN in three 5 s samples on Volve F-4)."""


@dataclass(frozen=True, slots=True)
class RigSample:
    """One aligned sample of the rig's channels, SI; None where a channel is missing.

    Attributes
    ----------
    t : [s]
    hookload : [N], including the travelling equipment
    bit_depth : MD of the bit [m]
    block_position : height of the block above its lowest point [m]
    rpm : surface rotation [rad/s]
    flow : flow in [m3/s]
    spp : standpipe pressure [Pa]
    hole_depth : [m]
    torque : surface torque [N m]
    wob : weight on bit [N]
    block_time, bit_time : when the block position and the bit depth were sampled [s]
        (None: at ``t``); an aligner repeats a channel's last value on frames between its
        samples, and a velocity must use the channel's own times
    """

    t: float
    hookload: float | None
    bit_depth: float | None
    block_position: float | None = None
    rpm: float | None = None
    flow: float | None = None
    spp: float | None = None
    hole_depth: float | None = None
    torque: float | None = None
    wob: float | None = None
    block_time: float | None = None
    bit_time: float | None = None


@dataclass(frozen=True, slots=True)
class DetectorState:
    """What the detector remembers between samples."""

    t: float = -math.inf
    bit_depth: float | None = None
    bit_time: float = -math.inf
    block_position: float | None = None
    block_time: float = -math.inf
    block_loaded: bool = False
    velocity: float | None = None
    hookload: float | None = None
    state: RigState = RigState.UNKNOWN
    state_since: float = -math.inf
    run: int = 0
    hang_load: float | None = None  # mean hook load of the current hang [N]
    hang_since: float = -math.inf
    hang_run: int = 0


@dataclass(frozen=True, slots=True)
class Detection:
    """Result for one sample: ``state``, ``steady``, axial ``velocity`` [m/s] (> 0 deeper)."""

    state: RigState
    steady: bool
    velocity: float | None


def _finite(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def classify(hookload: float | None, velocity: float | None, rpm: float | None,
             circulating: bool, on_bottom: bool, thresholds: RigStateThresholds) -> RigState:
    """Rig state of one sample.

    Parameters
    ----------
    hookload : [N]; None gives ``unknown``
    velocity : axial velocity of the string, > 0 going deeper [m/s]
    rpm : surface rotation [rad/s]
    circulating : mud is being pumped
    on_bottom : the bit is on bottom (see `detect`)
    thresholds : the detector's settings

    Returns
    -------
    RigState

    Notes
    -----
    In slips wins over everything: when the hook carries only the block, the string's motion
    and the bit depth say nothing about the string (the Volve trip-in log shows the bit depth
    advancing while the block moves empty, a depth-tracking artefact).
    """
    if hookload is None:
        return RigState.UNKNOWN
    if hookload < thresholds.block_weight + thresholds.in_slips_margin:
        return RigState.IN_SLIPS
    moving_down = velocity is not None and velocity > thresholds.moving_speed
    moving_up = velocity is not None and velocity < -thresholds.moving_speed
    rotating = rpm is not None and rpm > thresholds.rotating_speed
    if rotating:
        if on_bottom:
            return RigState.DRILLING
        if moving_up:
            return RigState.BACK_REAMING
        return RigState.REAMING if moving_down else RigState.ROTATING_OFF_BOTTOM
    if moving_up:
        return RigState.PICK_UP
    if moving_down:
        return RigState.SLACK_OFF
    return RigState.CIRCULATING if circulating else RigState.STATIC


def _channel_velocity(value: float | None, time: float, prior_value: float | None,
                      prior_time: float, sign: float, thresholds: RigStateThresholds
                      ) -> tuple[float | None, bool]:
    """(velocity or None, whether this is a new sample of the channel)."""
    if value is None or prior_value is None:
        return None, value is not None
    dt = time - prior_time
    if not (0.0 < dt <= thresholds.max_gap):
        return None, dt > 0.0
    velocity = sign * (value - prior_value) / dt
    return (velocity if abs(velocity) <= thresholds.max_speed else None), True


def _velocity(prior: DetectorState, sample: RigSample, loaded: bool,
              thresholds: RigStateThresholds
              ) -> tuple[float | None, float | None, float, float | None, float, bool]:
    """(velocity, then the channel memory: bit depth, its time, block position, its time,
    whether the block was loaded)."""
    # Two measures of the string's axial speed. The bit depth is what the rig reports for the
    # string, but it can jump (depth-tracking resets, Volve trip in); the block moves with the
    # string only while the hook carries it (in slips it travels empty) and its encoder can be
    # noisy. Rules: the block counts only between samples taken with the string on the hook;
    # when both agree the bit depth is used; when they disagree, the one continuing the last
    # velocity wins (a jump is a discontinuity), unless the bit depth is frozen. A frame that
    # repeats a channel's last sample keeps that channel's last velocity, except across the
    # slips.
    block, bit = _finite(sample.block_position), _finite(sample.bit_depth)
    t = sample.t
    block_time = t if sample.block_time is None else sample.block_time
    bit_time = t if sample.bit_time is None else sample.bit_time
    carry = prior.velocity if prior.state != RigState.IN_SLIPS else None
    # the channel memory is kept in locals and the new state built once by `detect` (a
    # dataclasses.replace per channel cost more than the rest of the detector)
    memory_block, memory_block_time, memory_loaded = (prior.block_position, prior.block_time,
                                                      prior.block_loaded)
    memory_bit, memory_bit_time = prior.bit_depth, prior.bit_time
    v_block: float | None = None
    if block is not None and block_time == prior.block_time and block == prior.block_position:
        v_block = carry if prior.block_loaded else None
    elif block is not None:
        if prior.block_loaded and loaded:
            v_block, _ = _channel_velocity(block, block_time, prior.block_position,
                                           prior.block_time, -1.0, thresholds)
        if block_time > prior.block_time:
            memory_block, memory_block_time, memory_loaded = block, block_time, loaded
    frozen_bit = False
    if bit is not None and bit_time == prior.bit_time and bit == prior.bit_depth:
        v_bit = carry
    else:
        # a new sample repeating the last value exactly while the block moves: a stuck
        # depth channel (a depth that follows the block never repeats while it moves)
        frozen_bit = bit is not None and bit == prior.bit_depth
        v_bit, fresh = _channel_velocity(bit, bit_time, prior.bit_depth, prior.bit_time, 1.0,
                                         thresholds)
        if fresh and bit is not None:
            memory_bit, memory_bit_time = bit, bit_time
    if v_block is None or v_bit is None:
        velocity = v_bit if v_bit is not None else v_block
    elif frozen_bit and abs(v_block) > thresholds.moving_speed:
        velocity = v_block
    elif abs(v_block - v_bit) <= thresholds.velocity_disagreement or carry is None:
        velocity = v_bit
    else:
        velocity = v_block if abs(v_block - carry) < abs(v_bit - carry) else v_bit
    return (velocity, memory_bit, memory_bit_time, memory_block, memory_block_time,
            memory_loaded)


def _hang(prior: DetectorState, same: bool, state: RigState, t: float, hookload: float | None,
          thresholds: RigStateThresholds) -> tuple[float | None, float, int]:
    """The hang's mean hook load [N], since when [s] and over how many samples it held within
    tolerance ((None, -inf, 0) outside a hanging state)."""
    if state not in HANGING_STATES or hookload is None:
        return None, -math.inf, 0
    tolerance = max(thresholds.hang_tolerance, thresholds.hang_tolerance_fraction * abs(hookload))
    mean, run = prior.hang_load, prior.hang_run
    if same and mean is not None and abs(hookload - mean) <= tolerance:
        return mean + (hookload - mean) / (run + 1), prior.hang_since, run + 1
    return hookload, t, 1


def detect(prior: DetectorState, sample: RigSample, thresholds: RigStateThresholds
           ) -> tuple[DetectorState, Detection]:
    """Classify one sample and say whether it is steady.

    Parameters
    ----------
    prior : the state after the previous sample (``DetectorState()`` at the start)
    sample : this sample
    thresholds : settings

    Returns
    -------
    (DetectorState, Detection)
    """
    hookload = _finite(sample.hookload)
    t = sample.t
    if not math.isfinite(t):
        return replace(prior, state=RigState.UNKNOWN), Detection(RigState.UNKNOWN, False, None)
    dt = t - prior.t
    fresh = not (math.isfinite(dt) and 0.0 < dt <= thresholds.max_gap)
    loaded = hookload is not None and (
        hookload >= thresholds.block_weight + thresholds.in_slips_margin)
    velocity, bit_depth, bit_time, block_position, block_time, block_loaded = _velocity(
        prior, sample, loaded, thresholds)
    if fresh:
        velocity = None
    rpm = _finite(sample.rpm)
    flow, spp = _finite(sample.flow), _finite(sample.spp)
    circulating = ((flow is not None and flow > thresholds.circulating_flow)
                   or (flow is None and spp is not None and spp > thresholds.circulating_pressure))
    bit, hole, wob = _finite(sample.bit_depth), _finite(sample.hole_depth), _finite(sample.wob)
    off_bottom = None if bit is None or hole is None else hole - bit
    if wob is not None:
        # hole-depth channels are coarse; weight on the bit says the bit touches bottom
        on_bottom = wob > thresholds.drilling_wob and (
            off_bottom is None or off_bottom <= thresholds.on_bottom_with_wob)
    else:
        on_bottom = off_bottom is not None and off_bottom <= thresholds.on_bottom
    state = classify(hookload, velocity, rpm, circulating, on_bottom, thresholds)
    same = state == prior.state and not fresh
    since = prior.state_since if same else t
    run = prior.run + 1 if same else 1
    prior_hookload = prior.hookload
    steady = (state != RigState.UNKNOWN and not fresh and t - since >= thresholds.settle_time
              and run >= thresholds.settle_samples
              and hookload is not None and prior_hookload is not None)
    if steady and velocity is not None and prior.velocity is not None:
        steady = abs(velocity - prior.velocity) / dt <= thresholds.max_acceleration
    if steady and hookload is not None and prior_hookload is not None:
        step = max(thresholds.max_hookload_step,
                   thresholds.max_hookload_step_fraction * abs(hookload))
        steady = abs(hookload - prior_hookload) <= step
    if steady and state in MOVING_STATES and velocity is None:
        steady = False
    hang_load, hang_since, hang_run = _hang(prior, same, state, t, hookload, thresholds)
    if steady and hang_load is not None:
        steady = (t - hang_since >= thresholds.settle_time
                  and hang_run >= thresholds.settle_samples)
    # positional, in the order of the fields (once per frame: the keywords cost a third)
    new = DetectorState(t, bit_depth, bit_time, block_position, block_time, block_loaded,
                        velocity, hookload, state, since, run, hang_load, hang_since, hang_run)
    return new, Detection(state, bool(steady), velocity)


def _optional(values: ArrayLike | None, n: int) -> NDArray[np.float64]:
    if values is None:
        return np.full(n, np.nan)
    return np.asarray(values, dtype=np.float64)


def detect_series(
    t: ArrayLike,
    hookload: ArrayLike,
    bit_depth: ArrayLike,
    thresholds: RigStateThresholds,
    *,
    block_position: ArrayLike | None = None,
    rpm: ArrayLike | None = None,
    flow: ArrayLike | None = None,
    spp: ArrayLike | None = None,
    hole_depth: ArrayLike | None = None,
    wob: ArrayLike | None = None,
) -> tuple[NDArray[np.str_], NDArray[np.bool_]]:
    """Run :func:`detect` over a whole record (NaN = missing).

    Returns
    -------
    states : state name per sample
    steady : steady flag per sample
    """
    times = np.asarray(t, dtype=np.float64)
    n = times.size
    columns = [np.asarray(hookload, dtype=np.float64), np.asarray(bit_depth, dtype=np.float64),
               _optional(block_position, n), _optional(rpm, n), _optional(flow, n),
               _optional(spp, n), _optional(hole_depth, n), _optional(wob, n)]
    states = np.empty(n, dtype="<U20")
    steady = np.zeros(n, dtype=bool)
    prior = DetectorState()
    for i in range(n):
        values = [float(column[i]) for column in columns]
        v = [x if math.isfinite(x) else None for x in values]
        sample = RigSample(float(times[i]), hookload=v[0], bit_depth=v[1], block_position=v[2],
                           rpm=v[3], flow=v[4], spp=v[5], hole_depth=v[6], wob=v[7])
        prior, result = detect(prior, sample, thresholds)
        states[i] = result.state
        steady[i] = result.steady
    return states, steady
