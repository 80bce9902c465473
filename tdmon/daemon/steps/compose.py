"""The daemon's steps from its configuration: rig state and monitor, and with the calibration
on, the calibration, alarm and well/profile steps (docs/back-calculation.md, "Daemon
composition")."""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from tdmon.daemon.pipeline import Step
from tdmon.daemon.steps.monitor import DrillingMonitor, LoadModel, MonitorStep
from tdmon.daemon.steps.rig_state import (
    RigStateStep,
    StringWeight,
    calibration_thresholds,
    rig_state_thresholds,
)
from tdmon.errors import FitError

if TYPE_CHECKING:
    from tdmon.calib.joint import JointSettings
    from tdmon.config.daemon import CalibrationConfig, DaemonConfig
    from tdmon.config.well_file import WellFile
    from tdmon.model.well import Well

log = logging.getLogger(__name__)

__all__ = ["calibration_steps_for", "default_steps", "drilling_monitor", "joint_settings"]


def default_steps(config: DaemonConfig, model: LoadModel | None,
                  rig_state: Step | None = None) -> list[Step]:
    """Rig state (``rig_state``, else the detector with ``[rig_state]``'s thresholds), then the
    monitor when a model is available."""
    steps: list[Step] = [rig_state or RigStateStep(rig_state_thresholds(config.rig_state))]
    if model is not None:
        steps.append(MonitorStep(model, drilling=drilling_monitor(config)))
    return steps


def drilling_monitor(config: DaemonConfig) -> DrillingMonitor:
    """The monitor's drilling with ``[monitor]``'s bit model and tag settling."""
    monitor = config.monitor
    bit = (None if monitor.bit_diameter is None or monitor.bit_friction is None
           else (monitor.bit_diameter, monitor.bit_friction))
    return DrillingMonitor(bit, monitor.tag_settle)


def joint_settings(cal: CalibrationConfig, well: Well) -> JointSettings:
    """The joint estimate's settings for a rig: its parameters as the well file's hook-load
    sensor calls for them (the sheave efficiency for a deadline sensor), with the daemon
    file's priors (docs/hookload.md)."""
    from tdmon.calib.joint import JointSettings, for_rig
    from tdmon.calib.parameters import (
        BLOCK_WEIGHT,
        HOOKLOAD_OFFSET,
        SHEAVE_EFFICIENCY,
        WEIGHT_FACTOR,
    )

    base = for_rig(JointSettings(mismatch_tolerance=cal.weight_mismatch_tolerance,
                                 hysteresis=cal.hookload_hysteresis,
                                 torque_uncertainty=cal.torque_uncertainty), well)
    parameters = base.parameters
    parameters = parameters.with_prior(WEIGHT_FACTOR.name, cal.weight_factor,
                                       cal.weight_factor_std)
    block = parameters.get(BLOCK_WEIGHT.name)
    if well.block_weight > 0.0:
        parameters = parameters.with_prior(block.name, block.prior, cal.block_weight_std)
    parameters = parameters.replaced(HOOKLOAD_OFFSET.name, prior_std=cal.hookload_offset_std,
                                     drift_per_hour=cal.hookload_offset_drift)
    if SHEAVE_EFFICIENCY.name in parameters.names:
        sheave = parameters.get(SHEAVE_EFFICIENCY.name)
        parameters = parameters.with_prior(sheave.name, sheave.prior, cal.sheave_efficiency_std)
    return replace(base, parameters=parameters)


def calibration_steps_for(config: DaemonConfig, well: Any = None,
                          well_file: WellFile | None = None) -> tuple[Step, list[Step]]:
    """The back-calculation's rig-state step and the steps after the monitor
    (docs/back-calculation.md, "Daemon composition"), with the mu(T) calibration when the
    well file has a temperature model, and the well/profile step last."""
    # imported here: a daemon without the calibration does not load the estimator's modules
    from tdmon.calib.estimator import CalibrationSettings
    from tdmon.daemon.steps.alarms import AlarmStep
    from tdmon.daemon.steps.calibrate import CalibrationStep
    from tdmon.daemon.steps.mu_t import mu_t_setup
    from tdmon.daemon.steps.profile import profile_step
    from tdmon.model.torque_drag import WellModel

    assert config.well is not None
    if well_file is None:
        from tdmon.config.well_file import read_well_file

        well_file = read_well_file(config)
    assert well_file is not None
    if well is None:
        well = well_file.well
    model = WellModel(well)
    # the in-slips margin scales with the string's modelled weight at the bit depth
    rig_state = RigStateStep(calibration_thresholds(config, well.block_weight),
                             string_weight=StringWeight(model))
    setup = mu_t_setup(config, well_file, model.grid)
    settings = CalibrationSettings(mu_t_mode=setup.mode,
                                   joint=joint_settings(config.calibration, well))
    try:
        calibration = CalibrationStep(
            model, rig_state, settings, temperature=setup.temperature if setup.law else None,
            friction_law=setup.law, mu_t_mask=setup.mask, mu_t_base=setup.base_mu,
            mu_t_prior_std=setup.prior_std)
    except FitError as exc:
        # e.g. a law undefined at the well's temperatures: monitor anyway, say why
        setup = replace(setup, law=None, note=f"mu(T) calibration is off: {exc}")
        calibration = CalibrationStep(model, rig_state, settings)
    if setup.note is not None:
        log.info("%s", setup.note)
    else:
        assert setup.law is not None and setup.temperature is not None
        log.info("mu(T) calibration on: %s (%s mode) over %.1f-%.1f degC", setup.law.describe(),
                 setup.mode, float(np.min(setup.temperature)), float(np.max(setup.temperature)))
    return rig_state, [calibration, AlarmStep(rig_state=rig_state),
                       profile_step(config, well_file, model.grid, setup, calibration)]
