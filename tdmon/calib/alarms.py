"""Alarms: loads leaving the modelled band, loads nearing the limits, friction jumps, sensors.

Each detector is a pure function, with a small frozen state where it needs memory, returning
:class:`Alarm` values in the shape of the daemon's ``alarm`` message (docs/architecture.md:
``t``, ``kind``, ``severity``, ``message``, ``value``, ``limit``).

* ``band``: a trend, not a spike. The excess of the measured hook load (or torque) beyond the
  modelled band, in units of the measurement noise, is smoothed by an exponentially weighted
  moving average; the alarm fires when the average stays beyond a threshold for a minimum
  number of samples, and re-arms once the load is back inside the band.
* ``limits``: at a window's bit depth, the loads modelled with the back-calculated friction
  (which reproduce the measurement) are compared with the operating limits of
  `tdmon.model.limits`; a utilisation above ``warn`` gives a warning, above 1 a critical alarm.
* ``friction_jump``: a window's friction factor against the median of the recent windows of the
  same operation; a rise larger than both an absolute step and a multiple of the combined
  uncertainty is a tight spot or a cuttings bed building up. The same kind is raised when a
  stretch of the friction profile along MD stands above the rest (a local anomaly the bit has
  passed).
* ``sensor``: a channel gone stale, a hook load that is negative or above a plausible maximum,
  a bit below the hole depth, a channel the rig-state detector judged frozen (constant while
  its neighbours say it must move: `tdmon.calib.frozen`), named with why.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from statistics import median
from typing import Any

import numpy as np

from tdmon.calib.frozen import FrozenChannel, shown
from tdmon.calib.rigstate import WITHOUT_CHANNEL
from tdmon.messages import alarm_message
from tdmon.model.limits import operating_window
from tdmon.model.torque_drag import Loads
from tdmon.model.well import HoleGrid, Well
from tdmon.vocabulary import FROZEN_ALARM_KINDS, AlarmKind, Operation, Severity

__all__ = [
    "Alarm",
    "BandSettings",
    "BandTrendState",
    "JumpSettings",
    "SensorSettings",
    "SensorState",
    "friction_jump",
    "frozen_alarm",
    "limit_alarms",
    "profile_anomaly",
    "sensor_alarms",
    "stale_gap_alarm",
    "update_band_trend",
]


@dataclass(frozen=True)
class Alarm:
    """One alarm, as the daemon's ``alarm`` message.

    ``kind`` and ``severity`` may be given as their plain names; they are held as the
    `AlarmKind` and `Severity` members, so a name outside the vocabulary (and therefore outside
    the alarm schema) raises ``ValueError`` where the alarm is made.
    """

    t: float
    kind: AlarmKind | str
    severity: Severity | str
    message: str
    value: float | None = None
    limit: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", AlarmKind(self.kind))
        object.__setattr__(self, "severity", Severity(self.severity))

    def to_message(self) -> dict[str, Any]:
        """The ``alarm`` message; non-finite numbers become null (JSON has no NaN)."""
        return alarm_message(self.t, self.kind, self.severity, self.message, self.value,
                             self.limit)


# -- band trend -----------------------------------------------------------------------------

@dataclass(frozen=True)
class BandSettings:
    """Band-trend alarm settings.

    Attributes
    ----------
    smoothing : EWMA weight of a new sample [-]
    threshold : EWMA excess, in noise standard deviations, that raises the alarm [-]
    min_samples : consecutive samples beyond the band needed as well [-]
    """

    smoothing: float = 0.1
    threshold: float = 3.0
    min_samples: int = 10


@dataclass(frozen=True)
class BandTrendState:
    """EWMA of the normalised excess, the run of samples outside, and whether it has fired."""

    average: float = 0.0
    outside: int = 0
    active: bool = False


def update_band_trend(state: BandTrendState, t: float, measured: float, low: float,
                      high: float, noise_std: float, settings: BandSettings, *,
                      what: str = "hook load") -> tuple[BandTrendState, Alarm | None]:
    """Feed one steady sample against the modelled band [low, high] (same unit as measured).

    Non-finite inputs keep the state. Returns the new state and an alarm when the trend first
    crosses the threshold (one alarm per excursion).
    """
    isfinite = math.isfinite
    if not (isfinite(t) and isfinite(measured) and isfinite(low) and isfinite(high)
            and isfinite(noise_std)) or noise_std <= 0:
        return state, None
    low, high = min(low, high), max(low, high)
    excess = ((measured - high) if measured > high else (measured - low) if measured < low
              else 0.0) / noise_std
    average = (1.0 - settings.smoothing) * state.average + settings.smoothing * excess
    outside = state.outside + 1 if excess != 0.0 else 0
    firing = abs(average) >= settings.threshold and outside >= settings.min_samples
    if state.active:
        active = excess != 0.0 or abs(average) >= 0.5 * settings.threshold
        return BandTrendState(average, outside, active), None
    if not firing:
        return BandTrendState(average, outside, False), None
    above = average > 0
    bound = high if above else low
    alarm = Alarm(t, AlarmKind.BAND, Severity.WARNING,
                  f"{what} trending {'above' if above else 'below'} the modelled band for "
                  f"{outside} samples", measured, bound)
    return BandTrendState(average, outside, True), alarm


# -- limits ---------------------------------------------------------------------------------

def limit_alarms(well: Well, loads: Loads, operation: str, t: float, *, warn: float = 0.8,
                 grid: HoleGrid | None = None) -> list[Alarm]:
    """Loads of ``operation`` nearing or beyond the tensile, buckling and make-up limits.

    Parameters
    ----------
    well : the well
    loads : `WellModel.loads` at the window's bit depth with the back-calculated friction (of
        ``operation`` and rotating at least)
    operation : which operation's profile to check (``pick_up``, ``slack_off``, ``rotating``)
    t : time [s]
    warn : utilisation that raises a warning [-]
    grid : ``hole_grid(well)``, when the caller has it (see `operating_window`)

    Returns
    -------
    list of Alarm (worst node per limit)

    Notes
    -----
    Tension is compared with eq 28 on the effective axial force (the true force differs by the
    end-area pressure terms, small against the limit near surface where tension peaks);
    compression with the sinusoidal and helical buckling loads (eq 30, 31); torque with the
    connections' make-up torque.
    """
    window = operating_window(well, loads, torque_operation=Operation.ROTATING, grid=grid)
    force = loads.axial_force[operation]
    torque = np.abs(loads.torque[operation])
    checks = (
        (AlarmKind.LIMIT_TENSILE, "tensile", force, window.tensile, "tension"),
        (AlarmKind.LIMIT_SINUSOIDAL_BUCKLING, "sinusoidal_buckling", -force,
         window.sinusoidal_buckling, "compression"),
        (AlarmKind.LIMIT_HELICAL_BUCKLING, "helical_buckling", -force, window.helical_buckling,
         "compression"),
        (AlarmKind.LIMIT_MAKEUP_TORQUE, "makeup_torque", torque, window.makeup_torque, "torque"),
    )
    alarms: list[Alarm] = []
    # one errstate for the loop (the usage is its only arithmetic): entering and leaving one
    # per check cost ~5 us a window; argmax the array's method, without np.argmax's wrapper
    with np.errstate(invalid="ignore", divide="ignore"):
        for kind, name, load, limit, label in checks:
            usage = np.where(np.isfinite(limit) & (limit > 0) & (load > 0), load / limit, 0.0)
            if not usage.size:
                continue
            worst = int(usage.argmax())
            ratio = float(usage[worst])
            if ratio < warn:
                continue
            severity = Severity.CRITICAL if ratio >= 1.0 else Severity.WARNING
            where = "at surface" if loads.md[worst] < 0.5 else f"at {loads.md[worst]:.0f} m MD"
            limit_name = ("make-up torque" if name == "makeup_torque"
                          else name.replace("_", " "))
            alarms.append(Alarm(t, kind, severity,
                                f"{operation.replace('_', '-')} {label} {where} is "
                                f"{100 * ratio:.0f} % of the {limit_name} limit",
                                float(load[worst]), float(limit[worst])))
    return alarms


# -- friction jump --------------------------------------------------------------------------

@dataclass(frozen=True)
class JumpSettings:
    """Friction-jump settings: history length [-], absolute step [-], sigmas [-]."""

    history: int = 8
    min_history: int = 3
    min_step: float = 0.05
    sigmas: float = 3.0


def friction_jump(history: tuple[float, ...], mu: float, mu_std: float, t: float,
                  settings: JumpSettings, *, operation: str, bit_depth: float
                  ) -> Alarm | None:
    """Alarm when ``mu`` rises above the recent median of ``history`` by a real step.

    The step must exceed ``min_step`` and ``sigmas`` times the combined spread
    ``sqrt(mu_std^2 + (1.4826 MAD)^2)`` of the history.
    """
    recent = [x for x in history[-settings.history:] if math.isfinite(x)]
    if len(recent) < settings.min_history or not (math.isfinite(mu) and math.isfinite(mu_std)):
        return None
    # a few values, once per window: medians in Python, NumPy's to the last bit
    middle = median(recent)
    spread = 1.4826 * median([abs(x - middle) for x in recent])
    limit = middle + max(settings.min_step, settings.sigmas * math.hypot(mu_std, spread))
    if mu <= limit:
        return None
    return Alarm(t, AlarmKind.FRICTION_JUMP, Severity.WARNING,
                 f"{operation} friction {mu:.3f} at {bit_depth:.0f} m jumped above the recent "
                 f"{middle:.3f} (tight spot or cuttings bed?)", mu, limit)


def profile_anomaly(t: float, edges: np.ndarray, mu: np.ndarray, covariance: np.ndarray,
                    prior_std: float, settings: JumpSettings, *, width: int = 3,
                    known: frozenset[int] = frozenset()) -> tuple[Alarm | None, frozenset[int]]:
    """A stretch of the friction profile standing above the rest: local friction anomaly.

    Single bins trade friction with their neighbours and the whole profile trades with its
    level (their standard deviations stay large); the contrast of ``width`` adjacent bins
    against the rest is much better known, so the test runs on it, with its variance ``c P c``
    from the full covariance. Only stretches the data have touched
    (every bin's standard deviation below 0.8 of the prior's) count. A stretch is anomalous when
    its mean exceeds the mean of the other touched bins by more than ``min_step`` and ``sigmas``
    standard deviations of that contrast; it is reported once (``known`` holds the bins
    reported).

    Parameters
    ----------
    t : [s]
    edges : bin edges [m]
    mu : profile mean per bin [-]
    covariance : its covariance
    prior_std : the profile's prior standard deviation [-]
    settings : friction-jump settings (``min_step``, ``sigmas``)
    width : bins per stretch [-]
    known : bins already reported

    Returns
    -------
    (Alarm or None, bins reported so far)
    """
    n = mu.size
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    touched = np.isfinite(mu) & (std < 0.8 * prior_std)
    # in Python: one NumPy call per candidate stretch cost more than the products below
    flags = touched.tolist()
    touched_before = [0, *itertools.accumulate(flags)]  # touched bins in [0, k)
    if width > 0:
        # all touched: ``width`` touched bins in the stretch (a subtraction, not a slice and
        # all(), per stretch: 141 bins 19 -> 8 us)
        starts = [k for k in range(n - width + 1)
                  if touched_before[k + width] - touched_before[k] == width]
    else:
        starts = [k for k in range(n - width + 1) if all(flags[k:k + width])]
    if len(starts) < 3:
        return None, known
    best: tuple[float, int, float, float, float] | None = None
    for first in _candidates(mu, touched, starts, width, settings.min_step):
        # contrast: this stretch's mean minus the mean of the other touched bins (leaving a
        # bin out on each side); its variance c P c is small even where single bins are not
        lo, hi = max(0, first - 1), min(n, first + width + 1)
        rest_count = touched_before[n] - (touched_before[hi] - touched_before[lo])
        if rest_count < width:
            continue
        contrast = np.where(touched, -1.0 / rest_count, 0.0)
        contrast[lo:hi] = 0.0
        contrast[first:first + width] = 1.0 / width
        excess = float(contrast @ mu)
        if excess <= settings.min_step:
            continue  # within the smallest step whatever the spread: c P c is not needed
        spread = math.sqrt(max(float(contrast @ covariance @ contrast), 0.0))
        limit = max(settings.min_step, settings.sigmas * spread)
        if excess > limit and not (frozenset(range(first, first + width)) & known) and (
                best is None or excess - limit > best[0]):
            rest = touched.copy()
            rest[lo:hi] = False
            best = (excess - limit, first, excess, limit, float(np.mean(mu[rest])))
    if best is None:
        return None, known
    _, first, excess, limit, reference = best
    alarm = Alarm(t, AlarmKind.FRICTION_JUMP, Severity.WARNING,
                  f"local friction {reference + excess:.3f} between {edges[first]:.0f} and "
                  f"{edges[first + width]:.0f} m MD, {excess:.3f} above the rest of the profile "
                  "(tight spot or cuttings bed?)", reference + excess, reference + limit)
    return alarm, known | frozenset(range(first, first + width))


def _candidates(mu: np.ndarray, touched: np.ndarray, starts: list[int], width: int,
                min_step: float) -> list[int]:
    """The stretches of `profile_anomaly` that may stand more than ``min_step`` above the rest
    (and leave at least ``width`` touched bins outside), in order.

    The contrast of every stretch from running sums, in a few array operations: it differs
    from the exact contrast (`profile_anomaly` computes it again for those kept) by rounding
    only, at most a few ``n eps`` of the summed friction, so a stretch is dropped only when
    it lies below ``min_step`` by far more than that, where the exact test would drop it too.
    A profile of a hundred bins has a hundred candidate stretches and few above ``min_step``:
    one NumPy product per stretch cost more than the rest of the per-window profile work.
    """
    n = mu.size
    values = np.where(touched, mu, 0.0)
    prefix = np.concatenate(([0.0], np.cumsum(values)))
    counts = np.concatenate(([0], np.cumsum(touched)))
    first = np.asarray(starts, dtype=np.int64)
    lo, hi = np.maximum(first - 1, 0), np.minimum(first + width + 1, n)
    rest_count = counts[n] - (counts[hi] - counts[lo])
    slack = 64.0 * (n + 2) * np.finfo(np.float64).eps * (1.0 + float(np.abs(values).sum()))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        contrast = ((prefix[first + width] - prefix[first]) / width
                    - (prefix[n] - (prefix[hi] - prefix[lo])) / rest_count)
        below = contrast < min_step - slack  # NaN (overflowing sums) is never dropped
    kept: list[int] = first[(rest_count >= width) & ~below].tolist()
    return kept


# -- sensors --------------------------------------------------------------------------------

@dataclass(frozen=True)
class SensorSettings:
    """Plausibility settings: hook-load range [N], depth tolerance [m], and how long a depth
    inconsistency must last (hole-depth channels are coarse and noisy) [s]. Frozen channels
    are judged by the rig-state detector (`tdmon.calib.rigstate`, `tdmon.calib.frozen`), which
    knows the neighbours that say a channel must move."""

    max_hookload: float = 10e6
    depth_tolerance: float = 5.0
    persist_time: float = 60.0


_NONE: frozenset[str] = frozenset()
_NO_CONDITIONS: frozenset[AlarmKind] = frozenset()


@dataclass(frozen=True, slots=True)
class SensorState:
    """Channels reported stale, those named by a gap's alarm and not heard from since, the
    sensor alarm kinds whose condition holds (an alarm is raised when its condition starts),
    and since when the bit has been below the hole depth."""

    stale: frozenset[str] = _NONE
    announced: frozenset[str] = _NONE
    active: frozenset[AlarmKind] = _NO_CONDITIONS
    below_since: float | None = None


def stale_gap_alarm(gap: tuple[tuple[str, float], ...], resumed: float | None = None) -> Alarm:
    """The one ``sensor_stale`` alarm of a silence of the whole stream.

    Parameters
    ----------
    gap : the channels that went stale (the hook load first) and when each did [s]
    resumed : when the data came back [s] (None: still silent)

    Returns
    -------
    Alarm stamped when the first channel went stale; ``value`` how long they stayed stale [s]
    (None while the silence lasts)
    """
    since = min(when for _, when in gap)
    names = [channel for channel, _ in gap]
    listed = ", ".join(names[:1] + sorted(names[1:]))
    if resumed is None:
        text = (f"{len(names)} channels went stale together, no data since: {listed}"
                if len(names) > 1 else f"channel {names[0]} went stale, no data since")
        return Alarm(since, AlarmKind.SENSOR_STALE, Severity.WARNING, text)
    text = (f"{len(names)} channels went stale together, for {resumed - since:.0f} s until data "
            f"resumed: {listed}" if len(names) > 1
            else f"channel {names[0]} went stale, for {resumed - since:.0f} s until it resumed")
    return Alarm(since, AlarmKind.SENSOR_STALE, Severity.WARNING, text, resumed - since)


def frozen_alarm(t: float, frozen: FrozenChannel) -> Alarm:
    """The ``sensor_<channel>_frozen`` alarm of a channel the rig-state detector judged frozen:
    which channel, the value it repeats, for how long, why (its neighbours) and what the
    daemon does without it."""
    channel = frozen.channel
    kind = FROZEN_ALARM_KINDS[channel]
    return Alarm(t, kind, Severity.WARNING,
                 f"{channel} reads {shown(channel, frozen.value)} unchanged for "
                 f"{t - frozen.since:.0f} s {frozen.reason}; {WITHOUT_CHANNEL[channel]}",
                 frozen.value, None)


def sensor_alarms(state: SensorState, t: float, values: dict[str, float],  # noqa: C901  (complex today; simplify when next touched)
                  stale: tuple[str, ...], frozen: tuple[FrozenChannel, ...],
                  settings: SensorSettings, gap: tuple[tuple[str, float], ...] = (),
                  gap_reported: bool = False) -> tuple[SensorState, list[Alarm]]:
    """Stale, implausible and frozen channels; one alarm when a condition starts.

    Parameters
    ----------
    state : prior
    t : [s]
    values : channel values of this frame (SI)
    stale : channels the aligner reports as too old
    frozen : channels the rig-state detector judges frozen on this frame
        (`tdmon.calib.rigstate.Detection.frozen`): each raises its ``sensor_<channel>_frozen``
        alarm once, until it moves again
    settings : thresholds
    gap : channels that went stale in a silence of the whole stream ending at this frame, and
        when each did [s] (the aligner's ``Frame.gap``): one alarm names them all, stamped when
        they went stale; they are not reported again until they have been heard from
    gap_reported : the daemon raised the gap's alarm while it lasted (live): only remember
        its channels

    Notes
    -----
    A stream that stops delivers no frame: a replay sees the silence when the data resume, and
    the alarm carries the time the channels went stale, not the time they came back; a live
    daemon raises it while the silence lasts (``Aligner.silence``) and passes ``gap_reported``.
    """
    alarms: list[Alarm] = []
    # once per frame: the sets are built only when a channel is stale or was announced
    new_stale = frozenset(stale) if stale else _NONE
    announced = state.announced
    if gap:
        if not gap_reported:
            alarms.append(stale_gap_alarm(gap, t))
        announced = announced | frozenset(channel for channel, _ in gap)
    if announced:
        announced = announced - frozenset(values)  # heard from again
    started = new_stale - state.stale - announced if new_stale else _NONE
    if started:
        for channel in sorted(started):
            alarms.append(Alarm(t, AlarmKind.SENSOR_STALE, Severity.WARNING,
                                f"channel {channel} is stale"))
    conditions: set[AlarmKind] = set()
    hookload = values.get("hookload")
    if hookload is not None and (not math.isfinite(hookload) or hookload < 0.0
                                 or hookload > settings.max_hookload):
        conditions.add(AlarmKind.SENSOR_HOOKLOAD_IMPLAUSIBLE)
    bit, hole = values.get("bit_depth"), values.get("hole_depth")
    below = (bit is not None and hole is not None and math.isfinite(bit) and math.isfinite(hole)
             and bit > hole + settings.depth_tolerance)
    below_since = (state.below_since if state.below_since is not None else t) if below else None
    if below_since is not None and t - below_since >= settings.persist_time:
        conditions.add(AlarmKind.SENSOR_BIT_BELOW_HOLE)
    records = {FROZEN_ALARM_KINDS[f.channel]: f for f in frozen}
    if records:
        conditions.update(records)
    # once per frame: no set arithmetic and no new frozenset while no condition holds
    active = frozenset(conditions) if conditions else _NO_CONDITIONS
    new_conditions = active - state.active if active else _NO_CONDITIONS
    # sorted by name: the order the alarms of one frame are raised in
    for condition in sorted(new_conditions):
        if condition in records:
            alarms.append(frozen_alarm(t, records[condition]))
        elif condition == AlarmKind.SENSOR_HOOKLOAD_IMPLAUSIBLE:
            alarms.append(Alarm(t, condition, Severity.CRITICAL,
                                "hook load is negative or implausibly large", hookload,
                                settings.max_hookload))
        else:
            alarms.append(Alarm(t, condition, Severity.WARNING,
                                "bit depth is below the hole depth", bit, hole))
    # built directly, positionally in the order of the fields: dataclasses.replace on every
    # frame cost more than the checks, and the keywords a third of the construction
    new_state = SensorState(new_stale, announced, active, below_since)
    return new_state, alarms
