"""Steady windows: runs of steady samples of one rig state, summarised for estimation.

A window collects consecutive steady samples of one state; it closes when the state changes,
a sample is not steady, a gap appears, or it has grown to ``max_samples`` or ``max_travel`` (so
that each window stays local in bit depth for the friction profile). On closing it is checked:
spikes are dropped (median absolute deviation), a stuck hook load (every sample identical)
rejects it, a bit depth that does not follow the block flags it low-confidence, and so does a
torque that never changes in a rotating window (a window without rotation does not use it).
A window any of whose samples rested on a channel the rig-state detector judged frozen carries
that channel in ``suspect`` (`tdmon.calib.rigstate.Detection.suspect`; and the window being
built when a channel its state rests on is judged frozen, for the run began before the
judgement): the estimator feeds it to no estimate. The standard error of its mean hook load
carries a floor from the sensor's noise, so a one-sample window at 15 s sampling still has an
honest uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from statistics import median

import numpy as np

from tdmon.calib.rigstate import RESTING_ON, Detection, RigSample
from tdmon.vocabulary import MOVING_STATES, ROTATING_STATES, RigState

#: states whose windows are estimated from their surface torque (the rotating ones): only they
#: are flagged for a torque sensor that does not move
TORQUE_STATES: frozenset[RigState] = ROTATING_STATES

__all__ = ["TORQUE_STATES", "Window", "WindowAccumulator", "WindowSettings", "add_sample",
           "close", "summarise"]


@dataclass(frozen=True)
class WindowSettings:
    """Settings of window building and checking.

    Attributes
    ----------
    min_samples : fewer steady samples (after spike removal) reject the window [-]
    max_samples : a window closes when it holds this many samples [-]
    max_travel : a window closes when the bit has moved this far [m]
    noise_floor : hook-load sensor noise, absolute [N] ...
    noise_floor_fraction : ... and relative to the hook load [-]; the larger is used
    torque_noise_floor : surface-torque sensor noise [N m]
    spike_mads : samples further than this many scaled MADs from the median are spikes [-]
    max_gap : a longer gap between samples closes the window [s]
    """

    min_samples: int = 1
    max_samples: int = 120
    max_travel: float = 30.0
    noise_floor: float = 2e3
    noise_floor_fraction: float = 0.005
    torque_noise_floor: float = 200.0
    spike_mads: float = 5.0
    max_gap: float = 60.0


@dataclass(frozen=True)
class Window:
    """A closed window.

    Attributes
    ----------
    state : rig state of its samples
    t_start, t_end : [s]
    n : samples used [-]
    bit_depth : mean bit depth [m]
    bit_depth_start, bit_depth_end : [m]
    hookload : mean hook load [N]
    hookload_se : standard error of the mean hook load, with the sensor-noise floor [N]
    torque : mean surface torque [N m] (None when not measured)
    torque_se : its standard error [N m]
    rpm : mean rotation [rad/s] (None when not measured)
    velocity : mean axial velocity [m/s] (> 0 deeper; None when unknown)
    flags : quality remarks, e.g. ``"spikes_removed:2"``, ``"depth_not_following_block"``
    rejected : why the window must not be used (None when usable)
    suspect : channels judged frozen that its samples' state rested on (sorted; the window
        is then fed to no estimate)
    wob : a drilling window's weight on bit [N]: the mean MWD weight on bit when every kept
        sample has one, else the mean surface weight on bit (None: another state, or neither)
    wob_source : whose ``wob`` is: ``"downhole"`` (the MWD's), ``"surface"`` (None: no ``wob``)
    bit_torque : a drilling window's bit torque [N m]: the mean MWD torque at the bit when
        every kept sample has one, else the estimator's from the last tag (None: not known)
    bit_torque_source : whose ``bit_torque`` is: ``"downhole"``, ``"tag"`` (None: not known)
    """

    state: RigState
    t_start: float
    t_end: float
    n: int
    bit_depth: float
    bit_depth_start: float
    bit_depth_end: float
    hookload: float
    hookload_se: float
    torque: float | None = None
    torque_se: float | None = None
    rpm: float | None = None
    velocity: float | None = None
    flags: tuple[str, ...] = ()
    rejected: str | None = None
    suspect: tuple[str, ...] = ()
    wob: float | None = None
    wob_source: str | None = None
    bit_torque: float | None = None
    bit_torque_source: str | None = None

    @property
    def low_confidence(self) -> bool:
        """Usable but with a quality remark."""
        return self.rejected is None and bool(self.flags)


@dataclass(frozen=True, slots=True)
class WindowAccumulator:
    """Samples of the window being built (tuples: the accumulator is immutable)."""

    state: RigState = RigState.UNKNOWN  # of the samples; none yet: unknown is never steady
    samples: tuple[RigSample, ...] = ()
    velocities: tuple[float | None, ...] = ()
    suspect: frozenset[str] = frozenset()  # the frozen channels its samples rested on


def _robust_keep(values: np.ndarray, spike_mads: float, floor: float) -> np.ndarray:
    # medians with the standard library, np.median's to the last bit for finite floats
    # (tests/calib/test_median.py): NumPy's call costs more than a window's sort
    middle = median(values.tolist())
    deviation = np.abs(values - middle)
    mad = 1.4826 * median(deviation.tolist())
    tolerance = max(spike_mads * mad, spike_mads * floor)
    return np.asarray(deviation <= tolerance)


def _mean_se(values: np.ndarray, floor: float) -> tuple[float, float]:
    # np.mean and np.std(ddof=1) as NumPy computes them (the same pairwise sums, divisions and
    # square root, so the same bits), without their wrappers' cost, which exceeds the sums
    n = values.size
    mean = values.sum() / n
    if n > 1:
        deviation = values - mean
        spread = math.sqrt((deviation * deviation).sum() / (n - 1))
    else:
        spread = 0.0
    return float(mean), max(spread, floor) / math.sqrt(n)


def _mean(values: list[float] | np.ndarray) -> float:
    # np.mean of floats to the last bit (the same pairwise sum and division) without its
    # wrapper, which costs more than the sum of a window's values (summarise 81 -> 66 us)
    return float(np.asarray(values, dtype=np.float64).sum() / len(values))


def summarise(state: RigState, samples: tuple[RigSample, ...],
              velocities: tuple[float | None, ...], settings: WindowSettings,
              suspect: frozenset[str] = frozenset()) -> Window | None:
    """Check and summarise the samples of one window (None when there are none usable).

    Parameters
    ----------
    state : their rig state
    samples : the steady samples, in time order
    velocities : the detector's axial velocity of each sample [m/s]
    settings : window settings
    suspect : frozen channels the samples rested on

    Returns
    -------
    Window or None
    """
    rows = [(s, v) for s, v in zip(samples, velocities, strict=True)
            if s.hookload is not None and s.bit_depth is not None
            and math.isfinite(s.hookload) and math.isfinite(s.bit_depth)]
    if not rows:
        return None
    hookload = np.array([s.hookload for s, _ in rows], dtype=np.float64)
    loads: list[float] = hookload.tolist()
    depth = np.array([s.bit_depth for s, _ in rows], dtype=np.float64)
    flags: list[str] = []
    rejected: str | None = None
    floor = max(settings.noise_floor,
                settings.noise_floor_fraction * median([abs(x) for x in loads]))
    if len(loads) >= 3 and max(loads) == min(loads):
        # a real load cell always shows some noise: identical readings mean a frozen value
        rejected = "hookload_stuck"
    keep = _robust_keep(hookload, settings.spike_mads, floor)
    if keep.all():
        kept = rows  # no spike (most windows): no copies of the same values
    else:
        flags.append(f"spikes_removed:{int((~keep).sum())}")
        kept = [row for row, k in zip(rows, keep.tolist(), strict=True) if k]
        hookload, depth = hookload[keep], depth[keep]
    if len(kept) < settings.min_samples:
        rejected = rejected or f"too_few_samples:{len(kept)}"
    mean, se = _mean_se(hookload, floor)
    torque_values = np.array([s.torque for s, _ in kept if s.torque is not None
                              and math.isfinite(s.torque)], dtype=np.float64)
    torque = torque_se = None
    if torque_values.size == len(kept) and torque_values.size:
        torque, torque_se = _mean_se(torque_values, settings.torque_noise_floor)
        # only where the window's estimate uses its torque: a pick-up without rotation
        # rests at the sensor's zero offset and its confidence does not depend on it
        if (state in TORQUE_STATES and torque_values.size >= 3
                and float(np.ptp(torque_values)) == 0.0 and torque != 0.0):
            flags.append("torque_stuck")
    rpm_values = [s.rpm for s, _ in kept if s.rpm is not None and math.isfinite(s.rpm)]
    rpm = _mean(rpm_values) if len(rpm_values) == len(kept) else None
    speeds = [v for _, v in kept if v is not None and math.isfinite(v)]
    velocity = _mean(speeds) if speeds else None
    if state in MOVING_STATES and len(kept) >= 2 and velocity is not None:
        travel = float(depth[-1] - depth[0])
        expected = velocity * (kept[-1][0].t - kept[0][0].t)
        if abs(travel - expected) > max(1.0, 0.5 * abs(expected)):
            # bit depth and block disagree: depth tracking reset or a stuck depth channel
            flags.append("depth_not_following_block")
    wob, wob_source, bit_torque = _drilling_bit(state, [s for s, _ in kept])
    return Window(
        state=state, t_start=kept[0][0].t if kept else rows[0][0].t,
        t_end=kept[-1][0].t if kept else rows[-1][0].t, n=len(kept),
        bit_depth=_mean(depth) if depth.size else float(rows[0][0].bit_depth or 0.0),
        bit_depth_start=float(depth[0]) if depth.size else 0.0,
        bit_depth_end=float(depth[-1]) if depth.size else 0.0,
        hookload=mean if hookload.size else 0.0, hookload_se=se if hookload.size else 0.0,
        torque=torque, torque_se=torque_se, rpm=rpm, velocity=velocity, flags=tuple(flags),
        rejected=rejected, suspect=tuple(sorted(suspect)),
        wob=wob, wob_source=wob_source, bit_torque=bit_torque,
        bit_torque_source=None if bit_torque is None else "downhole",
    )


def _mean_of_all(values: list[float | None]) -> float | None:
    """The mean of ``values`` when every one is a finite number (None otherwise)."""
    finite = [x for x in values if x is not None and math.isfinite(x)]
    return _mean(finite) if finite and len(finite) == len(values) else None


def _drilling_bit(state: RigState, kept: list[RigSample]
                  ) -> tuple[float | None, str | None, float | None]:
    """A drilling window's weight on bit [N] and whose, and its MWD bit torque [N m].

    The MWD weighs the bit itself; the rig's surface weight on bit is the hook load off
    bottom less the hook load now, so a hook-load balance with it says again what the
    hook load at the tag said, and with the MWD's it is a measurement of its own
    (docs/drilling.md, "Drilling windows and the joint estimate"). Each is taken only when
    every kept sample has it, so that a window's mean is of one source.
    """
    if state != RigState.DRILLING:
        return None, None, None
    bit_torque = _mean_of_all([s.downhole_torque for s in kept])
    downhole = _mean_of_all([s.downhole_wob for s in kept])
    if downhole is not None:
        return downhole, "downhole", bit_torque
    surface = _mean_of_all([s.wob for s in kept])
    return surface, None if surface is None else "surface", bit_torque


def close(acc: WindowAccumulator, settings: WindowSettings
          ) -> tuple[WindowAccumulator, Window | None]:
    """Close the window being built (end of input, or forced)."""
    if not acc.samples:
        return WindowAccumulator(), None
    return WindowAccumulator(), summarise(acc.state, acc.samples, acc.velocities, settings,
                                          acc.suspect)


def add_sample(acc: WindowAccumulator, sample: RigSample, detection: Detection,
               settings: WindowSettings) -> tuple[WindowAccumulator, Window | None]:
    """Add one detected sample; returns the new accumulator and a window if one closed.

    A non-steady sample closes the current window; a steady sample of another state, or after
    a gap, closes it and starts a new one; a full window closes after taking the sample.
    """
    closed: Window | None = None
    if detection.frozen and acc.samples:
        # a channel judged frozen now was frozen during the window being built: its samples
        # rested on it too
        rested = frozenset(f.channel for f in detection.frozen
                           if acc.state in RESTING_ON.get(f.channel, ()))
        if not rested <= acc.suspect:
            acc = replace(acc, suspect=acc.suspect | rested)
    if acc.samples:
        last = acc.samples[-1]
        gap = sample.t - last.t
        moved = (abs((sample.bit_depth or 0.0) - (acc.samples[0].bit_depth or 0.0))
                 if sample.bit_depth is not None and acc.samples[0].bit_depth is not None
                 else 0.0)
        if (not detection.steady or detection.state != acc.state
                or not (0.0 < gap <= settings.max_gap) or moved > settings.max_travel):
            acc, closed = close(acc, settings)
    if not detection.steady:
        return acc, closed
    suspect = detection.suspect
    acc = WindowAccumulator(detection.state, (*acc.samples, sample),
                            (*acc.velocities, detection.velocity),
                            acc.suspect | suspect if suspect else acc.suspect)
    if len(acc.samples) >= settings.max_samples:
        acc, full = close(acc, settings)
        return acc, full if closed is None else closed
    return acc, closed
