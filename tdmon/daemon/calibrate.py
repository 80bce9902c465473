"""Daemon steps around the pure estimators of `tdmon.calib`.

Three steps, in this order in the pipeline (see docs/back-calculation.md):

1. :class:`RigStateStep` replaces ``SimpleRigState``: sets ``frame.state`` and ``frame.steady``
   and emits ``state``.
2. ``MonitorStep`` (unchanged) emits ``model`` for the frame.
3. :class:`CalibrationStep` builds steady windows and, per window, emits ``estimate`` messages
   (kinds ``window``, ``profile``, ``mu_T``) and the window-level alarms (limits, friction
   jump, rejected windows, block weight, weight check).
4. :class:`AlarmStep` emits the per-frame alarms: hook load trending out of the monitor's band,
   stale and implausible sensors.

Frame fields read: ``values["hookload"]`` [N], ``values["bit_depth"]`` [m], and when present
``values["block_position"]`` [m], ``values["rpm"]`` [rad/s], ``values["flow_in"]`` [m3/s],
``values["spp"]`` [Pa], ``values["hole_depth"]`` [m], ``values["torque"]`` [N m],
``values["wob"]`` [N]; ``frame.ages`` (when each channel was sampled: velocities use the
channel's own times);
``frame.stale``; ``frame.results["model"]`` (from the monitor) for the band alarm.
Everything emitted is finite: a value that is not is left out or the message is not sent.
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.alarms import (
    Alarm,
    BandSettings,
    BandTrendState,
    JumpSettings,
    SensorSettings,
    SensorState,
    friction_jump,
    limit_alarms,
    profile_anomaly,
    sensor_alarms,
    update_band_trend,
)
from tdmon.calib.backcalc import FrictionEstimate, back_calculate_window, shoe_depth
from tdmon.calib.blockweight import BlockWeightTracker, BuoyancyCheck, buoyancy_check
from tdmon.calib.mu_calibration import MuTCalibrator
from tdmon.calib.profile import FrictionProfile
from tdmon.calib.rigstate import (
    MOVING_STATES,
    Detection,
    DetectorState,
    RigSample,
    RigStateThresholds,
    detect,
)
from tdmon.calib.windows import Window, WindowAccumulator, WindowSettings, add_sample, close
from tdmon.daemon.pipeline import Emit, Frame
from tdmon.errors import FitError, ModelError
from tdmon.model.friction import FrictionModel
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid

log = logging.getLogger(__name__)

__all__ = ["AlarmStep", "CalibrationSettings", "CalibrationStep", "ProfileStep", "RigStateStep"]


def _value(values: dict[str, float], name: str) -> float | None:
    value = values.get(name)
    return float(value) if value is not None and math.isfinite(value) else None


def _sampled_at(frame: Frame, channel: str) -> float | None:
    age = frame.ages.get(channel)
    return frame.t - age if age is not None and math.isfinite(age) else None


#: Frame channels of a RigSample, in the order of its fields after ``t``.
_SAMPLE_CHANNELS = ("hookload", "bit_depth", "block_position", "rpm", "flow_in", "spp",
                    "hole_depth", "torque", "wob")


def _sample(frame: Frame) -> RigSample:
    # once per frame: one comprehension and positional arguments rather than a helper call
    # and a keyword per channel
    hookload, bit_depth, block_position, rpm, flow, spp, hole_depth, torque, wob = [
        float(x) if x is not None and math.isfinite(x) else None
        for x in map(frame.values.get, _SAMPLE_CHANNELS)]
    return RigSample(frame.t, hookload, bit_depth, block_position, rpm, flow, spp, hole_depth,
                     torque, wob, _sampled_at(frame, "block_position"),
                     _sampled_at(frame, "bit_depth"))


class RigStateStep:
    """Step: rig state and steadiness of every frame; ``state`` on a change or every ``every`` s.

    The last sample and detection stay readable (``last_sample``, ``last_detection``) for the
    calibration step, which runs after it on the same frame.
    """

    name = "rig_state"

    def __init__(self, thresholds: RigStateThresholds | None = None, every: float = 1.0) -> None:
        self.thresholds = thresholds or RigStateThresholds()
        self.every = every
        self.detector = DetectorState()
        self.last_sample: RigSample | None = None
        self.last_detection: Detection | None = None
        self._last_sent: tuple[str, bool] | None = None
        self._last_sent_t = -math.inf

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        sample = _sample(frame)
        self.detector, detection = detect(self.detector, sample, self.thresholds)
        self.last_sample, self.last_detection = sample, detection
        frame.state, frame.steady = detection.state, detection.steady
        key = (detection.state, detection.steady)
        if key != self._last_sent or frame.t - self._last_sent_t >= self.every:
            self._last_sent, self._last_sent_t = key, frame.t
            emit("state", {"t": frame.t, "state": detection.state,
                           "steady": bool(detection.steady), "bit_depth_m": sample.bit_depth})

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of the calibration step (SI).

    Attributes
    ----------
    windows : window building and checking
    method : torque-and-drag method of the back-calculation
    bracket : friction range of the root solve [-]
    min_open_length : string below the shoe needed to solve open-hole friction [m]
    profile_bin : depth-bin length of the friction profile [m]
    prior_mu, prior_std : prior friction per bin [-]
    process_std : drift per window of the profile and mu(T) filters [-]
    mu_t_mode : ``"family"`` or ``"scale"`` (when a mu(T) law and temperatures are given)
    limit_warn : utilisation that raises a limit warning [-]
    jump : friction-jump settings
    learn_block_weight : feed the in-slips block weight back into the rig-state threshold
    block_weight_tolerance : relative deviation from the configured block weight reported [-]
    """

    windows: WindowSettings = field(default_factory=WindowSettings)
    method: str = "soft-string"
    bracket: tuple[float, float] = (0.0, 1.0)
    min_open_length: float = 30.0
    profile_bin: float = 30.0
    prior_mu: float = 0.25
    prior_std: float = 0.1
    process_std: float = 0.002
    mu_t_mode: str = "family"
    limit_warn: float = 0.8
    jump: JumpSettings = field(default_factory=JumpSettings)
    learn_block_weight: bool = True
    block_weight_tolerance: float = 0.05


class CalibrationStep:
    """Step: windows, per-window friction, profile, mu(T), window-level alarms.

    Parameters
    ----------
    model : the prepared well
    rig_state : the rig-state step that runs before this one
    settings : calibration settings
    temperature : annulus temperature per hole-grid element [degC] (enables mu(T))
    friction_law : configured mu(T) (family mode) or lab fit (scale mode)
    """

    name = "calibrate"

    def __init__(self, model: WellModel, rig_state: RigStateStep,
                 settings: CalibrationSettings | None = None, *,
                 temperature: NDArray[np.float64] | None = None,
                 friction_law: FrictionModel | None = None,
                 mu_t_mask: NDArray[np.bool_] | None = None,
                 mu_t_base: float | NDArray[np.float64] = 0.0,
                 mu_t_prior_std: Sequence[float] | None = None) -> None:
        self.model = model
        self.rig_state = rig_state
        self.settings = settings or CalibrationSettings()
        s = self.settings
        self.accumulator = WindowAccumulator()
        self.block_weight = BlockWeightTracker()
        self.profile = FrictionProfile(model, bin_length=s.profile_bin, prior_mu=s.prior_mu,
                                       prior_std=s.prior_std, process_std=s.process_std,
                                       method=s.method)
        self.mu_t: MuTCalibrator | None = None
        if temperature is not None and friction_law is not None:
            self.mu_t = MuTCalibrator(model, temperature, friction_law, mode=s.mu_t_mode,
                                      method=s.method, mask=mu_t_mask, base_mu=mu_t_base,
                                      prior_std=mu_t_prior_std)
        #: incremented whenever the local friction profile takes a window (ProfileStep)
        self.profile_updates = 0
        self.shoe = shoe_depth(model)
        self.mu_cased: dict[str, tuple[float, float]] = {}  # state -> (sum w mu, sum w)
        self._cased_count: Counter[str] = Counter()
        self._pending: dict[str, list[Window]] = {}
        self.history: dict[str, tuple[float, ...]] = {}
        self.estimates: list[FrictionEstimate] = []
        self.rejected: Counter[str] = Counter()
        self._active_limits: set[str] = set()
        self._anomalous_bins: frozenset[int] = frozenset()
        self._air_model: WellModel | None = None
        self._block_alarmed = False
        self._weight_off = 0
        self.weight_checks: list[BuoyancyCheck] = []

    # -- frames ---------------------------------------------------------------------------

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        sample, detection = self.rig_state.last_sample, self.rig_state.last_detection
        if sample is None or detection is None or sample.t != frame.t:
            return
        if detection.state == "in_slips" and detection.steady and sample.hookload is not None:
            self._learn_block_weight(frame.t, sample.hookload, emit)
        self.accumulator, window = add_sample(self.accumulator, sample, detection,
                                              self.settings.windows)
        if window is not None:
            self.on_window(window, emit)

    def close(self, emit: Emit) -> None:
        self.accumulator, window = close(self.accumulator, self.settings.windows)
        if window is not None:
            self.on_window(window, emit)

    # -- windows --------------------------------------------------------------------------

    def on_window(self, window: Window, emit: Emit) -> None:
        """Everything one closed window gives."""
        if window.rejected is not None:
            self.rejected[window.rejected.split(":")[0]] += 1
            if not window.rejected.startswith("too_few"):
                self._alarm(emit, Alarm(window.t_end, "window_rejected", "info",
                                        f"{window.state} window rejected: {window.rejected}"))
            return
        if window.state in ("static", "circulating", "rotating_off_bottom"):
            self._weight_check(window, emit)
        if window.state not in ("pick_up", "slack_off", "rotating_off_bottom", "reaming",
                                "back_reaming"):
            return
        try:
            estimate = back_calculate_window(
                self.model, window, mu_cased=self._cased(window.state),
                min_open_length=self.settings.min_open_length, bracket=self.settings.bracket,
                method=self.settings.method)
        except FitError as exc:
            self.rejected["not_bracketed"] += 1
            self._alarm(emit, Alarm(window.t_end, "window_rejected", "info",
                                    f"{window.state} window at {window.bit_depth:.0f} m: {exc}"))
            return
        self.estimates.append(estimate)
        emit("estimate", self._window_message(window, estimate))
        if window.state in ("reaming", "back_reaming"):
            return  # combined motion: not a reference for the cased value, profile or mu(T)
        if estimate.section in ("cased", "all") and window.bit_depth <= self.shoe:
            total, weight = self.mu_cased.get(window.state, (0.0, 0.0))
            w = 1.0 / max(estimate.mu_std, 1e-4) ** 2
            self.mu_cased[window.state] = (total + w * estimate.mu, weight + w)
            self._cased_count[window.state] += 1
            self._revise(window.state, emit)
        elif (estimate.section == "all"
              and window.bit_depth > self.shoe + self.settings.min_open_length
              and self.shoe > 0.0):
            # tripping out from below the shoe: open-hole friction needs the cased value,
            # known only once the bit is inside casing; these windows are solved again then
            self._pending.setdefault(window.state, []).append(window)
            del self._pending[window.state][:-500]
        self._jump(window, estimate, emit)
        self._limits(window, estimate, emit)
        if self.profile.add_window(window):
            self.profile_updates += 1
            emit("estimate", self._profile_message(window))
            alarm, self._anomalous_bins = profile_anomaly(
                window.t_end, self.profile.grid.edges, self.profile.state.mu,
                self.profile.state.covariance, self.settings.prior_std, self.settings.jump,
                known=self._anomalous_bins)
            if alarm is not None:
                self._alarm(emit, alarm)
        if self.mu_t is not None and self.mu_t.add_window(window):
            fields = self.mu_t.message_fields()
            if math.isfinite(float(fields["mu"])):  # type: ignore[arg-type]
                emit("estimate", {"t": window.t_end, "kind": "mu_T",
                                  "operation": estimate.operation, **fields})

    def _revise(self, state: str, emit: Emit) -> None:
        """Solve the open-hole friction of earlier deep windows once cased friction is known."""
        pending = self._pending.get(state)
        mu_cased = self._cased(state)
        if not pending or mu_cased is None or self._cased_count[state] < 3:
            return
        self._pending[state] = []
        for window in pending:
            try:
                estimate = back_calculate_window(
                    self.model, window, mu_cased=mu_cased,
                    min_open_length=self.settings.min_open_length,
                    bracket=self.settings.bracket, method=self.settings.method)
            except FitError:
                self.rejected["not_bracketed"] += 1
                continue
            self.estimates.append(estimate)
            emit("estimate", {**self._window_message(window, estimate), "revised": True,
                              "mu_cased": mu_cased})

    def _cased(self, state: str) -> float | None:
        total, weight = self.mu_cased.get(state, (0.0, 0.0))
        return total / weight if weight > 0 else None

    def _window_message(self, window: Window, estimate: FrictionEstimate) -> dict[str, Any]:
        operation = (window.state if window.state in ("reaming", "back_reaming")
                     else estimate.operation)
        message: dict[str, Any] = {
            "t": window.t_end, "kind": "window", "operation": operation,
            "mu": estimate.mu, "mu_std": estimate.mu_std, "bit_depth_m": window.bit_depth,
            "section": estimate.section, "samples": window.n, "t_start": window.t_start,
            "low_confidence": bool(window.low_confidence), "flags": list(window.flags),
            "measured": estimate.measured, "measured_se": estimate.measured_se,
            "quantity": estimate.quantity,
        }
        bw = self.block_weight.estimate
        if bw is not None:
            message["block_weight_N"] = bw.value
        return message

    def _profile_message(self, window: Window) -> dict[str, Any]:
        fields = self.profile.message_fields()
        grid = self.profile.grid
        k = int(np.clip(np.searchsorted(grid.edges, window.bit_depth) - 1, 0, grid.n_bins - 1))
        operation = window.state if window.state != "rotating_off_bottom" else "rotating"
        return {"t": window.t_end, "kind": "profile", "operation": operation,
                "mu": float(self.profile.state.mu[k]),
                "mu_std": float(self.profile.state.std[k]), "bit_depth_m": window.bit_depth,
                **fields}

    # -- alarms ---------------------------------------------------------------------------

    def _alarm(self, emit: Emit, alarm: Alarm) -> None:
        emit("alarm", alarm.to_message())

    def _jump(self, window: Window, estimate: FrictionEstimate, emit: Emit) -> None:
        history = self.history.get(window.state, ())
        alarm = friction_jump(history, estimate.mu, estimate.mu_std, window.t_end,
                              self.settings.jump, operation=estimate.operation,
                              bit_depth=window.bit_depth)
        if alarm is not None:
            self._alarm(emit, alarm)
        self.history[window.state] = (*history, estimate.mu)[-self.settings.jump.history:]

    def _limits(self, window: Window, estimate: FrictionEstimate, emit: Emit) -> None:
        try:
            loads = self.model.loads(window.bit_depth, self._friction_of(estimate),
                                     method=self.settings.method)
            alarms = limit_alarms(self.model.well, loads, estimate.operation, window.t_end,
                                  warn=self.settings.limit_warn)
        except (ModelError, ValueError) as exc:
            log.debug("no limit check at %.0f m: %s", window.bit_depth, exc)
            return
        kinds = {a.kind for a in alarms}
        for alarm in alarms:
            if alarm.kind not in self._active_limits:
                self._alarm(emit, alarm)
        self._active_limits = kinds

    def _friction_of(self, estimate: FrictionEstimate) -> NDArray[np.float64]:
        kind = self.model.grid.element_kind
        if estimate.section == "open":
            cased = self._cased("pick_up" if estimate.operation == "pick_up" else "slack_off")
            return np.where(kind == "open", estimate.mu, cased if cased is not None
                            else estimate.mu)
        return np.full(self.model.n_elements, estimate.mu)

    def _learn_block_weight(self, t: float, hookload: float, emit: Emit) -> None:
        estimate = self.block_weight.add(hookload)
        if estimate is None or estimate.n < 20 or not self.settings.learn_block_weight:
            return
        configured = self.model.well.block_weight
        thresholds = self.rig_state.thresholds
        if thresholds.block_weight != estimate.value:  # the running median often stays put
            self.rig_state.thresholds = replace(thresholds, block_weight=estimate.value)
        if (configured > 0 and not self._block_alarmed
                and abs(estimate.value - configured) > self.settings.block_weight_tolerance
                * configured):
            self._block_alarmed = True
            self._alarm(emit, Alarm(t, "block_weight", "info",
                                    f"block weight from in-slips periods {estimate.value / 1e3:.0f}"
                                    f" kN differs from the configured {configured / 1e3:.0f} kN",
                                    estimate.value, configured))

    def _weight_check(self, window: Window, emit: Emit) -> None:
        estimate = self.block_weight.estimate
        block = estimate.value if estimate is not None else self.model.well.block_weight
        try:
            if self._air_model is None:
                well = self.model.well
                self._air_model = WellModel(replace(well, fluid=Fluid(0.0)))
            modelled = self.model.evaluate("static", window.bit_depth, 0.0)[0]
            in_air = self._air_model.evaluate("static", window.bit_depth, 0.0)[0]
            check = buoyancy_check(window.hookload, block, modelled, in_air,
                                   self.model.well.block_weight)
        except (FitError, ModelError):
            return
        self.weight_checks.append(check)
        off = abs(check.ratio - 1.0) > self.settings.block_weight_tolerance
        # static hangs keep part of the last pull's or run's drag locked in: one odd hang is
        # not news, three in a row are; reported once until the weights agree again
        self._weight_off = self._weight_off + 1 if off else 0
        if self._weight_off != 3 or not math.isfinite(check.ratio):
            return
        buoyed_given = abs(in_air - modelled) < 1e-6 * max(abs(modelled), 1.0)
        density = ("" if buoyed_given or not math.isfinite(check.fluid_density)
                   else f" (implied fluid density {check.fluid_density:.0f} kg/m3)")
        self._alarm(emit, Alarm(
            window.t_end, "weight_check", "info",
            f"{window.state} string weight at {window.bit_depth:.0f} m is "
            f"{100 * check.ratio:.0f} % of the model's for three hangs in a row{density}",
            check.measured_weight, check.modelled_weight))


class AlarmStep:
    """Step: per-frame alarms (band trend from the monitor's ``model`` message, sensors)."""

    name = "alarms"

    def __init__(self, band: BandSettings | None = None, sensors: SensorSettings | None = None,
                 windows: WindowSettings | None = None) -> None:
        self.band = band or BandSettings()
        self.sensors = sensors or SensorSettings()
        self.windows = windows or WindowSettings()
        self.trend: dict[str, BandTrendState] = {}
        self.sensor_state = SensorState()

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        rig_state = frame.state
        self.sensor_state, alarms = sensor_alarms(
            self.sensor_state, frame.t, frame.values, frame.stale,
            rig_state in MOVING_STATES, self.sensors)
        for sensor_alarm in alarms:
            emit("alarm", sensor_alarm.to_message())
        if not frame.steady or rig_state not in ("pick_up", "slack_off"):
            return
        model = frame.results.get("model")
        hookload = _value(frame.values, "hookload")
        if model is None or hookload is None:
            return
        band = model.get("band", {})
        curve = band.get("pick_up_N" if rig_state == "pick_up" else "slack_off_N") or []
        values = [float(x) for x in curve if x is not None and math.isfinite(x)]
        if not values:
            return
        noise = max(self.windows.noise_floor, self.windows.noise_floor_fraction * hookload)
        state = self.trend.get(rig_state)
        if state is None:
            state = BandTrendState()
        state, alarm = update_band_trend(state, frame.t, hookload, min(values), max(values),
                                         noise, self.band, what=f"{rig_state} hook load")
        self.trend[rig_state] = state
        if alarm is not None:
            emit("alarm", alarm.to_message())

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""


class ProfileStep:
    """Step: the well's trajectory and its profiles along MD for the 3D and profile views.

    On the first frame it emits ``well`` (the hole grid's nodes: ``md_m``, ``tvd_m``,
    ``north_m``, ``east_m``), a ``profile`` (``temperature_C`` of the annulus when the well file
    has a temperature model, and the friction: the calibration's local profile when one runs,
    else the well file's friction); the ``well`` message's ``notes`` say why the mu(T)
    calibration is off when it is. Afterwards a ``profile`` follows whenever the calibration's
    friction profile has changed, at most every ``interval`` seconds of rig time, and once
    more at the end.
    Both are stamped with the frame's time, not the wall clock, so that a replay keeps one time
    axis and gives the same messages at any speed.

    Parameters
    ----------
    well_message : the ``well`` message without ``t``
    md : MD of the profile points [m]
    element_index : hole-grid element of each profile point
    temperature : annulus temperature per hole-grid element [degC], or None
    friction : the well file's friction per element [-], or None
    calibration : the calibration step whose profile is reported, or None
    interval : shortest time between two ``profile`` messages [s]
    mu_t_note : why the mu(T) calibration is off (None: it runs, or there is nothing to say)
    """

    name = "profile"

    def __init__(self, well_message: dict[str, Any], md: NDArray[np.float64],
                 element_index: NDArray[np.int64], *,
                 temperature: NDArray[np.float64] | None = None,
                 friction: NDArray[np.float64] | None = None,
                 calibration: CalibrationStep | None = None, interval: float = 30.0,
                 mu_t_note: str | None = None) -> None:
        self.well_message = well_message
        self.md = np.asarray(md, dtype=np.float64)
        self.element_index = np.asarray(element_index, dtype=np.int64)
        self.temperature = temperature
        self.friction = friction
        self.calibration = calibration
        self.interval = interval
        self.mu_t_note = mu_t_note
        self._started = False
        self._sent_updates = 0
        self._sent_t = -math.inf
        self._last_t: float | None = None

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        self._last_t = frame.t
        if not self._started:
            self._started = True
            # the note rides on the start-up message rather than an alarm: nothing is wrong
            # on the rig, and dashboards read the well message once anyway
            notes = [] if self.mu_t_note is None else [self.mu_t_note]
            emit("well", {"t": frame.t, **self.well_message, "notes": notes})
            self._send(frame.t, emit)
            return
        calibration = self.calibration
        if (calibration is not None and calibration.profile_updates != self._sent_updates
                and frame.t - self._sent_t >= self.interval):
            self._send(frame.t, emit)

    def close(self, emit: Emit) -> None:
        calibration = self.calibration
        if (self._last_t is not None and calibration is not None
                and calibration.profile_updates != self._sent_updates):
            self._send(self._last_t, emit)

    def message(self, t: float) -> dict[str, Any] | None:
        """The ``profile`` message now (None when there is nothing to show)."""
        message: dict[str, Any] = {"t": t, "md_m": self.md.tolist()}
        if self.temperature is not None:
            message["temperature_C"] = self.temperature[self.element_index].tolist()
        if self.calibration is not None:
            profile = self.calibration.profile
            bins = profile.grid.element_bin[self.element_index]
            message["mu"] = profile.state.mu[bins].tolist()
            message["mu_std"] = profile.state.std[bins].tolist()
        elif self.friction is not None:
            message["mu"] = self.friction[self.element_index].tolist()
        if "mu" not in message and "temperature_C" not in message:
            return None
        # a non-finite value would be written as null and break the arrays' number schema
        if not all(np.isfinite(message[key]).all() for key in ("temperature_C", "mu", "mu_std")
                   if key in message):
            return None
        return message

    def _send(self, t: float, emit: Emit) -> None:
        if self.calibration is not None:
            self._sent_updates = self.calibration.profile_updates
        self._sent_t = t
        message = self.message(t)
        if message is not None:
            emit("profile", message)
