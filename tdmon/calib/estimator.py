"""The friction estimator: what the calibration decides, as pure updates of a frozen state.

:class:`FrictionEstimator` holds what does not change (the prepared well, the settings, the
shoe depth); :class:`EstimatorState` (`tdmon.calib.estimator_state`) holds what does: the window
being built, the block weight from the in-slips samples, the cased-hole friction so far, the
deep windows waiting for it, the alarms' memory and the friction-profile and mu(T) filters.
Two updates, each ``(state, input) -> (state, outputs)``, as filterpy's ``update``:

- :meth:`FrictionEstimator.add_sample`, per detected sample: the block weight learnt from steady
  in-slips samples (and its alarm), and the window being built; a window that closes goes
  through `update` at once.
- :meth:`FrictionEstimator.update`, per window: rejected windows and those resting on a channel
  judged frozen (`Window.suspect`: fed to no estimate), the weight check of static
  hangs (:mod:`tdmon.calib.weightcheck`), the friction of the window (`back_calculate_window`
  with the cased friction found so far), the cased friction's inverse-variance weighted mean
  and the deep windows solved again once it is known (:mod:`tdmon.calib.cased`), the
  friction-jump and load-limit alarms, and the windows fed to the friction profile and the
  mu(T) calibration.

Outputs are :class:`Output` pairs (``estimate`` and ``alarm`` messages as plain dicts) in the
order they are to be sent: nothing is emitted, logged or written here. The daemon's steps
(`tdmon.daemon.steps`) adapt this in a few lines. See docs/back-calculation.md.

The two filters are objects (:class:`~tdmon.calib.profile.FrictionProfile`,
:class:`~tdmon.calib.mu_calibration.MuTCalibrator`) used as values: once in a state they are
never changed; a window updates a shallow copy (their ``add_window`` rebinds their ``state``,
it does not change arrays in place).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from statistics import median
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.alarms import Alarm, friction_jump, limit_alarms, profile_anomaly
from tdmon.calib.backcalc import FrictionEstimate, back_calculate_window, shoe_depth
from tdmon.calib.blockweight import BlockWeightWindow, add_block_weight
from tdmon.calib.cased import CasedFriction, add_cased, wait_for_cased
from tdmon.calib.drilling import DrillingState, drilling_friction, track
from tdmon.calib.estimator_state import (
    CalibrationSettings,
    EstimatorState,
    Output,
    SampleState,
    WindowState,
    count,
    put,
)
from tdmon.calib.joint import (
    PAIR_CORRELATION,
    JointState,
    for_rig,
    initial_joint,
    joint_fields,
    mean_and_covariance,
    sensor_estimate,
    slips_measurement,
    update_joint,
    update_joint_slips,
)
from tdmon.calib.measurement import Resolution, SensorEstimate, corrected_window, resolution
from tdmon.calib.mismatch import mismatch_alarm, weight_difference
from tdmon.calib.mu_calibration import MuTCalibrator
from tdmon.calib.parameters import BLOCK_WEIGHT, FRICTION_AND_WEIGHT, HOOKLOAD_OFFSET
from tdmon.calib.profile import FrictionProfile
from tdmon.calib.rigstate import Detection, RigSample
from tdmon.calib.scatter import Scatter, add_window, scatter_std
from tdmon.calib.slips import SlipsRun, add_slips_sample, close_run
from tdmon.calib.weightcheck import block_weight_alarm, weight_check
from tdmon.calib.windows import Window, add_sample, close
from tdmon.errors import FitError, ModelError
from tdmon.messages import estimate_message
from tdmon.model.friction import FrictionModel
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid
from tdmon.vocabulary import (
    OPERATION_FOR_STATE,
    REAMING_AXIAL_OPERATION,
    AlarmKind,
    EstimateKind,
    Operation,
    RigState,
    Severity,
)

__all__ = [
    "CalibrationSettings",
    "EstimatorState",
    "FrictionEstimator",
    "Output",
    "SampleState",
    "WindowState",
]

#: states whose steady windows check the string's weight (no axial friction)
WEIGHT_CHECK_STATES = frozenset({RigState.STATIC, RigState.CIRCULATING,
                                 RigState.ROTATING_OFF_BOTTOM})
#: states whose windows give a friction factor
ESTIMATED_STATES = frozenset({RigState.PICK_UP, RigState.SLACK_OFF, RigState.ROTATING_OFF_BOTTOM,
                              RigState.REAMING, RigState.BACK_REAMING})
#: steady in-slips samples before the learnt block weight is used and compared [-]
MIN_BLOCK_WEIGHT_SAMPLES = 20
#: the between-window scatter each estimated rig state feeds (named as the joint
#: estimate's measurement kinds)
#: the motion whose drag a later hang keeps in part (rotation off bottom releases it)
_MOTION: dict[str, str] = {
    RigState.PICK_UP: "pick_up", RigState.BACK_REAMING: "pick_up",
    RigState.SLACK_OFF: "slack_off", RigState.REAMING: "slack_off",
    RigState.ROTATING_OFF_BOTTOM: "rotating"}
_SCATTER_KIND = {RigState.PICK_UP: "pick_up", RigState.SLACK_OFF: "slack_off",
                 RigState.ROTATING_OFF_BOTTOM: "rotating_torque"}


def _mwd_sources(window: Window) -> dict[str, str | None]:
    """A drilling window estimate's ``wob_source`` and ``bit_torque_source`` where the MWD gave
    either (docs/drilling.md); without the MWD the message stays as it was before the MWD fed
    the windows (surface weight on bit, the tag's bit torque)."""
    if "downhole" not in (window.wob_source, window.bit_torque_source):
        return {}
    return {"wob_source": window.wob_source, "bit_torque_source": window.bit_torque_source}


def _alarm(alarm: Alarm) -> Output:
    return Output("alarm", alarm.to_message())


#: weight checks kept in the state (the rule itself needs only the count of odd ones)
_WEIGHT_CHECKS_KEPT = 500


@dataclass(frozen=True)
class FrictionEstimator:
    """The estimator's fixed part: the well and the settings.

    Parameters
    ----------
    model : the prepared well
    settings : estimator settings (a joint estimate left at its default parameters is fitted
        to the well's own hook-load sensor and block weight, `tdmon.calib.joint.for_rig`)
    """

    model: WellModel
    settings: CalibrationSettings = field(default_factory=CalibrationSettings)

    def __post_init__(self) -> None:
        joint = self.settings.joint
        if joint.parameters is FRICTION_AND_WEIGHT:
            object.__setattr__(self, "settings", replace(
                self.settings, joint=for_rig(joint, self.model.well)))

    @cached_property
    def shoe(self) -> float:
        """MD of the casing shoe [m] (0 without casing)."""
        return shoe_depth(self.model)

    @cached_property
    def air_model(self) -> WellModel | None:
        """The well with its fluid taken out, for the weight check (None: not buildable)."""
        try:
            return WellModel(replace(self.model.well, fluid=Fluid(0.0)))
        except ModelError:
            return None

    # -- state ----------------------------------------------------------------------------

    def initial_state(self, *, temperature: NDArray[np.float64] | None = None,
                      friction_law: FrictionModel | None = None,
                      mu_t_mask: NDArray[np.bool_] | None = None,
                      mu_t_base: float | NDArray[np.float64] = 0.0,
                      mu_t_prior_std: Sequence[float] | None = None) -> EstimatorState:
        """The state before any sample: prior profile, and mu(T) when a law is given.

        Parameters
        ----------
        temperature : annulus temperature per hole-grid element [degC] (enables mu(T))
        friction_law : the configured mu(T) (family mode) or the lab fit (scale mode)
        mu_t_mask : elements the law applies to (None: all)
        mu_t_base : friction of the other elements [-]
        mu_t_prior_std : prior spread of each parameter

        Raises
        ------
        FitError
            The mu(T) calibration cannot start (e.g. a law undefined at these temperatures).
        """
        s = self.settings
        profile = FrictionProfile(self.model, bin_length=s.profile_bin, prior_mu=s.prior_mu,
                                  prior_std=s.prior_std, process_std=s.process_std,
                                  method=s.method)
        mu_t = None
        if temperature is not None and friction_law is not None:
            mu_t = MuTCalibrator(self.model, temperature, friction_law, mode=s.mu_t_mode,
                                 method=s.method, mask=mu_t_mask, base_mu=mu_t_base,
                                 prior_std=mu_t_prior_std)
        return EstimatorState(SampleState(), WindowState(profile, mu_t,
                                                         joint=initial_joint(s.joint)))

    def learnt_block_weight(self, state: EstimatorState) -> float | None:
        """The block weight the rig-state detector should use [N] (None: keep its own)."""
        return self._learnt(state.samples.block_weight)

    def _learnt(self, block: BlockWeightWindow) -> float | None:
        # the in-slips median, once it rests on enough samples and learning is on (the
        # median alone: per sample, the estimate's spread is not needed)
        if len(block.ordered) < MIN_BLOCK_WEIGHT_SAMPLES or not self.settings.learn_block_weight:
            return None
        return block.median

    # -- samples --------------------------------------------------------------------------

    def add_sample(self, state: EstimatorState, sample: RigSample, detection: Detection
                   ) -> tuple[EstimatorState, tuple[Output, ...]]:
        """One detected sample: block weight in slips, the window being built.

        Parameters
        ----------
        state : the state so far
        sample : this sample
        detection : its rig state and steadiness

        Returns
        -------
        (EstimatorState, outputs)
        """
        samples = state.samples
        block = samples.block_weight
        outputs: tuple[Output, ...] = ()
        slips = samples.slips
        if detection.state == RigState.IN_SLIPS:
            slips = add_slips_sample(slips or SlipsRun(), sample, detection.steady)
        elif slips is not None:
            state, outputs = self._slips_done(state, slips, sample.t)
            slips = None
        if (detection.state == RigState.IN_SLIPS and detection.steady
                and sample.hookload is not None):
            block = add_block_weight(block, sample.hookload)
        accumulator, window = add_sample(samples.accumulator, sample, detection,
                                         self.settings.windows)
        drilling = self._track_drilling(samples.drilling, sample, detection)
        if (accumulator is samples.accumulator and block is samples.block_weight
                and window is None and slips is samples.slips
                and drilling is samples.drilling):
            return state, outputs
        state = EstimatorState(SampleState(accumulator, block, slips, drilling), state.windows)
        if window is None:
            return state, outputs
        if window.state == RigState.DRILLING and window.bit_torque is None:
            # no MWD torque at the bit on every sample: the torque step at the last tag
            window = replace(window, bit_torque=drilling.bit_torque,
                             bit_torque_source=None if drilling.bit_torque is None else "tag")
        state, more = self.update(state, window)
        return state, outputs + more

    def _track_drilling(self, prior: DrillingState, sample: RigSample, detection: Detection
                        ) -> DrillingState:
        """The tags and the bit torque of the last one after this sample (docs/drilling.md)."""
        state = detection.state
        if not (prior.drilling or state in (RigState.DRILLING, RigState.ROTATING_OFF_BOTTOM)
                or prior.off_bottom_samples):
            return prior  # tripping, in slips: nothing to follow
        change = 0.0
        settling = state == RigState.DRILLING and (
            not prior.drilling or sample.t - prior.since <= self.settings.tag_settle)
        if settling and sample.wob is not None and sample.bit_depth is not None:
            change = self._string_torque_change(sample.bit_depth, sample.wob)
        return track(prior, sample.t, state, detection.steady, sample.bit_depth,
                     sample.hole_depth, sample.hookload, sample.torque,
                     string_torque_change=change, settle=self.settings.tag_settle)

    def _string_torque_change(self, bit_depth: float, wob: float) -> float:
        """What ``wob`` [N] on the bit changes of the string's torque at ``bit_depth`` [m], at
        the prior friction [N m] (0 where the model does not reach)."""
        mu, method = self.settings.prior_mu, self.settings.method
        try:
            on = self.model.evaluate(Operation.ON_BOTTOM, bit_depth, mu, method=method,
                                     wob=wob)[1]
            off = self.model.evaluate(Operation.ROTATING, bit_depth, mu, method=method)[1]
        except ModelError:
            return 0.0
        return on - off

    def _slips_done(self, state: EstimatorState, run: SlipsRun, t: float
                    ) -> tuple[EstimatorState, tuple[Output, ...]]:
        """A connection ended: its in-slips readings to the joint estimate (the empty block's
        weight and the zero offset; with the block moving, the sheave factor), and the
        block-weight alarm when they show the block off the well file's."""
        w = state.windows
        if w.joint is None:
            return state, ()
        readings = tuple(slips_measurement(r.mean, r.se, r.motion)
                         for r in close_run(run, self.settings.windows.noise_floor))
        joint = update_joint_slips(w.joint, self.model, readings, t, self._block_of(
            state.samples.block_weight), self.settings.joint, self.settings.method)
        if joint is w.joint:
            return state, ()
        out: list[Output] = []
        alarmed = w.block_alarmed or self._block_alarm(joint, t, out)
        return (EstimatorState(state.samples, replace(w, joint=joint, block_alarmed=alarmed)),
                tuple(out))

    def _block_of(self, block: BlockWeightWindow) -> float:
        """The block weight where the joint estimate does not estimate it [N]: learnt in
        slips, else the well file's."""
        return block.estimate.value if block.estimate is not None else \
            self.model.well.block_weight

    def sensor(self, w: WindowState, block: BlockWeightWindow) -> SensorEstimate:
        """What is known now of the hook-load measurement (the joint estimate's block weight,
        offset and sheave efficiency; the prior's before it starts)."""
        joint = w.joint if w.joint is not None else initial_joint(self.settings.joint)
        return sensor_estimate(joint, self.settings.joint, self._block_of(block))

    def close(self, state: EstimatorState) -> tuple[EstimatorState, tuple[Output, ...]]:
        """End of input: the connection in slips and the window being built are closed and
        used."""
        outputs: tuple[Output, ...] = ()
        if state.samples.slips is not None:
            state, outputs = self._slips_done(state, state.samples.slips,
                                              state.samples.slips.t)
        samples = state.samples
        accumulator, window = close(samples.accumulator, self.settings.windows)
        state = EstimatorState(replace(samples, accumulator=accumulator, slips=None),
                               state.windows)
        if window is None:
            return state, outputs
        state, more = self.update(state, window)
        return state, outputs + more

    # -- windows --------------------------------------------------------------------------

    def update(self, state: EstimatorState, window: Window
               ) -> tuple[EstimatorState, tuple[Output, ...]]:
        """Everything one closed window gives.

        Parameters
        ----------
        state : the state so far
        window : a closed window

        Returns
        -------
        (EstimatorState, outputs)
        """
        windows, outputs = self._update(state.windows, state.samples.block_weight, window)
        if window.rejected is None and not window.suspect and window.state in _MOTION:
            motion = _MOTION[window.state]
            if motion != windows.last_motion:
                windows = replace(windows, last_motion=motion)
        return EstimatorState(state.samples, windows), tuple(outputs)

    def _update(self, w: WindowState, block: BlockWeightWindow, window: Window
                ) -> tuple[WindowState, list[Output]]:
        out: list[Output] = []
        if window.suspect:
            # resting on a channel judged frozen (its alarm says which and why): fed to no
            # estimate, counted only
            return replace(w, rejected=count(w.rejected, "suspect_channel")), out
        if window.rejected is not None:
            w = replace(w, rejected=count(w.rejected, window.rejected.split(":")[0]))
            if not window.rejected.startswith("too_few"):
                out.append(_alarm(Alarm(window.t_end, AlarmKind.WINDOW_REJECTED, Severity.INFO,
                                        f"{window.state} window rejected: {window.rejected}")))
            return w, out
        # the window as the model's own hook load: read through what is known of the sensor
        # (the joint estimate takes the reading itself, with the measurement in its model)
        sensor = self.sensor(w, block)
        corrected = corrected_window(window, sensor, self.model.well.block_weight)
        if window.state in WEIGHT_CHECK_STATES:
            w = self._weight_check(w, corrected, out)
        if window.state == RigState.DRILLING:
            w = self._joint(w, block, window, sensor, out)
            return self._drilling_window(w, window, out), out
        if window.state not in ESTIMATED_STATES:
            return self._joint(w, block, window, sensor, out), out
        try:
            estimate = self._solve(corrected, w.mu_cased(window.state))
        except FitError as exc:
            out.append(_alarm(Alarm(window.t_end, AlarmKind.WINDOW_REJECTED, Severity.INFO,
                                    f"{window.state} window rejected: {exc}")))
            return replace(w, rejected=count(w.rejected, "not_bracketed")), out
        resolved = self._resolution(window, sensor)
        out.append(Output("estimate", self._window_message(
            corrected, estimate, block, self._scatter_of(w, window), resolved)))
        if window.state in REAMING_AXIAL_OPERATION:
            return w, out  # combined motion: not a reference for the cased value, profile or mu(T)
        w = self._joint(w, block, window, sensor, out)
        if resolved is not None and not resolved.resolvable:
            # no friction published: nothing to average, alarm on or learn from
            return replace(w, rejected=count(w.rejected, "not_resolvable")), out
        w = self._add_scatter(w, window, estimate)
        w = self._cased_or_pending(w, block, corrected, estimate, out)
        w = self._jump(w, window, estimate, out)
        w = self._limits(w, window, estimate, out)
        w = self._feed_profile(w, corrected, out)
        w = self._feed_mu_t(w, corrected, estimate, out)
        return w, out

    def _drilling_window(self, w: WindowState, window: Window, out: list[Output]
                         ) -> WindowState:
        """Friction from a drilling window's torque less the bit's (docs/drilling.md), as a
        ``window`` estimate of operation ``drilling``; nothing without a weight on bit, a bit
        torque or a torque that moves."""
        if (window.wob is None or window.bit_torque is None or window.torque is None
                or window.torque_se is None or "torque_stuck" in window.flags):
            return w
        try:
            solved = drilling_friction(self.model, window.bit_depth, window.wob,
                                       window.torque, window.torque_se, window.bit_torque,
                                       method=self.settings.method,
                                       bracket=self.settings.bracket)
        except (FitError, ModelError) as exc:
            out.append(_alarm(Alarm(window.t_end, AlarmKind.WINDOW_REJECTED, Severity.INFO,
                                    f"{window.state} window rejected: {exc}")))
            return replace(w, rejected=count(w.rejected, "not_bracketed"))
        scatter = self._scatter_of(w, window)
        out.append(Output("estimate", estimate_message(
            window.t_end, EstimateKind.WINDOW, RigState.DRILLING, solved.mu,
            math.hypot(solved.mu_std, scatter), bit_depth_m=window.bit_depth, section="all",
            samples=window.n, t_start=window.t_start,
            low_confidence=bool(window.low_confidence), flags=list(window.flags),
            measured=window.torque, measured_se=window.torque_se, quantity="torque",
            mu_std_measurement=solved.mu_std, scatter_std=scatter, wob_N=window.wob,
            bit_torque_Nm=window.bit_torque, **_mwd_sources(window))))
        return w

    def _resolution(self, window: Window, sensor: SensorEstimate) -> Resolution | None:
        """Whether the window's load can show friction above the sensor's uncertainty (None:
        not judged, for reaming and back-reaming); the drag it names is the prior friction's."""
        if window.state in REAMING_AXIAL_OPERATION:
            return None
        try:
            return resolution(self.model, window.state, window.bit_depth, sensor,
                              mu=self.settings.prior_mu,
                              hookload_se=window.hookload_se, torque_se=window.torque_se or 0.0,
                              torque_uncertainty=self.settings.joint.torque_uncertainty,
                              method=self.settings.method)
        except ModelError:
            return None

    def _solve(self, window: Window, mu_cased: float | None) -> FrictionEstimate:
        s = self.settings
        return back_calculate_window(self.model, window, mu_cased=mu_cased,
                                     min_open_length=s.min_open_length, bracket=s.bracket,
                                     method=s.method, shoe=self.shoe)

    def _cased_or_pending(self, w: WindowState, block: BlockWeightWindow, window: Window,
                          estimate: FrictionEstimate, out: list[Output]) -> WindowState:
        """Add a cased window to the cased friction (and revise the waiting windows), or keep
        a deep window solved over the whole string until the cased friction is known."""
        state = window.state
        if estimate.section in ("cased", "all") and window.bit_depth <= self.shoe:
            cased = add_cased(w.cased.get(state, CasedFriction()), estimate.mu, estimate.mu_std)
            w = replace(w, cased=put(w.cased, state, cased))
            return self._revise(w, block, state, out)
        if (estimate.section == "all"
                and window.bit_depth > self.shoe + self.settings.min_open_length
                and self.shoe > 0.0):
            # tripping out from below the shoe: open-hole friction needs the cased value,
            # known only once the bit is inside casing; these windows are solved again then
            waiting = wait_for_cased(w.pending.get(state, ()), window)
            return replace(w, pending=put(w.pending, state, waiting))
        return w

    def _revise(self, w: WindowState, block: BlockWeightWindow, state: str,
                out: list[Output]) -> WindowState:
        """Solve the open-hole friction of earlier deep windows once cased friction is known."""
        pending = w.pending.get(state)
        cased = w.cased.get(state)
        mu_cased = None if cased is None else cased.mu
        if not pending or cased is None or mu_cased is None or not cased.known:
            return w  # nothing waits, or the cased friction rests on too few windows
        w = replace(w, pending=put(w.pending, state, ()))
        for window in pending:
            try:
                estimate = self._solve(window, mu_cased)
            except FitError:
                w = replace(w, rejected=count(w.rejected, "not_bracketed"))
                continue
            message = self._window_message(window, estimate, block, self._scatter_of(w, window))
            out.append(Output("estimate", {**message, "revised": True, "mu_cased": mu_cased}))
        return w

    def _window_message(self, window: Window, estimate: FrictionEstimate,
                        block: BlockWeightWindow, scatter: float,
                        resolved: Resolution | None = None) -> dict[str, Any]:
        """The window's estimate; its ``mu_std`` is the measurement's (the sensor's
        uncertainty included) and the between-window scatter's together (the spread of the
        window's friction about the trip's). Where the window cannot resolve friction
        (``resolved``), ``mu`` and ``mu_std`` are None and ``resolution`` says why."""
        operation = (window.state if window.state in REAMING_AXIAL_OPERATION
                     else estimate.operation)
        unresolved = resolved is not None and not resolved.resolvable
        message: dict[str, Any] = {
            "t": window.t_end, "kind": EstimateKind.WINDOW, "operation": operation,
            "mu": None if unresolved else estimate.mu,
            "mu_std": None if unresolved else math.hypot(estimate.mu_std, scatter),
            "bit_depth_m": window.bit_depth,
            "section": estimate.section, "samples": window.n, "t_start": window.t_start,
            "low_confidence": bool(window.low_confidence), "flags": list(window.flags),
            "measured": estimate.measured, "measured_se": estimate.measured_se,
            "quantity": estimate.quantity,
            "mu_std_measurement": estimate.mu_std, "scatter_std": scatter,
        }
        if block.estimate is not None:
            message["block_weight_N"] = block.estimate.value
        if resolved is not None:
            message["resolvable"] = resolved.resolvable
            if unresolved:
                message["resolution"] = resolved.statement
        return message

    # -- friction and weight together ----------------------------------------------------

    def _scatter_of(self, w: WindowState, window: Window) -> float:
        """Between-window friction scatter of the window's operation so far [-]."""
        return scatter_std(w.scatter.get(_SCATTER_KIND.get(window.state, "")),
                           self.settings.joint.scatter_prior)

    def _single_frictions(self, w: WindowState) -> dict[str, float]:
        """Median single-window friction at the modelled weight of each operation's recent
        windows [-]: pick-up and slack-off far apart at the same depth is a weight error."""
        recent = 8
        return {kind: median(scatter.mu[-recent:])
                for kind, scatter in w.scatter.items() if scatter.mu}

    def _add_scatter(self, w: WindowState, window: Window,
                     estimate: FrictionEstimate) -> WindowState:
        kind = _SCATTER_KIND.get(window.state)
        if kind is None:
            return w
        scatter = add_window(w.scatter.get(kind, Scatter()), estimate.mu, estimate.mu_std,
                             self.settings.joint.scatter_windows)
        return replace(w, scatter=put(w.scatter, kind, scatter))

    def _joint(self, w: WindowState, block: BlockWeightWindow, window: Window,
               sensor: SensorEstimate, out: list[Output]) -> WindowState:
        """Friction, weight factor and the hook-load measurement from the recent windows; the
        weight-mismatch alarm."""
        if w.joint is None:
            return w
        s = self.settings.joint
        taus = {kind: scatter_std(w.scatter.get(kind), s.scatter_prior)
                for kind in _SCATTER_KIND.values()}
        joint = update_joint(w.joint, self.model, window, self._block_of(block), taus, s,
                             self.settings.method, last_motion=w.last_motion)
        if joint is w.joint:
            return w
        resolved = self._joint_resolution(window, sensor)
        fields = joint_fields(joint, s, resolved)
        try:
            difference = weight_difference(self.model, window.bit_depth,
                                           fields["weight_factor"])
        except ModelError:
            difference = math.nan
        operation = OPERATION_FOR_STATE.get(window.state, window.state)
        out.append(Output("estimate", estimate_message(
            window.t_end, EstimateKind.JOINT, operation, fields.pop("mu"), fields.pop("mu_std"),
            bit_depth_m=window.bit_depth, **fields,
            weight_difference_N=difference if math.isfinite(difference) else None,
            scatter=taus, mu_single=self._single_frictions(w))))
        mismatch, alarm = mismatch_alarm(
            w.mismatch, self.model, self.air_model, window.t_end, window.bit_depth,
            float(fields["weight_factor"]), float(fields["weight_factor_std"]),
            float(fields["mu_joint"]), bool(fields["identifiable"]),
            tolerance=s.mismatch_tolerance, windows=s.mismatch_windows,
            block=(float(fields[BLOCK_WEIGHT.name]), float(fields[BLOCK_WEIGHT.std_field]))
            if BLOCK_WEIGHT.name in fields else None)
        if alarm is not None:
            out.append(_alarm(alarm))
        block_alarmed = w.block_alarmed or self._block_alarm(joint, window.t_end, out)
        return replace(w, joint=joint, mismatch=mismatch, block_alarmed=block_alarmed)

    def _block_alarm(self, joint: JointState, t: float, out: list[Output]) -> bool:
        """The block-weight alarm from the joint estimate (once): whether it was raised."""
        s = self.settings.joint
        b, o = s.position(BLOCK_WEIGHT.name), s.position(HOOKLOAD_OFFSET.name)
        if b is None or o is None:
            return False
        mean, p = mean_and_covariance(joint, s)
        empty = (float(mean[b] + mean[o]),
                 math.sqrt(max(float(p[b, b] + p[o, o] + 2 * p[b, o]), 0.0)))
        std_b, std_o = (math.sqrt(max(float(p[k, k]), 0.0)) for k in (b, o))
        # strongly anti-correlated: only their sum is known (identifiability's pair note)
        separated = std_b * std_o > 0 and p[b, o] / (std_b * std_o) > -PAIR_CORRELATION
        alarm = block_weight_alarm(
            t, (float(mean[b]), std_b), (float(mean[o]), std_o), empty,
            self.model.well.block_weight - s.sensor.above_sensor,
            self.settings.block_weight_tolerance, separated=bool(separated))
        if alarm is None:
            return False
        out.append(_alarm(alarm))
        return True

    def _joint_resolution(self, window: Window, sensor: SensorEstimate) -> Resolution | None:
        """Whether the pick-up/slack-off split at the window's depth can show friction above
        the sensor's uncertainty (the joint estimate's evidence for friction)."""
        se = window.hookload_se if math.isfinite(window.hookload_se) else 0.0
        try:
            return resolution(self.model, RigState.PICK_UP, window.bit_depth, sensor,
                              mu=self.settings.prior_mu, hookload_se=se,
                              torque_uncertainty=self.settings.joint.torque_uncertainty,
                              method=self.settings.method, paired=True)
        except ModelError:
            return None

    # -- alarms ---------------------------------------------------------------------------

    def _jump(self, w: WindowState, window: Window, estimate: FrictionEstimate,
              out: list[Output]) -> WindowState:
        history = w.history.get(window.state, ())
        alarm = friction_jump(history, estimate.mu, estimate.mu_std, window.t_end,
                              self.settings.jump, operation=estimate.operation,
                              bit_depth=window.bit_depth)
        if alarm is not None:
            out.append(_alarm(alarm))
        history = (*history, estimate.mu)[-self.settings.jump.history:]
        return replace(w, history=put(w.history, window.state, history))

    def _limits(self, w: WindowState, window: Window, estimate: FrictionEstimate,
                out: list[Output]) -> WindowState:
        """Load-limit alarms at the window's friction, each reported when it starts."""
        try:
            # the loads of the two operations limit_alarms reads (the estimate's operation
            # is one the back-calculation modelled, so a valid one)
            loads = self.model.loads(window.bit_depth, self._friction_of(w, estimate),
                                     method=self.settings.method,
                                     operations=(estimate.operation, Operation.ROTATING))
            alarms = limit_alarms(self.model.well, loads, estimate.operation, window.t_end,
                                  warn=self.settings.limit_warn, grid=self.model.grid)
        except (ModelError, ValueError):
            return w  # the model does not reach this depth: no check, the memory stays
        out.extend(_alarm(a) for a in alarms if a.kind not in w.active_limits)
        return replace(w, active_limits=frozenset(a.kind for a in alarms))

    def _friction_of(self, w: WindowState, estimate: FrictionEstimate) -> NDArray[np.float64]:
        kind = self.model.grid.element_kind
        if estimate.section == "open":
            cased = w.mu_cased(RigState.PICK_UP if estimate.operation == Operation.PICK_UP
                               else RigState.SLACK_OFF)
            return np.where(kind == "open", estimate.mu, cased if cased is not None
                            else estimate.mu)
        return np.full(self.model.n_elements, estimate.mu)

    def _weight_check(self, w: WindowState, window: Window, out: list[Output]) -> WindowState:
        """The string's weight in a hang (``window`` as the model's own hook load: read through
        the sensor's estimate, with the model's block weight)."""
        air_model = self.air_model
        if air_model is None:
            return w
        checked = weight_check(self.model, air_model, window, self.model.well.block_weight,
                               w.weight_off, self.settings.block_weight_tolerance)
        if checked is None:
            return w
        check, weight_off, alarm = checked
        if alarm is not None:
            out.append(_alarm(alarm))
        return replace(w, weight_off=weight_off,
                       weight_checks=(*w.weight_checks, check)[-_WEIGHT_CHECKS_KEPT:])

    # -- filters --------------------------------------------------------------------------

    def _feed_profile(self, w: WindowState, window: Window, out: list[Output]) -> WindowState:
        profile = copy.copy(w.profile)
        if not profile.add_window(window):
            # a gated window changes only the profile's count of gated windows
            return w if profile.gated == w.profile.gated else replace(w, profile=profile)
        out.append(Output("estimate", _profile_message(profile, window)))
        alarm, anomalous = profile_anomaly(
            window.t_end, profile.grid.edges, profile.state.mu, profile.state.covariance,
            self.settings.prior_std, self.settings.jump, known=w.anomalous_bins)
        if alarm is not None:
            out.append(_alarm(alarm))
        return replace(w, profile=profile, profile_updates=w.profile_updates + 1,
                       anomalous_bins=anomalous)

    def _feed_mu_t(self, w: WindowState, window: Window, estimate: FrictionEstimate,
                   out: list[Output]) -> WindowState:
        if w.mu_t is None:
            return w
        mu_t = copy.copy(w.mu_t)
        if not mu_t.add_window(window):
            return w
        fields = mu_t.message_fields()
        if math.isfinite(float(fields["mu"])):  # type: ignore[arg-type]
            out.append(Output("estimate", {"t": window.t_end, "kind": EstimateKind.MU_T,
                                           "operation": estimate.operation, **fields}))
        return replace(w, mu_t=mu_t)


def _profile_message(profile: FrictionProfile, window: Window) -> dict[str, Any]:
    """The ``estimate`` message of kind ``profile`` after ``window``: the bin at the bit."""
    fields = profile.message_fields()
    grid = profile.grid
    k = min(max(int(np.searchsorted(grid.edges, window.bit_depth)) - 1, 0), grid.n_bins - 1)
    operation = (window.state if window.state != RigState.ROTATING_OFF_BOTTOM
                 else Operation.ROTATING)
    return {"t": window.t_end, "kind": EstimateKind.PROFILE, "operation": operation,
            "mu": float(profile.state.mu[k]), "mu_std": float(profile.state.std[k]),
            "bit_depth_m": window.bit_depth, **fields}
