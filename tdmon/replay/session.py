"""A simulated rig session with a known truth: scenario in, channel arrays and truth arrays out.

Pure: no files, no clock, no global random state. :func:`simulate_session` takes a
:class:`Scenario` (built from a scenario TOML by :mod:`tdmon.replay.scenario`) and returns a
:class:`Session`: for every canonical channel the sample times, the values as a rig would send
them (noise, spikes, stuck values, dropouts, clock jitter) and the noise-free values, plus the
truth a replay is checked against (rig state, friction profile, effective friction factors,
expected alarms, injected faults).

This module composes the steps, each in its own module: the scenario's pieces
(:mod:`tdmon.replay.spec`), the rig motion (:mod:`tdmon.replay.timeline`), the surface loads
from the model (:mod:`tdmon.replay.loads`), the sensors (:mod:`tdmon.replay.sensors`) and the
truth (:mod:`tdmon.replay.truth`). Their names are importable from here as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tdmon.config.scenario import CHANNELS, FAULT_KINDS, PHASE_KINDS
from tdmon.model.torque_drag import WellModel
from tdmon.replay.fluids import fluid_truth
from tdmon.replay.loads import Loads, friction_with_anomalies
from tdmon.replay.sensors import ChannelSeries, InjectedFault, channel_truth, sensor_series
from tdmon.replay.spec import (
    Array,
    FrictionAnomaly,
    ModelMismatch,
    NoiseSettings,
    Phase,
    RigSettings,
    Scenario,
    SensorFault,
    TightSpot,
)
from tdmon.replay.timeline import STATES, Position, Timeline, build_timeline
from tdmon.replay.truth import (
    ExpectedAlarm,
    expected_alarms,
    state_changes,
    truth_samples,
    weight_factors,
)
from tdmon.vocabulary import RigState

__all__ = [
    "CHANNELS",
    "FAULT_KINDS",
    "PHASE_KINDS",
    "STATES",
    "ChannelSeries",
    "ExpectedAlarm",
    "FrictionAnomaly",
    "InjectedFault",
    "ModelMismatch",
    "NoiseSettings",
    "Phase",
    "Position",
    "RigSettings",
    "Scenario",
    "SensorFault",
    "Session",
    "TightSpot",
    "Timeline",
    "build_timeline",
    "friction_with_anomalies",
    "simulate_session",
]

_EPS = 1e-9


@dataclass(frozen=True)
class Session:
    """A generated session.

    Attributes
    ----------
    scenario : what it was generated from
    timeline : the rig motion
    channels : per channel name, what was sent
    truth_t : times of the truth samples [Unix s] (the true hook-load sampling times)
    truth : per truth sample: ``state`` (array of rig-state names), ``bit_depth``, ``hole_depth``,
        ``block_position`` [m], ``hookload`` [N], ``torque`` [N m] (noise-free), ``mu_pick_up``,
        ``mu_slack_off``, ``mu_rotating`` (the uniform friction factor reproducing the true
        pick-up/slack-off hook load and rotating torque at that bit depth; NaN in slips),
        ``mu_mean`` (length-weighted mean of the profile over the string in the hole) [-];
        with an injected model error also ``weight_factor``: true over modelled buoyed string
        weight at the hook (:func:`tdmon.replay.truth.weight_factors`; NaN in slips) [-]
    state_changes : (Unix time [s], state) at the start and every change
    profile_md : mid-MD of the hole-grid elements [m]
    profile_mu : true friction factor per element (base plus anomalies) [-]
    profile_temperature : annulus temperature per element [degC] or None
    alarms : expected alarms
    faults : injected sensor faults
    """

    scenario: Scenario
    timeline: Timeline
    channels: dict[str, ChannelSeries]
    truth_t: Array
    truth: dict[str, NDArray[np.generic]]
    state_changes: list[tuple[float, RigState]]
    profile_md: Array
    profile_mu: Array
    profile_temperature: Array | None
    alarms: list[ExpectedAlarm]
    faults: list[InjectedFault]


def _sample_times(duration: float, interval: float) -> Array:
    """Sample times [s from the start]: every ``interval`` [s] until the session ends."""
    return np.arange(0.0, duration - _EPS, interval, dtype=np.float64)


def simulate_session(scenario: Scenario) -> Session:
    """Generate a rig session with its truth.

    Parameters
    ----------
    scenario : the session's well, programme, sampling, noise and faults

    Returns
    -------
    Session
        Channels sampled every ``scenario.sample_interval[channel]`` seconds from the start
        (sample ``k`` at ``k * interval``, minus missing and dropped samples), truth sampled at
        the hook-load times.

    Raises
    ------
    ModelError
        A phase cannot be done, or a bit depth leaves the well (string too short, below the
        hole).

    Notes
    -----
    Deterministic: channel ``c`` draws from ``numpy.random.default_rng([seed, index of c in
    CHANNELS])``, so the same scenario gives the same session, and adding a channel does not
    change the others.
    """
    timeline = build_timeline(scenario)
    well = scenario.well
    model_check = WellModel(well)
    deepest = float(max(timeline.bit0.max(), timeline.bit1.max()))
    shallowest = float(min(timeline.bit0.min(), timeline.bit1.min()))
    model_check.check_bit_depth(deepest)
    model_check.check_bit_depth(shallowest)
    grid = model_check.grid
    element_md = grid.element_mid_md
    element_length = np.diff(grid.md)
    mu = friction_with_anomalies(element_md, np.asarray(scenario.friction, dtype=np.float64),
                                 scenario.anomalies)
    loads = Loads(scenario, mu, model_check, fluid_truth(scenario, timeline, model_check))

    channels: dict[str, ChannelSeries] = {}
    faults: list[InjectedFault] = []
    for number, name in enumerate(CHANNELS):
        interval = scenario.sample_interval.get(name)
        if interval is None:
            continue
        if name == "mud_temp_in" and scenario.mud_temp_in is None:
            continue
        if name == "mud_temp_out" and scenario.mud_temp_out is None:
            continue
        if name == "mud_density" and loads.fluid is None:
            continue
        tau = _sample_times(timeline.duration, interval)
        truth_values = channel_truth(name, scenario, timeline, loads, tau)
        rng = np.random.default_rng([scenario.seed, number])
        channels[name], injected = sensor_series(name, scenario, tau, truth_values, interval,
                                                 rng)
        faults += injected

    truth_interval = scenario.sample_interval.get("hookload", 5.0)
    tau = _sample_times(timeline.duration, truth_interval)
    truth = truth_samples(timeline, loads, tau, element_md, element_length)
    if scenario.model_well is not None:
        truth["weight_factor"] = weight_factors(loads, scenario.model_well, truth)
    truth_t = scenario.start + tau
    return Session(
        scenario=scenario, timeline=timeline, channels=channels, truth_t=truth_t, truth=truth,
        state_changes=state_changes(timeline, scenario.start), profile_md=element_md,
        profile_mu=mu, profile_temperature=scenario.temperature,
        alarms=expected_alarms(scenario, truth_t, truth),
        faults=sorted(faults, key=lambda fault: (fault.t, fault.channel)),
    )
