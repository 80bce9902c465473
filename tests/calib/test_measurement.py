"""The hook-load measurement in the estimates (tdmon.calib.measurement, slips, the joint
estimate's sensor parameters and the block-weight alarm) against known truth.

Truth is the torque-and-drag model read through a deadline sensor of known efficiency, zero
offset and block weight (the API RP 9B factors of tdmon.model.hookload_sensor, themselves
tested against the published table); the estimates must find them back, say how well, and say
when a well cannot resolve friction at all.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tdmon.calib.joint import (
    JointSettings,
    initial_joint,
    mean_and_covariance,
    sensor_estimate,
    slips_measurement,
    update_joint,
    update_joint_slips,
)
from tdmon.calib.measurement import SensorEstimate, corrected_window, factor_slope, resolution
from tdmon.calib.parameters import (
    BLOCK_WEIGHT,
    FRICTION,
    HOOKLOAD_OFFSET,
    SHEAVE_EFFICIENCY,
    WEIGHT_FACTOR,
    rig_parameters,
)
from tdmon.calib.rigstate import RigSample
from tdmon.calib.slips import MIN_SLIPS_SAMPLES, SlipsRun, add_slips_sample, close_run
from tdmon.calib.weightcheck import block_weight_alarm
from tdmon.calib.windows import Window
from tdmon.config.well import load_well_model
from tdmon.model.hookload_sensor import HookloadSensor, SensorLocation
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import AlarmKind

REPO = Path(__file__).resolve().parents[2]
DEADLINE = HookloadSensor(SensorLocation.DEADLINE, lines=10, efficiency=0.9615)


def _window(state: str, t: float, depth: float, hookload: float, se: float = 2e3,
            torque: float | None = None, torque_se: float | None = None) -> Window:
    return Window(state, t - 30.0, t, 30, depth, depth, depth, hookload, se, torque=torque,
                  torque_se=torque_se, rpm=10.0 if torque is not None else None)


def test_a_reading_and_the_load_it_stands_for_are_inverse() -> None:
    estimate = SensorEstimate(DEADLINE, 350e3, 10e3, offset=-12e3, offset_std=3e3,
                              efficiency=0.97, efficiency_std=0.01)
    for motion in (-1, 0, 1):
        reading = estimate.reading(800e3, motion)
        assert estimate.string_load(reading, motion) == pytest.approx(800e3, rel=1e-12)
    # hoisting reads low, lowering high, still as it is (plus the offset)
    assert estimate.reading(800e3, 1) < 1150e3 - 12e3 < estimate.reading(800e3, -1)
    assert estimate.reading(800e3, 0) == pytest.approx(1150e3 - 12e3)
    # the slope of the factor in the efficiency against a wide finite difference
    for motion in (-1, 1):
        wide = (DEADLINE.factor(motion, 0.975) - DEADLINE.factor(motion, 0.965)) / 0.01
        assert factor_slope(DEADLINE, motion, 0.97) == pytest.approx(wide, rel=1e-3)
    assert factor_slope(DEADLINE, 0, 0.97) == 0.0
    assert factor_slope(HookloadSensor(), 1, 0.97) == 0.0
    # paired (a pick-up minus a slack-off): the offset and the still block's weight cancel
    known = replace(estimate, efficiency_std=0.0, hysteresis=0.01)
    assert known.uncertainty(800e3, 1, paired=True) == pytest.approx(0.01 * 1150e3)
    assert known.uncertainty(800e3, 1) == pytest.approx(math.sqrt(
        3e3**2 + (known.factor(1) * 10e3) ** 2 + (0.01 * 1150e3) ** 2))


def test_a_deadline_window_is_read_back_to_the_models_hook_load(model_open: WellModel) -> None:
    block = model_open.well.block_weight
    estimate = SensorEstimate(DEADLINE, block - 20e3, 0.0, offset=8e3, efficiency=0.98)
    hook = model_open.evaluate("pick_up", 3500.0, 0.25)[0]
    reading = estimate.reading(hook - block, 1)
    assert reading < hook - 100e3  # a deadline sensor reads a pull well low (about -17 %)
    window = corrected_window(_window("pick_up", 60.0, 3500.0, reading), estimate, block)
    assert window.hookload == pytest.approx(hook, rel=1e-12)
    assert window.hookload_se == pytest.approx(2e3 / estimate.factor(1), rel=1e-9)
    # what is not known of the sensor widens the window's standard error
    vague = replace(estimate, offset_std=10e3, hysteresis=0.01)
    wide = corrected_window(_window("pick_up", 60.0, 3500.0, reading), vague, block)
    assert wide.hookload == pytest.approx(hook, rel=1e-12)
    assert wide.hookload_se == pytest.approx(
        math.hypot(2e3, vague.uncertainty(hook - block, 1)) / estimate.factor(1), rel=1e-9)
    assert wide.hookload_se > 10e3


def test_a_near_vertical_shallow_well_cannot_resolve_friction(model_open: WellModel) -> None:
    shallow = WellModel(load_well_model(REPO / "replays/scenarios/wells/"
                                         "near-vertical-shallow.toml"))
    sensor = shallow.well.hookload_sensor
    unknown = SensorEstimate(sensor, shallow.well.block_weight, 20e3, offset_std=20e3,
                             hysteresis=0.01)
    depth = 0.9 * shallow.well.string.length
    verdict = resolution(shallow, "pick_up", depth, unknown, mu=0.25, hookload_se=2e3)
    assert not verdict.resolvable
    assert verdict.signal < 2 * verdict.uncertainty
    assert verdict.statement.startswith("friction not resolvable here: friction 0.1 and 0.3 "
                                        "change the drag by ")
    assert f"{verdict.signal / 1e3:.1f} kN" in verdict.statement
    paired = resolution(shallow, "pick_up", depth, unknown, mu=0.25, hookload_se=2e3,
                        paired=True)
    assert not paired.resolvable  # not even a pull against a run at the same depth
    # the deviated well of these tests resolves it easily, alone or paired
    estimate = replace(unknown, sensor=HookloadSensor(), block_weight=model_open.well.block_weight)
    deep = resolution(model_open, "pick_up", 3800.0, estimate, mu=0.25, hookload_se=2e3)
    assert deep.resolvable and deep.statement == "resolvable"
    assert deep.signal > 100e3
    torque = resolution(model_open, "rotating_off_bottom", 3800.0, estimate, mu=0.25,
                        torque_se=200.0, torque_uncertainty=300.0)
    assert torque.resolvable and torque.uncertainty == pytest.approx(math.hypot(200.0, 300.0))


def _sample(t: float, hookload: float, block: float | None) -> RigSample:
    return RigSample(t, hookload, 1000.0, block_position=block)


def test_in_slips_readings_are_grouped_by_the_blocks_motion() -> None:
    run = SlipsRun()
    rng = np.random.default_rng(3)
    t, position = 0.0, 5.0
    expected = {0: 300e3, 1: 290e3, -1: 312e3}
    for motion, speed in ((0, 0.0), (1, 0.5), (-1, -0.5)):
        for _ in range(2 * MIN_SLIPS_SAMPLES):
            t += 1.0
            position += speed
            run = add_slips_sample(run, _sample(t, expected[motion] + rng.normal(0, 500.0),
                                                position), steady=True)
    readings = {r.motion: r for r in close_run(run, noise_floor=100.0)}
    assert set(readings) == {-1, 0, 1}
    for motion, reading in readings.items():
        # the first sample of a new motion still counts under the last one
        assert reading.mean == pytest.approx(expected[motion], abs=4e3)
        assert 50.0 < reading.se < 500.0
    # no block position: the block counts as still; unsteady samples do not count
    run = SlipsRun()
    for k in range(MIN_SLIPS_SAMPLES):
        run = add_slips_sample(run, _sample(float(k), 300e3, None), steady=True)
        run = add_slips_sample(run, _sample(k + 0.5, 900e3, None), steady=False)
    (still,) = close_run(run, noise_floor=1e3)
    assert still.motion == 0 and still.mean == pytest.approx(300e3)
    assert still.se == pytest.approx(1e3 / math.sqrt(MIN_SLIPS_SAMPLES))  # the noise floor


def test_the_block_weight_alarm_names_the_cause_the_data_can_tell() -> None:
    configured = 300e3
    # the block itself is off, known to 3 kN: named
    alarm = block_weight_alarm(600.0, (340e3, 3e3), (0.0, 3e3), (340e3, 2e3), configured, 0.05)
    assert alarm is not None and alarm.kind == AlarmKind.BLOCK_WEIGHT
    assert alarm.message.startswith("block weight 340 ± 3 kN")
    # only the sum is known: both causes named, with the jump in kN
    alarm = block_weight_alarm(600.0, (320e3, 20e3), (20e3, 20e3), (340e3, 2e3), configured,
                               0.05)
    assert alarm is not None
    assert "the block weight or the hook-load sensor's zero is off by +40 kN" in alarm.message
    # within the tolerance, or within twice its spread, or no block weight configured: none
    assert block_weight_alarm(0.0, (310e3, 3e3), (0.0, 3e3), (310e3, 2e3), configured,
                              0.05) is None
    assert block_weight_alarm(0.0, (340e3, 25e3), (0.0, 3e3), (340e3, 25e3), configured,
                              0.05) is None
    assert block_weight_alarm(0.0, (340e3, 3e3), (0.0, 3e3), (340e3, 2e3), 0.0, 0.05) is None


def _deadline_settings(block: float) -> JointSettings:
    parameters = rig_parameters(reads_sheave_friction=True, block_weight=block,
                                efficiency=DEADLINE.efficiency)
    return JointSettings(parameters=parameters, sensor=DEADLINE)


def _trip_through_a_deadline(model: WellModel, rng: np.random.Generator,
                             truth: dict[str, float], settings: JointSettings,
                             stands: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A trip out read by a deadline sensor: a pick-up per stand, a slack-off every third and
    rotation off bottom every fourth, and between stands a connection in slips while the empty
    block is lowered, held and hoisted. The truth (``truth``, by parameter name; updated in
    place to its values at the end) behaves as the estimate's model says it may: every
    parameter drifts as a random walk at its declared rates, friction scatters about its value
    from window to window and the string's weight by the model error, and readings carry 2 kN
    of noise (0.6 kN in slips) and a 1 % hysteresis drawn per reading while the block moves."""
    block_model = model.well.block_weight
    names = {p.name: p for p in settings.parameters}

    def drift(seconds: float, metres: float) -> float:
        for name, p in names.items():
            step = math.sqrt(p.drift_per_hour**2 * seconds / 3600.0
                             + p.drift_per_100m**2 * metres / 100.0)
            truth[name] = float(np.clip(truth[name] + rng.normal(0.0, step), *p.bounds))
        return seconds

    def read(string_load: float, motion: int, noise: float = 2e3) -> float:
        load = truth[BLOCK_WEIGHT.name] + string_load
        hysteresis = settings.hysteresis * load * rng.normal() if motion else 0.0
        factor = DEADLINE.factor(motion, truth[SHEAVE_EFFICIENCY.name])
        return factor * load + truth[HOOKLOAD_OFFSET.name] + hysteresis + rng.normal(0, noise)

    state = initial_joint(settings)
    depth, t = rng.uniform(3300.0, 4000.0), 0.0
    for k in range(stands):
        t += drift(120.0, 28.0)
        depth -= 28.0
        readings = tuple(slips_measurement(read(0.0, motion, 600.0), 600.0, motion)
                         for motion in (-1, 0, 1))
        state = update_joint_slips(state, model, readings, t, block_model, settings)
        plan = ["pick_up"] + (["slack_off"] if k % 3 == 1 else []) + (
            ["rotating_off_bottom"] if k % 4 == 2 else [])
        for name in plan:
            t += drift(60.0, 0.0)
            mu = max(truth[FRICTION.name] + rng.normal(0.0, settings.scatter_prior), 0.01)
            w = truth[WEIGHT_FACTOR.name] * (1.0 + rng.normal(0.0, settings.weight_model_std))
            if name == "rotating_off_bottom":
                hook, torque = model.evaluate("rotating", depth, mu)
                window = _window(name, t, depth, read(w * (hook - block_model), 0), 2e3,
                                 w * torque + rng.normal(0.0, 200.0), 200.0)
            else:
                hook = model.evaluate(name, depth, mu)[0]
                motion = 1 if name == "pick_up" else -1
                window = _window(name, t, depth, read(w * (hook - block_model), motion))
            state = update_joint(state, model, window, block_model, {}, settings,
                                 last_motion="rotating" if name == "rotating_off_bottom"
                                 else name)
    return mean_and_covariance(state, settings)


def test_intervals_of_friction_weight_and_the_sensor_cover_the_truth(model_open: WellModel
                                                                      ) -> None:
    # Monte Carlo over the truth, drawn as the estimate's priors say it may be (friction
    # 0.15-0.35, weight factor 1 +- 0.05, sheave efficiency 0.9615 +- 0.02, zero offset 0 +-
    # 20 kN, block weight +- 20 kN off the well file's, each drifting at its declared rate)
    # and over the noise: the +-2 standard deviation intervals hold the truth 90-98 % of the
    # time, for each parameter and for what an empty block reads (block weight plus offset)
    rng = np.random.default_rng(28)
    block = model_open.well.block_weight
    settings = _deadline_settings(block)
    names = settings.parameters.names
    runs = 200
    covered = dict.fromkeys([*names, "empty"], 0)
    errors: dict[str, list[float]] = {name: [] for name in covered}
    b, o = names.index(BLOCK_WEIGHT.name), names.index(HOOKLOAD_OFFSET.name)
    for _ in range(runs):
        truth = {FRICTION.name: rng.uniform(0.15, 0.35)}
        truth.update({p.name: float(np.clip(rng.normal(p.prior, p.prior_std), *p.bounds))
                      for p in settings.parameters if p.name != FRICTION.name})
        mean, p = _trip_through_a_deadline(model_open, rng, truth, settings)
        truth["empty"] = truth[BLOCK_WEIGHT.name] + truth[HOOKLOAD_OFFSET.name]
        values = {name: (float(mean[k]), math.sqrt(float(p[k, k])))
                  for k, name in enumerate(names)}
        values["empty"] = (float(mean[b] + mean[o]),
                           math.sqrt(float(p[b, b] + p[o, o] + 2 * p[b, o])))
        for name, (value, std) in values.items():
            covered[name] += abs(value - truth[name]) <= 2.0 * std
            errors[name].append(value - truth[name])
    for name, hits in covered.items():
        assert 0.90 <= hits / runs <= 0.98, (name, hits / runs)
    # and near the figures the replays are held to (efficiency within 0.01, friction within
    # 0.02, offset within 5 kN), for a truth that keeps drifting: the block weight and the
    # offset apart are known no better than their drift allows, what an empty block reads is
    assert np.percentile(np.abs(errors[SHEAVE_EFFICIENCY.name]), 90) < 0.01
    assert np.percentile(np.abs(errors["empty"]), 90) < 5e3
    assert np.median(np.abs(errors[FRICTION.name])) < 0.01
    assert np.percentile(np.abs(errors[FRICTION.name]), 90) < 0.025


def test_the_sensor_estimate_is_what_the_state_holds(model_open: WellModel) -> None:
    settings = _deadline_settings(300e3)
    estimate = sensor_estimate(initial_joint(settings), settings, 123e3)
    assert estimate.block_weight == pytest.approx(300e3)  # estimated: the prior, not 123 kN
    assert estimate.block_weight_std == pytest.approx(20e3)
    assert estimate.efficiency == pytest.approx(0.9615)
    assert estimate.offset == 0.0 and estimate.offset_std == pytest.approx(20e3)
    # a load cell reads no sheave friction: no efficiency is estimated, the block given is kept
    # where the block is not estimated
    plain = JointSettings(parameters=rig_parameters(reads_sheave_friction=False,
                                                    block_weight=0.0, efficiency=1.0))
    assert plain.position(SHEAVE_EFFICIENCY.name) is None
    estimate = sensor_estimate(initial_joint(plain), plain, 123e3)
    assert estimate.efficiency == 1.0 and estimate.efficiency_std == 0.0
