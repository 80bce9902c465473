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

Two rules guard against sensors that lie (issue 28):

* *In slips* means the hook load lies below the block weight plus a margin that scales with the
  modelled buoyed weight of the string hanging at the bit depth (`RigSample.string_weight`):
  ``in_slips_fraction`` of it, at least ``in_slips_min_margin``, at most ``in_slips_margin``. A
  light string in a shallow well hanging on the hook is then not "in slips".
* *Rotation* needs torque evidence whenever a torque channel is there: the torque above its
  still-string zero offset by a margin (`tdmon.calib.rotation`) as well as the RPM above the
  rotating speed; the RPM decides alone only without a torque channel. A sample whose RPM says
  the string turns while a live torque says it does not is not steady (its windows would rest
  on a contradiction).

Every channel is followed for freezing (`tdmon.calib.frozen`): constant within its resolution
while its neighbours say it must move. A frozen channel is then not used (the RPM: rotation
from the torque alone; the block or the bit depth: the velocity from the other; the flow: the
standpipe pressure), the detection names it (``Detection.frozen``, for the alarm) and lists it
in ``Detection.suspect`` where the sample's state rests on it, so that its windows are not fed
to the estimates.

Pure functions on a frozen :class:`DetectorState`; :func:`detect_series` runs them over arrays.
State names are those of the daemon's ``state`` message (docs/architecture.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from operator import attrgetter
from types import MappingProxyType
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.calib.frozen import (
    FROZEN_RESOLUTION,
    ChannelRun,
    FrozenChannel,
    changing,
    follow,
    shown,
)
from tdmon.calib.rotation import TorqueZero, torque_turning
from tdmon.vocabulary import MOVING_STATES, ROTATING_STATES, RigState

__all__ = [
    "HANGING_STATES",
    "MOVING_STATES",
    "RESTING_ON",
    "STATES",
    "WITHOUT_CHANNEL",
    "Detection",
    "DetectorState",
    "RigSample",
    "RigStateThresholds",
    "classify",
    "detect",
    "detect_series",
    "drilling_ahead",
    "in_slips_limit",
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
    in_slips_margin : hook load up to ``block_weight + in_slips_margin`` means in slips [N];
        with the string's modelled weight at the bit depth (``RigSample.string_weight``) the
        largest margin (see :func:`in_slips_limit`)
    in_slips_fraction : with the string's modelled weight W, the margin is
        ``in_slips_fraction * W`` within [``in_slips_min_margin``, ``in_slips_margin``] [-]
        (one half: midway between the hook carrying the block alone and carrying the whole
        string, as far from a slack-off's drag as from an in-slips load's noise and drift)
    in_slips_min_margin : smallest margin [N] (a string of a few stands: the load cell's noise
        and zero drift must not make the slips look open)
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
    rotating_torque : with a torque channel, rotation needs the torque level this far at least
        above its still-string zero offset [N m] (`tdmon.calib.rotation`)
    torque_sigmas : ... and this many standard deviations of the level's noise [-]
    torque_average : the torque level is the mean of its samples of the last this many
        seconds [s]
    torque_fraction : before any still-string torque is known, the level must exceed this
        share of its peak since the string was last known still [-]
    frozen_time : a channel unchanged within its resolution while its neighbours say it must
        move, for this long in all, is frozen [s] (`tdmon.calib.frozen`)
    frozen_samples : ... over at least this many of its own samples [-]
    frozen_resolution : per channel, changes smaller than this do not count [SI]
    wob_follow : on bottom, a fall of the hook load (weight set on the bit) the weight on bit
        must follow [N] (50 kN: several deviations of a hook load's noise above its on-bottom
        highest, below the weight a bit drills with)
    drilling_ahead_time : the bit is on bottom, whatever the weight on bit reads, while it lies
        within ``on_bottom`` of the hole depth and the hole depth deepened within this long
        [s] (docs/drilling.md; 120 s: a hole depth sent in 0.1 m steps at 3 m/h, the slowest
        rate of penetration a drilling interval is judged at)
    drilling_ahead_step : the hole deepens when its depth lies this much below the last
        deepening's [m] (a hole depth sent in 0.1 m steps deepens at every step)
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
    in_slips_fraction: float = 0.5
    in_slips_min_margin: float = 20e3
    rotating_torque: float = 100.0
    torque_sigmas: float = 4.0
    torque_average: float = 5.0
    torque_fraction: float = 0.2
    frozen_time: float = 30.0
    frozen_samples: int = 4
    frozen_resolution: Mapping[str, float] = field(
        default_factory=lambda: dict(FROZEN_RESOLUTION))
    wob_follow: float = 50e3
    drilling_ahead_time: float = 120.0
    drilling_ahead_step: float = 0.05


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
    string_weight : the modelled buoyed weight of the string hanging at this bit depth [N]
        (static hook load less the block weight; None: not known, the fixed in-slips margin)
    ages : how old each channel's value is [s] (the aligner's ``Frame.ages``; None: every
        value sampled at ``t``), so that a repeated frame is not a new sample of a channel
    downhole_wob, downhole_torque : the MWD's weight on bit [N] and torque at the bit [N m]
        (None: not streamed); a drilling window prefers them (`tdmon.calib.windows`)
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
    string_weight: float | None = None
    ages: Mapping[str, float] | None = None
    downhole_wob: float | None = None
    downhole_torque: float | None = None


_NO_CHANNELS: Final[frozenset[str]] = frozenset()
_NO_TORQUE: Final = TorqueZero()


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
    # each channel's run of unchanged readings
    # (a dict never changed once in a state: a state is pickled with the daemon's)
    runs: Mapping[str, ChannelRun] = field(default_factory=dict)
    frozen: frozenset[str] = _NO_CHANNELS  # the channels frozen now
    frozen_channels: tuple[FrozenChannel, ...] = ()  # and what the alarm says of them
    torque: TorqueZero = _NO_TORQUE  # the torque's zero offset and rotation evidence
    hole_depth: float = -math.inf  # the deepest hole depth read [m]
    hole_level: float = -math.inf  # the hole depth at its last deepening [m]
    hole_deepened: float = -math.inf  # when that was [s]


@dataclass(frozen=True, slots=True)
class Detection:
    """Result for one sample: ``state``, ``steady``, axial ``velocity`` [m/s] (> 0 deeper);
    ``suspect``, the frozen channels this sample's state rests on (its window is not fed to
    the estimates); ``frozen``, every channel frozen now, for the alarm."""

    state: RigState
    steady: bool
    velocity: float | None
    suspect: frozenset[str] = _NO_CHANNELS
    frozen: tuple[FrozenChannel, ...] = ()


#: The states whose samples rest on each channel: a frozen channel makes the samples of these
#: states suspect. The hook load and the bit depth feed every window; the block position only
#: the moving states' velocity; the RPM and the torque the rotating states (their friction
#: comes from the torque, the reaming angle from the RPM, and their rotation from both); the
#: weight on bit whether a rotating string is on bottom (drilling, not estimated) or off it.
#: Flow and standpipe pressure feed no estimate (circulating and static hangs are checked
#: alike).
RESTING_ON: Final[Mapping[str, frozenset[RigState]]] = MappingProxyType({
    "hookload": frozenset(RigState),
    "bit_depth": frozenset(RigState),
    "block_position": MOVING_STATES,
    "rpm": ROTATING_STATES,
    "torque": ROTATING_STATES,
    "wob": ROTATING_STATES,
})

WITHOUT_CHANNEL: Final[Mapping[str, str]] = MappingProxyType({
    "hookload": "the windows resting on it are left out of the estimates",
    "torque": ("rotation is read from the rpm alone and rotating windows are left out of the "
               "estimates"),
    "rpm": ("rotation is read from the torque alone and rotating windows are left out of the "
            "estimates"),
    "bit_depth": ("the string's velocity comes from the block and the windows are left out of "
                  "the estimates"),
    "block_position": ("the string's velocity comes from the bit depth and moving windows are "
                       "left out of the estimates"),
    "flow_in": "circulation is read from the standpipe pressure",
    "spp": "circulation is read from the flow in",
    "wob": ("the bit's contact with bottom is read from the depths and rotating windows are "
            "left out of the estimates"),
})
"""What the detector does without each channel once it is judged frozen, in the alarm's
words (a frozen channel is not used until its value changes)."""


def _finite(value: float | None) -> float | None:
    return value if value is not None and math.isfinite(value) else None


def in_slips_limit(string_weight: float | None, thresholds: RigStateThresholds) -> float:
    """Hook load below which the string is in slips [N].

    Parameters
    ----------
    string_weight : the modelled buoyed weight of the string hanging at the bit depth [N]
        (None: unknown)
    thresholds : ``block_weight``, ``in_slips_margin``, ``in_slips_fraction``,
        ``in_slips_min_margin``

    Returns
    -------
    ``block_weight + margin``, the margin ``in_slips_fraction * string_weight`` bounded by
    ``[in_slips_min_margin, in_slips_margin]`` (``in_slips_margin`` without a string weight)

    Notes
    -----
    In slips the hook carries the travelling equipment alone; hanging free, that plus the
    string's weight (more on a pull, less on a run by the drag). Half the string's weight is
    the threshold furthest from both: a fixed margin of 150-200 kN, sized for deep wells, put a
    light string of 50-330 kN hanging on the hook "in slips" (issue 28), and the block weight
    learnt from those samples drifted. Heavy strings keep the configured margin (the Volve F-4
    tubing weighs 800-900 kN, the margin stays 200 kN).
    """
    margin = thresholds.in_slips_margin
    if string_weight is not None and math.isfinite(string_weight):
        margin = min(margin, max(thresholds.in_slips_min_margin,
                                 thresholds.in_slips_fraction * string_weight))
    return thresholds.block_weight + margin


def classify(hookload: float | None, velocity: float | None, rpm: float | None,
             circulating: bool, on_bottom: bool, thresholds: RigStateThresholds, *,
             rotating: bool | None = None, in_slips_below: float | None = None) -> RigState:
    """Rig state of one sample.

    Parameters
    ----------
    hookload : [N]; None gives ``unknown``
    velocity : axial velocity of the string, > 0 going deeper [m/s]
    rpm : surface rotation [rad/s]
    circulating : mud is being pumped
    on_bottom : the bit is on bottom (see `detect`)
    thresholds : the detector's settings
    rotating : the string turns (`detect` decides it from the RPM and the torque); None: the
        RPM alone, above ``rotating_speed``
    in_slips_below : hook load below which the string is in slips [N] (None: the block weight
        plus ``in_slips_margin``; `detect` passes :func:`in_slips_limit`)

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
    limit = (thresholds.block_weight + thresholds.in_slips_margin if in_slips_below is None
             else in_slips_below)
    if hookload < limit:
        return RigState.IN_SLIPS
    moving_down = velocity is not None and velocity > thresholds.moving_speed
    moving_up = velocity is not None and velocity < -thresholds.moving_speed
    if rotating is None:
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
              ) -> tuple[float | None, float | None, float, float | None, float, bool,
                         float | None, float | None]:
    """(velocity, then the channel memory: bit depth, its time, block position, its time,
    whether the block was loaded; then the block's and the bit depth's own velocities)."""
    # Two measures of the string's axial speed. The bit depth is what the rig reports for the
    # string, but it can jump (depth-tracking resets, Volve trip in); the block moves with the
    # string only while the hook carries it (in slips it travels empty) and its encoder can be
    # noisy. Rules: the block counts only between samples taken with the string on the hook;
    # when both agree the bit depth is used; when they disagree, the one continuing the last
    # velocity wins (a jump is a discontinuity), unless the bit depth is frozen. A frame that
    # repeats a channel's last sample keeps that channel's last velocity, except across the
    # slips. A channel judged frozen is not used (the other one gives the velocity).
    block = _trusted(sample.block_position, "block_position", prior.frozen)
    bit = _trusted(sample.bit_depth, "bit_depth", prior.frozen)
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
            memory_loaded, v_block, v_bit)


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


class _Neighbours(NamedTuple):
    """What the channels say on one frame, for the frozen-channel evidence."""

    t: float
    loaded: bool  # the string hangs on the hook (not in slips)
    velocity: float | None  # the string's axial velocity [m/s]
    block_velocity: float | None  # the block's own [m/s]
    bit_velocity: float | None  # the bit depth's own [m/s]
    rpm: float | None  # the RPM reading [rad/s]
    rpm_turning: bool  # a trusted RPM above the rotating speed
    torque: TorqueZero | None  # the torque evidence (None: no trusted torque)
    torque_changing: bool  # the torque changed at its last samples
    flow: float | None  # trusted flow in [m3/s]
    spp: float | None  # trusted standpipe pressure [Pa]
    hookload: float | None  # [N]
    on_bottom: bool  # on bottom by the depths, or by a weight on bit near the hole depth
    thresholds: RigStateThresholds


_NO_ANCHOR: Final = -math.inf  # no anchor (not NaN: states compare equal)
_NO_EVIDENCE: Final = (False, _NO_ANCHOR, False)


def _hookload_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    # a moving string's hook load varies (drag, noise, the depth's weight)
    v = n.velocity
    return n.loaded and v is not None and abs(v) > n.thresholds.moving_speed, _NO_ANCHOR, False


def _torque_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    # a turning string's torque varies; at rest it may sit on one value (Volve: 5.2 N m)
    return n.loaded and n.rpm_turning, _NO_ANCHOR, False


def _rpm_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    # the torque turned during the RPM's run and now, still changing, says the string is
    # still while the RPM still reads rotation (the latch keeps "the torque turned")
    zero = n.torque
    if zero is None:
        return _NO_EVIDENCE
    reads_turning = n.rpm is not None and n.rpm > n.thresholds.rotating_speed
    evidence = (n.loaded and reads_turning and not zero.turning and n.torque_changing
                and run is not None and run.anchor == 1.0)
    return evidence, 1.0 if zero.turning else 0.0, True


def _bit_depth_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    v = n.block_velocity
    return n.loaded and v is not None and abs(v) > n.thresholds.moving_speed, _NO_ANCHOR, False


def _block_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    v = n.bit_velocity
    return n.loaded and v is not None and abs(v) > n.thresholds.moving_speed, _NO_ANCHOR, False


def _pumps_evidence(run: ChannelRun | None, reads: bool, other: bool | None
                    ) -> tuple[bool, float, bool]:
    # the other channel started or stopped the pumps during this one's run and now
    # contradicts it (a pressure bleeding off after the pumps stop agrees with a zero flow)
    if other is None:
        return _NO_EVIDENCE
    anchor = 1.0 if other else 0.0
    changed = run is not None and run.anchor == 1.0 - anchor
    return changed and other != reads, anchor, False


def _flow_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    th = n.thresholds
    spp = None if n.spp is None else n.spp > th.circulating_pressure
    reads = run is not None and run.low > th.circulating_flow
    return _pumps_evidence(run, reads, spp)


def _spp_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    th = n.thresholds
    flow = None if n.flow is None else n.flow > th.circulating_flow
    reads = run is not None and run.low > th.circulating_pressure
    return _pumps_evidence(run, reads, flow)


def _wob_evidence(run: ChannelRun | None, n: _Neighbours) -> tuple[bool, float, bool]:
    # on bottom the rig's weight on bit is its hook-load reference less the hook load: weight
    # set down on the bit (the hook load falling below the highest it read on bottom during
    # the run, the latch) must show on it; off bottom some rigs hold it or zero it, and a
    # hook load that changes off bottom (a ream down onto bottom) says nothing of it
    hookload = n.hookload
    if hookload is None:
        return _NO_EVIDENCE
    evidence = (n.loaded and n.on_bottom and run is not None and math.isfinite(run.anchor)
                and run.anchor - hookload > n.thresholds.wob_follow)
    return evidence, hookload if n.on_bottom else _NO_ANCHOR, True


#: Each followed channel: its RigSample field and what its neighbours say of it.
_FOLLOWED: Final = (
    ("hookload", "hookload", _hookload_evidence),
    ("torque", "torque", _torque_evidence),
    ("rpm", "rpm", _rpm_evidence),
    ("bit_depth", "bit_depth", _bit_depth_evidence),
    ("block_position", "block_position", _block_evidence),
    ("flow_in", "flow", _flow_evidence),
    ("spp", "spp", _spp_evidence),
    ("wob", "wob", _wob_evidence),
)


#: The followed channels' readings of a sample, in the order of `_FOLLOWED`.
_followed_values: Final = attrgetter(*(name for _, name, _ in _FOLLOWED))
_NO_AGES: Final[Mapping[str, float]] = MappingProxyType({})


def _why(channel: str, n: _Neighbours) -> str:
    """The neighbours' words, when a channel is judged frozen."""
    th = n.thresholds
    if channel == "hookload":
        return f"while the string moves at {abs(n.velocity or 0.0):.2f} m/s"
    if channel == "torque":
        return (f"while the rpm reads {shown('rpm', n.rpm or 0.0)} (a turning string's torque "
                "varies)")
    if channel == "rpm":
        zero = n.torque
        level = (math.fsum(v for _, v in zero.recent) / len(zero.recent)
                 if zero is not None and zero.recent else math.nan)
        where = ("" if zero is None or zero.offset is None
                 else f", its still-string zero offset being {shown('torque', zero.offset)}")
        return (f"while the torque fell to {shown('torque', level)}{where}: the string is not "
                "turning")
    if channel == "bit_depth":
        return f"while the block moves the string at {abs(n.block_velocity or 0.0):.2f} m/s"
    if channel == "block_position":
        return (f"while the bit depth moves at {abs(n.bit_velocity or 0.0):.2f} m/s with the "
                "string on the hook")
    if channel == "flow_in":
        running = n.spp is not None and n.spp > th.circulating_pressure
        return (f"while the standpipe pressure ({shown('spp', n.spp or 0.0)}) says the pumps "
                f"{'started' if running else 'stopped'}")
    if channel == "spp":
        running = n.flow is not None and n.flow > th.circulating_flow
        return (f"while the flow in ({shown('flow_in', n.flow or 0.0)}) says the pumps "
                f"{'started' if running else 'stopped'}")
    return "on bottom while the hook load changed"


def _follow_channels(prior: DetectorState, sample: RigSample, n: _Neighbours
                     ) -> tuple[Mapping[str, ChannelRun], frozenset[str],
                                tuple[FrozenChannel, ...]]:
    """Each present channel's run; the channels frozen now and their alarm records."""
    th = n.thresholds
    t = sample.t
    ages = sample.ages if sample.ages is not None else _NO_AGES
    resolution = th.frozen_resolution
    frozen_time, frozen_samples, max_gap = th.frozen_time, th.frozen_samples, th.max_gap
    runs = dict(prior.runs)
    changed = False
    values = _followed_values(sample)
    for (channel, _, evidence_of), value in zip(_FOLLOWED, values, strict=True):
        if value is None or not math.isfinite(value):
            continue
        run = runs.get(channel)
        evidence, anchor, latch = evidence_of(run, n)
        age = ages.get(channel)
        sampled = t - age if age is not None and math.isfinite(age) else t
        new = follow(run, t, value, sampled, resolution.get(channel, 0.0), evidence, anchor,
                     latch, frozen_time, frozen_samples, max_gap)
        if new.frozen:
            if not (run is not None and run.frozen and run.since == new.since):
                new = new._replace(reason=_why(channel, n))
                changed = True
        elif run is not None and run.frozen:
            changed = True  # it moved: no longer frozen
        runs[channel] = new
    if not changed:
        return runs, prior.frozen, prior.frozen_channels
    frozen = [channel for channel, _, _ in _FOLLOWED
              if channel in runs and runs[channel].frozen]
    records = tuple(FrozenChannel(channel, runs[channel].low, runs[channel].since,
                                  runs[channel].reason) for channel in frozen)
    return runs, frozenset(frozen), records


def _on_bottom(bit: float | None, hole: float | None, wob: float | None,
               thresholds: RigStateThresholds) -> bool:
    off_bottom = None if bit is None or hole is None else hole - bit
    if wob is not None:
        # hole-depth channels are coarse; weight on the bit says the bit touches bottom
        return wob > thresholds.drilling_wob and (
            off_bottom is None or off_bottom <= thresholds.on_bottom_with_wob)
    return off_bottom is not None and off_bottom <= thresholds.on_bottom


#: The states a string sliding ahead (turned by a mud motor, not from surface) is classed as:
#: its samples, while the hole deepens under the bit, carry an unknown weight on the bit.
_SLIDING_STATES: Final = frozenset({RigState.STATIC, RigState.CIRCULATING, RigState.SLACK_OFF})


def drilling_ahead(prior: DetectorState, t: float, bit: float | None, hole: float | None,
                   thresholds: RigStateThresholds) -> tuple[bool, float, float, float]:
    """Whether the hole deepens under the bit now: (drilling ahead, the deepest hole depth
    read [m], the hole depth at its last deepening [m], when that was [s]).

    The bit drills ahead while it lies within ``on_bottom`` of the deepest hole depth read
    and the hole deepened within ``drilling_ahead_time`` (docs/drilling.md, "Rig state"): the
    hole deepens only under a bit cutting rock, whatever the surface weight on bit reads (a
    driller's zero set off the hook load drifts, and a soft formation drills at a few kN).
    A deepening is a hole depth ``drilling_ahead_step`` or more below the last deepening's,
    read with the bit within ``on_bottom`` of it (the bit made that hole); the first hole depth
    read starts the record. So a noisy hole-depth channel, whose deepest reading runs ahead
    of the bit, does not put a bit off bottom on bottom.
    """
    deepest, level, deepened = prior.hole_depth, prior.hole_level, prior.hole_deepened
    if hole is not None:
        if not math.isfinite(level):
            level = hole
        elif (hole >= level + thresholds.drilling_ahead_step and bit is not None
              and hole - bit <= thresholds.on_bottom):
            level, deepened = hole, t
        deepest = max(deepest, hole)
    ahead = (bit is not None and deepest - bit <= thresholds.on_bottom
             and t - deepened <= thresholds.drilling_ahead_time)
    return ahead, deepest, level, deepened


def _trusted(value: float | None, channel: str, frozen: frozenset[str]) -> float | None:
    """A channel's finite value, None when missing or judged frozen."""
    value = _finite(value)
    return None if value is None or (frozen and channel in frozen) else value


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
    limit = in_slips_limit(sample.string_weight, thresholds)
    loaded = hookload is not None and hookload >= limit
    (velocity, bit_depth, bit_time, block_position, block_time, block_loaded, block_velocity,
     bit_velocity) = _velocity(prior, sample, loaded, thresholds)
    if fresh:
        velocity = None
    frozen = prior.frozen
    rpm = _trusted(sample.rpm, "rpm", frozen)
    torque = _trusted(sample.torque, "torque", frozen)
    rpm_turning = rpm is not None and rpm > thresholds.rotating_speed
    zero = prior.torque
    if torque is not None:
        known_still = (hookload is not None and not loaded) or (rpm is not None
                                                                 and not rpm_turning)
        age = sample.ages.get("torque") if sample.ages is not None else None
        zero = torque_turning(zero, torque, t - age if age is not None else t, known_still,
                              thresholds.torque_average, thresholds.rotating_torque,
                              thresholds.torque_sigmas, thresholds.torque_fraction)
        rotating = zero.turning and (rpm is None or rpm_turning)
    else:
        rotating = rpm_turning
    # the RPM says the string turns, a torque channel says it does not: one of them lies
    contradicted = rpm_turning and torque is not None and not zero.turning and loaded
    flow = _trusted(sample.flow, "flow_in", frozen)
    spp = _trusted(sample.spp, "spp", frozen)
    circulating = ((flow is not None and flow > thresholds.circulating_flow)
                   or (flow is None and spp is not None and spp > thresholds.circulating_pressure))
    bit, hole = _trusted(sample.bit_depth, "bit_depth", frozen), _finite(sample.hole_depth)
    on_bottom = _on_bottom(bit, hole, _trusted(sample.wob, "wob", frozen), thresholds)
    ahead, deepest, level, deepened = drilling_ahead(prior, t, bit, hole, thresholds)
    # a string pulled up off the new bottom (back-reaming, a pick-up) has left it
    ahead = ahead and not (velocity is not None and velocity < -thresholds.moving_speed)
    on_bottom = on_bottom or ahead
    # on bottom by the depths, or reading weight near the hole depth (coarse hole depths)
    wob_reading = _finite(sample.wob)
    near_bottom = bit is not None and hole is not None and (
        hole - bit <= thresholds.on_bottom
        or (wob_reading is not None and wob_reading > thresholds.drilling_wob
            and hole - bit <= thresholds.on_bottom_with_wob))
    neighbours = _Neighbours(
        t, loaded, velocity, block_velocity, bit_velocity, _finite(sample.rpm), rpm_turning,
        zero if torque is not None else None, changing(prior.runs.get("torque")), flow, spp,
        hookload, near_bottom, thresholds)
    runs, frozen, frozen_channels = _follow_channels(prior, sample, neighbours)
    state = classify(hookload, velocity, rpm, circulating, on_bottom, thresholds,
                     rotating=rotating, in_slips_below=limit)
    same = state == prior.state and not fresh
    since = prior.state_since if same else t
    run = prior.run + 1 if same else 1
    prior_hookload = prior.hookload
    steady = (state != RigState.UNKNOWN and not fresh and t - since >= thresholds.settle_time
              and run >= thresholds.settle_samples
              and hookload is not None and prior_hookload is not None and not contradicted)
    if steady and velocity is not None and prior.velocity is not None:
        steady = abs(velocity - prior.velocity) / dt <= thresholds.max_acceleration
    if steady and hookload is not None and prior_hookload is not None:
        step = max(thresholds.max_hookload_step,
                   thresholds.max_hookload_step_fraction * abs(hookload))
        steady = abs(hookload - prior_hookload) <= step
    if steady and state in MOVING_STATES and velocity is None:
        steady = False
    if steady and ahead and state in _SLIDING_STATES:
        steady = False  # the hole deepens without rotation (sliding): the bit carries weight
    hang_load, hang_since, hang_run = _hang(prior, same, state, t, hookload, thresholds)
    if steady and hang_load is not None:
        steady = (t - hang_since >= thresholds.settle_time
                  and hang_run >= thresholds.settle_samples)
    suspect = (frozenset(c for c in frozen if state in RESTING_ON.get(c, ())) if frozen
               else _NO_CHANNELS)
    # positional, in the order of the fields (once per frame: the keywords cost a third)
    new = DetectorState(t, bit_depth, bit_time, block_position, block_time, block_loaded,
                        velocity, hookload, state, since, run, hang_load, hang_since, hang_run,
                        runs, frozen, frozen_channels, zero, deepest, level, deepened)
    return new, Detection(state, bool(steady), velocity, suspect, frozen_channels)


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
    torque: ArrayLike | None = None,
    string_weight: ArrayLike | None = None,
) -> tuple[NDArray[np.str_], NDArray[np.bool_]]:
    """Run :func:`detect` over a whole record (NaN = missing; every channel sampled at ``t``).

    Returns
    -------
    states : state name per sample
    steady : steady flag per sample
    """
    times = np.asarray(t, dtype=np.float64)
    n = times.size
    columns = [np.asarray(hookload, dtype=np.float64), np.asarray(bit_depth, dtype=np.float64),
               _optional(block_position, n), _optional(rpm, n), _optional(flow, n),
               _optional(spp, n), _optional(hole_depth, n), _optional(wob, n),
               _optional(torque, n), _optional(string_weight, n)]
    states = np.empty(n, dtype="<U20")
    steady = np.zeros(n, dtype=bool)
    prior = DetectorState()
    for i in range(n):
        values = [float(column[i]) for column in columns]
        v = [x if math.isfinite(x) else None for x in values]
        sample = RigSample(float(times[i]), hookload=v[0], bit_depth=v[1], block_position=v[2],
                           rpm=v[3], flow=v[4], spp=v[5], hole_depth=v[6], wob=v[7],
                           torque=v[8], string_weight=v[9])
        prior, result = detect(prior, sample, thresholds)
        states[i] = result.state
        steady[i] = result.steady
    return states, steady
