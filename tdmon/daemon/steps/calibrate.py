"""The calibration step: the daemon's adapter of :class:`~tdmon.calib.estimator.FrictionEstimator`.

Per frame it hands the rig-state step's sample and detection to the estimator and emits what
comes back (``estimate`` messages of kinds ``window``, ``profile``, ``mu_T`` and ``joint``; the
window-level alarms), and gives the rig-state detector the block weight the estimator learns in
slips. All the policy is in `tdmon.calib.estimator` (docs/back-calculation.md).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.blockweight import BlockWeightWindow, BuoyancyCheck
from tdmon.calib.estimator import CalibrationSettings, EstimatorState, FrictionEstimator, Output
from tdmon.calib.joint import initial_joint
from tdmon.calib.measurement import SensorEstimate
from tdmon.calib.mismatch import Mismatch
from tdmon.calib.mu_calibration import MuTCalibrator
from tdmon.calib.profile import FrictionProfile
from tdmon.calib.rigstate import RigSample
from tdmon.calib.windows import Window
from tdmon.daemon.pipeline import Emit, Frame
from tdmon.daemon.steps.fluids import FluidEffect
from tdmon.daemon.steps.rig_state import RigStateStep
from tdmon.model.friction import FrictionModel
from tdmon.model.torque_drag import WellModel

__all__ = ["CalibrationStep"]


def _send(outputs: Iterable[Output], emit: Emit) -> None:
    for topic, message in outputs:
        emit(topic, message)


def without_fluid(sample: RigSample, effect: FluidEffect) -> RigSample:
    """``sample`` with what the fluid terms add to its hook load and torque taken off (the
    fluid step's `tdmon.daemon.steps.fluids.FluidEffect` for the frame's rig state), so that
    the windows hold what friction and the string's weight explain."""
    if effect.hookload == 0.0 and effect.torque == 0.0:
        return sample
    hookload = None if sample.hookload is None else sample.hookload - effect.hookload
    torque = None if sample.torque is None else sample.torque - effect.torque
    return replace(sample, hookload=hookload, torque=torque)


class CalibrationStep:
    """Step: windows, per-window friction, profile, mu(T), window-level alarms.

    Parameters
    ----------
    model : the prepared well
    rig_state : the rig-state step that runs before this one
    settings : calibration settings
    temperature : annulus temperature per hole-grid element [degC] (enables mu(T))
    friction_law : configured mu(T) (family mode) or lab fit (scale mode)
    mu_t_mask, mu_t_base, mu_t_prior_std : see
        :meth:`~tdmon.calib.estimator.FrictionEstimator.initial_state`
    """

    name = "calibrate"

    def __init__(self, model: WellModel, rig_state: RigStateStep,
                 settings: CalibrationSettings | None = None, *,
                 temperature: NDArray[np.float64] | None = None,
                 friction_law: FrictionModel | None = None,
                 mu_t_mask: NDArray[np.bool_] | None = None,
                 mu_t_base: float | NDArray[np.float64] = 0.0,
                 mu_t_prior_std: Sequence[float] | None = None) -> None:
        self.estimator = FrictionEstimator(model, settings or CalibrationSettings())
        self.rig_state = rig_state
        self.state: EstimatorState = self.estimator.initial_state(
            temperature=temperature, friction_law=friction_law, mu_t_mask=mu_t_mask,
            mu_t_base=mu_t_base, mu_t_prior_std=mu_t_prior_std)
        self._sensor: tuple[object, tuple[SensorEstimate, float] | None] | None = None

    def sensor_reading(self) -> tuple[SensorEstimate, float] | None:
        """What is known now of the hook-load measurement, with the model's block weight [N]
        (the monitor shows its curves as the sensor reads them; None while the sensor reads
        the modelled load as it is); worked out again only when the joint estimate moved."""
        joint = self.state.windows.joint
        if self._sensor is None or self._sensor[0] is not joint:
            estimate = self.estimator.sensor(self.state.windows, self.state.samples.block_weight)
            block = self.estimator.model.well.block_weight
            as_is = (estimate.offset == 0.0 and estimate.block_weight == block
                     and all(estimate.factor(m) == 1.0 for m in (-1, 0, 1)))
            self._sensor = (joint, None if as_is else (estimate, block))
        return self._sensor[1]

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        sample, detection = self.rig_state.last_sample, self.rig_state.last_detection
        if sample is None or detection is None or sample.t != frame.t:
            return
        fluid = frame.results.get("fluids")
        if fluid is not None:
            sample = without_fluid(sample, fluid["effect"])
        block = self.state.samples.block_weight
        self.state, outputs = self.estimator.add_sample(self.state, sample, detection)
        if self.state.samples.block_weight is not block:  # a new in-slips sample
            learnt = self.estimator.learnt_block_weight(self.state)
            thresholds = self.rig_state.thresholds
            if learnt is not None and thresholds.block_weight != learnt:
                self.rig_state.thresholds = replace(thresholds, block_weight=learnt)
        if outputs:
            _send(outputs, emit)

    def on_window(self, window: Window, emit: Emit) -> None:
        """Everything one closed window gives."""
        self.state, outputs = self.estimator.update(self.state, window)
        _send(outputs, emit)

    def close(self, emit: Emit) -> None:
        self.state, outputs = self.estimator.close(self.state)
        _send(outputs, emit)

    def use_model(self, model: WellModel) -> None:
        """Go on with a new string or fluid on the same hole grid (a new run's well file,
        :mod:`tdmon.daemon.steps.coverage`): the friction profile and mu(T) keep what they
        have learnt, later windows are solved with ``model``. The joint weight factor starts
        again from its prior: it measured the old string's weight against its model."""
        self.estimator = FrictionEstimator(model, self.estimator.settings)
        self.rig_state.use_model(model)  # the in-slips margin weighs the new string
        windows = self.state.windows
        windows.profile.model = model
        if windows.mu_t is not None:
            windows.mu_t.model = model
        self.state = replace(self.state, windows=replace(
            windows, joint=initial_joint(self.estimator.settings.joint), mismatch=Mismatch()))

    # -- what the estimator holds, for the profile step and for tests ---------------------

    @property
    def model(self) -> WellModel:
        return self.estimator.model

    @property
    def settings(self) -> CalibrationSettings:
        return self.estimator.settings

    @property
    def profile(self) -> FrictionProfile:
        """The local friction profile now."""
        return self.state.windows.profile

    @property
    def profile_updates(self) -> int:
        """Windows the profile has taken (the profile step sends a new profile on a change)."""
        return self.state.windows.profile_updates

    @property
    def mu_t(self) -> MuTCalibrator | None:
        """The mu(T) calibration now (None when off)."""
        return self.state.windows.mu_t

    @property
    def block_weight(self) -> BlockWeightWindow:
        """The in-slips hook loads and their block weight."""
        return self.state.samples.block_weight

    @property
    def weight_checks(self) -> tuple[BuoyancyCheck, ...]:
        """The recent weight checks, oldest first."""
        return self.state.windows.weight_checks

    @property
    def rejected(self) -> Counter[str]:
        """Windows rejected or not solved, per reason."""
        return Counter(self.state.windows.rejected)
