"""Joint friction and weight-factor estimate (tdmon.calib.joint) against known truth.

Truth here is the torque-and-drag model itself with the string's buoyed weight scaled by a
known factor (an independent WellModel built with scaled component weights), per-window
friction scatter drawn about the true friction, and window noise.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from tdmon.calib.backcalc import back_calculate_window
from tdmon.calib.estimator import CalibrationSettings, FrictionEstimator
from tdmon.calib.joint import (
    JointSettings,
    identifiability,
    initial_joint,
    joint_fields,
    update_joint,
)
from tdmon.calib.parameters import FRICTION_AND_WEIGHT, EstimatedParameters
from tdmon.calib.scatter import Scatter, add_window, scatter_std
from tdmon.calib.windows import Window
from tdmon.config.well import load_well_model
from tdmon.model.string import DrillString
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well

# the truth of these tests has no sensor hysteresis; the hook-load measurement is as modelled
SETTINGS = JointSettings(hysteresis=0.0)
#: friction and weight alone: the hook-load sensor taken as configured (a new tuple, so the
#: estimator does not fit the rig's measurement parameters in, `tdmon.calib.joint.for_rig`)
KNOWN_SENSOR = CalibrationSettings(joint=JointSettings(
    parameters=EstimatedParameters(tuple(FRICTION_AND_WEIGHT)), hysteresis=0.0))


def _scaled(well: Well, factor: float) -> WellModel:
    """The same well with every component's buoyed weight per metre times ``factor``."""
    weights = [c.buoyed_weight_in(well.fluid.density, well.fluid.inside_density)
               for c in well.string.components]
    string = DrillString(tuple(replace(c, buoyed_weight=factor * wt, weight_in_air=None)
                               for c, wt in zip(well.string.components, weights, strict=True)))
    return WellModel(replace(well, string=string))


def _window(state: str, t: float, depth: float, hookload: float, se: float = 3e3,
            torque: float | None = None, torque_se: float | None = None) -> Window:
    return Window(state, t - 30.0, t, 30, depth, depth, depth, hookload, se, torque=torque,
                  torque_se=torque_se, rpm=10.0 if torque is not None else None)


def test_hook_load_is_homogeneous_in_the_weight_factor(model_open: WellModel) -> None:
    # the premise of the linear weight factor: B + w F(mu) equals a model with weights times w
    truth = _scaled(model_open.well, 0.93)
    block = model_open.well.block_weight
    for operation in ("pick_up", "slack_off", "static", "rotating"):
        for depth in (2500.0, 3900.0):
            hook, torque = model_open.evaluate(operation, depth, 0.28)
            true_hook, true_torque = truth.evaluate(operation, depth, 0.28)
            assert true_hook - block == pytest.approx(0.93 * (hook - block), rel=1e-9)
            assert true_torque == pytest.approx(0.93 * torque, rel=1e-9, abs=1e-6)


def test_volve_pick_up_and_slack_off_give_one_friction_and_a_lighter_string() -> None:
    # the trip-out figures: at ~2390 m pick-up alone gives 0.22 and slack-off 0.33 at
    # the modelled weight; one friction of ~0.26 with a string 30-45 kN lighter explains both
    well = load_well_model("config/wells/volve-f4.toml")
    model = WellModel(well)
    estimator = FrictionEstimator(model, KNOWN_SENSOR)
    state = estimator.initial_state()
    rng = np.random.default_rng(3)
    joint: list[dict[str, Any]] = []
    alarms: list[dict[str, Any]] = []
    singles: dict[str, list[float]] = {"pick_up": [], "slack_off": []}
    for k in range(8):
        for state_name, mu in (("pick_up", 0.22), ("slack_off", 0.33)):
            depth = 2400.0 - 2.5 * k
            hook = model.evaluate(state_name, depth, mu)[0] + rng.normal(0.0, 3e3)
            t = 1.6e9 + 120.0 * k + (60.0 if state_name == "slack_off" else 0.0)
            state, outputs = estimator.update(state, _window(state_name, t, depth, hook))
            for topic, message in outputs:
                if message.get("kind") == "joint":
                    joint.append(message)
                elif message.get("kind") == "window":
                    singles[state_name].append(message["mu"])
                elif topic == "alarm":
                    alarms.append(message)
    assert np.median(singles["pick_up"]) == pytest.approx(0.22, abs=0.01)
    assert np.median(singles["slack_off"]) == pytest.approx(0.33, abs=0.01)
    last = joint[-1]
    assert last["identifiable"] and last["identifiability"] == "identifiable"
    assert 0.24 <= last["mu"] <= 0.29
    assert -45e3 <= last["weight_difference_N"] <= -30e3
    assert last["correlation"] ** 2 < 0.5  # the pair crosses: friction and weight separated
    mismatch = [a for a in alarms if a["kind"] == "weight_mismatch"]
    assert len(mismatch) == 1
    text = mismatch[0]["message"]
    lighter = -last["weight_difference_N"] / 1e3
    assert "lighter than modelled" in text and "kN" in text and "%" in text
    assert abs(float(text.split("string ")[1].split(" kN")[0]) - lighter) < 3.0
    assert "kg/m3" not in text or "rather than 1080" in text  # never an impossible density


def test_pick_up_alone_is_not_identifiable(model_open: WellModel) -> None:
    state = initial_joint(SETTINGS)
    for k in range(12):
        depth = 3800.0 - 28.0 * k
        hook = model_open.evaluate("pick_up", depth, 0.3)[0]
        state = update_joint(state, model_open, _window("pick_up", 60.0 * k, depth, hook),
                             model_open.well.block_weight, {}, SETTINGS)
    verdict = identifiability(state, SETTINGS)
    assert not verdict.identifiable
    assert verdict.statement.startswith("pick-up only: weight and friction not separable")
    fields = joint_fields(state, SETTINGS)
    # the friction published is the one at the prior weight: the single window's
    assert fields["mu"] == pytest.approx(0.3, abs=0.005)
    assert fields["weight_factor_std"] > 0.8 * SETTINGS.parameters.get("weight_factor").prior_std


def _trip(model: WellModel, mu: float, factor: float, rng: np.random.Generator,
          scatter: float, stands: int = 14) -> dict[str, Any]:
    """A trip out with a pick-up per stand, a slack-off every 4th and rotation off bottom every
    5th stand; the joint estimate at the end, with the scatter estimated as the estimator does.
    Each window's weight is off by a further 0.2 % (model error: heave, locked stresses)."""
    truths = [_scaled(model.well, factor * (1.0 + e)) for e in (-0.004, -0.002, 0.0, 0.002,
                                                                  0.004)]
    block = model.well.block_weight
    state = initial_joint(SETTINGS)
    spread: dict[str, Scatter] = {}
    depth = rng.uniform(3300.0, 4000.0)
    t = 0.0
    for k in range(stands):
        plan = ["pick_up"] + (["slack_off"] if k % 4 == 1 else []) + (
            ["rotating_off_bottom"] if k % 5 == 2 else [])
        for name in plan:
            t += 60.0
            mu_k = max(mu + rng.normal(0.0, scatter), 0.01)
            truth = truths[int(rng.integers(len(truths)))]  # sd 0.28 % of the weight
            if name == "rotating_off_bottom":
                hook, torque = truth.evaluate("rotating", depth, mu_k)
                window = _window(name, t, depth, hook + rng.normal(0.0, 3e3), 3e3,
                                 torque + rng.normal(0.0, 200.0), 200.0)
                kind = "rotating_torque"
            else:
                hook = truth.evaluate(name, depth, mu_k)[0]
                window = _window(name, t, depth, hook + rng.normal(0.0, 3e3))
                kind = name
            taus = {key: scatter_std(value, SETTINGS.scatter_prior)
                    for key, value in spread.items()}
            state = update_joint(state, model, window, block, taus, SETTINGS,
                                 last_motion="rotating" if name == "rotating_off_bottom"
                                 else name)
            single = back_calculate_window(model, window)
            spread[kind] = add_window(spread.get(kind, Scatter()), single.mu, single.mu_std,
                                      SETTINGS.scatter_windows)
        depth -= 28.0
    return joint_fields(state, SETTINGS)


def test_95_percent_intervals_cover_the_truth(model_open: WellModel) -> None:
    # Monte-Carlo: true friction 0.15-0.35, weight factor off by up to +-8 % (fluid density,
    # fill level, mass per metre), joint-to-joint friction scatter 0.01-0.04, 3 kN noise
    rng = np.random.default_rng(12)
    runs = 150
    covered = {"mu": 0, "weight_factor": 0}
    for _ in range(runs):
        mu, factor = rng.uniform(0.15, 0.35), rng.uniform(0.92, 1.08)
        fields = _trip(model_open, mu, factor, rng, rng.uniform(0.01, 0.04))
        assert fields["identifiable"]
        covered["mu"] += abs(fields["mu"] - mu) <= 1.96 * fields["mu_std"]
        covered["weight_factor"] += (abs(fields["weight_factor"] - factor)
                                     <= 1.96 * fields["weight_factor_std"])
    for name, hits in covered.items():
        assert 0.90 <= hits / runs <= 0.98, (name, hits / runs)


def test_scatter_is_the_spread_of_consecutive_windows() -> None:
    rng = np.random.default_rng(5)
    spread = Scatter()
    for _ in range(30):
        spread = add_window(spread, 0.2 + rng.normal(0.0, 0.03), 0.01, 30)
    tau = scatter_std(spread, 0.02)
    # 0.03 drawn, 0.01 of it measurement: tau ~ sqrt(0.03^2 - 0.01^2) = 0.028
    assert 0.018 < tau < 0.04
    assert scatter_std(Scatter((0.2, 0.21), (0.01, 0.01)), 0.02) == 0.02  # prior until 5
    assert math.isfinite(scatter_std(add_window(spread, math.nan, 0.01, 30), 0.02))


def _unfilled(well: Well, depth: float, empty: float) -> WellModel:
    """``well`` with the top ``empty`` metres of pipe run without being filled, bit at
    ``depth``: that stretch weighs its inside fluid less."""
    bha, pipe = well.string.components
    rho = well.fluid.density
    inside = rho * 9.80665 * math.pi / 4.0 * pipe.inner_diameter**2
    assert pipe.buoyed_weight is not None
    filled = replace(pipe, length=depth - bha.length - empty)
    dry = replace(pipe, name="unfilled pipe", length=empty + 500.0,
                  buoyed_weight=pipe.buoyed_weight - inside)
    return WellModel(replace(well, string=DrillString((bha, filled, dry))))


def test_unfilled_pipe_is_named_with_its_level(model_open: WellModel) -> None:
    # the top 400 m run empty: the string hangs lighter by the missing inside fluid
    # (1200 kg/m3 in a 108 mm bore, 108 N/m over 400 m of vertical pipe: 43 kN)
    estimator = FrictionEstimator(model_open, KNOWN_SENSOR)
    state = estimator.initial_state()
    rng = np.random.default_rng(8)
    alarms: list[dict[str, Any]] = []
    joint: list[dict[str, Any]] = []
    t = 1.6e9
    for k in range(10):
        depth = 3600.0 - 28.0 * k
        truth = _unfilled(model_open.well, depth, 400.0)
        plan = ["pick_up", "slack_off"] + (["rotating_off_bottom"] if k % 3 == 0 else [])
        for name in plan:
            t += 90.0
            mu = 0.28 + rng.normal(0.0, 0.01)
            if name == "rotating_off_bottom":
                hook, torque = truth.evaluate("rotating", depth, mu)
                window = _window(name, t, depth, hook + rng.normal(0.0, 3e3), 3e3,
                                 torque + rng.normal(0.0, 200.0), 200.0)
            else:
                window = _window(name, t, depth,
                                 truth.evaluate(name, depth, mu)[0] + rng.normal(0.0, 3e3))
            state, outputs = estimator.update(state, window)
            joint += [m for _, m in outputs if m.get("kind") == "joint"]
            alarms += [m for topic, m in outputs if topic == "alarm"]
    last = joint[-1]
    assert last["identifiable"]
    assert last["mu"] == pytest.approx(0.28, abs=0.02)
    assert -50e3 < last["weight_difference_N"] < -36e3
    mismatch = [a for a in alarms if a["kind"] == "weight_mismatch"]
    assert len(mismatch) == 1
    level = float(mismatch[0]["message"].split("empty down to about ")[1].split(" m")[0])
    assert 340.0 <= level <= 460.0


def test_mismatch_names_only_possible_causes() -> None:
    from dataclasses import replace as change

    from tdmon.calib.mismatch import Mismatch, empty_length, mismatch_alarm, mud_density_for
    from tdmon.model.well import Fluid

    well = load_well_model("config/wells/volve-f4.toml")  # weights in air, 1080 kg/m3
    model = WellModel(well)
    air = WellModel(change(well, fluid=Fluid(0.0)))
    static = model.evaluate("static", 2400.0, 0.0)[0] - well.block_weight
    # an independent computation: the same well in a heavier mud weighs this much less
    heavier = WellModel(change(well, fluid=Fluid(1150.0)))
    difference = heavier.evaluate("static", 2400.0, 0.0)[0] - well.block_weight - static
    assert mud_density_for(model, air, 2400.0, difference) == pytest.approx(1150.0, rel=1e-3)
    # 12 % lighter would need mud 40 % heavier: no density is named, the fill level is
    assert mud_density_for(model, air, 2400.0, -0.12 * static) is None
    level = empty_length(model, 2400.0, 0.12 * static)
    assert level is not None and 0.0 < level < 2400.0
    assert empty_length(model, 2400.0, 2.0 * static) is None  # more than all the fluid inside
    memory = Mismatch()
    alarms = []
    for k in range(4):
        memory, alarm = mismatch_alarm(memory, model, air, float(k), 2400.0, 0.88, 0.01, 0.2,
                                       True, tolerance=0.01, windows=3)
        alarms += [alarm] if alarm is not None else []
    assert len(alarms) == 1 and alarms[0].t == 2.0  # the third in a row, once
    text = alarms[0].message
    assert "12.0 %" in text and "lighter" in text and "kg/m3" not in text
    assert f"empty down to about {level:.0f} m" in text
    assert "or the hook-load sensor reading 12.0 % low (its calibration)?" in text
    assert "block weight" not in text  # not estimated here
    # a block weight known to 60 kN could hide a good part of the difference: named
    memory, alarm = mismatch_alarm(Mismatch(), model, air, 0.0, 2400.0, 0.88, 0.01, 0.2,
                                   True, tolerance=0.01, windows=1, block=(300e3, 60e3))
    assert alarm is not None and "the block weight is known to 60 kN only (300 kN)" in \
        alarm.message
    memory, alarm = mismatch_alarm(Mismatch(), model, air, 0.0, 2400.0, 0.88, 0.01, 0.2,
                                   True, tolerance=0.01, windows=1, block=(300e3, 3e3))
    assert alarm is not None and "block weight" not in alarm.message
    # heavier, not identified: nothing; identified: mud lighter or heavier pipe
    memory, alarm = mismatch_alarm(Mismatch(), model, air, 0.0, 2400.0, 1.03, 0.005, 0.2,
                                   False, tolerance=0.01, windows=1)
    assert alarm is None
    memory, alarm = mismatch_alarm(Mismatch(), model, air, 0.0, 2400.0, 1.03, 0.005, 0.2,
                                   True, tolerance=0.01, windows=1)
    assert alarm is not None and "heavier than modelled" in alarm.message
    assert "rather than 1080" in alarm.message and "mass per metre" in alarm.message


def test_the_weight_prior_comes_from_the_daemon_file(tmp_path: Any) -> None:
    from pathlib import Path

    from tdmon.config.daemon import load_daemon_config
    from tdmon.daemon.steps.calibrate import CalibrationStep
    from tdmon.daemon.steps.compose import calibration_steps_for
    from tdmon.errors import ConfigError

    shipped = Path("config/daemon/replay-rig-f4.toml").resolve()
    text = shipped.read_text().replace('well = "../wells/volve-f4.toml"',
                                       f'well = "{(shipped.parent / "../wells/volve-f4.toml")}"')
    text = text.replace('path = "../../replays/volve-f4-trip-out.mcap"',
                        f'path = "{Path("replays/volve-f4-trip-out.mcap").resolve()}"')
    good = tmp_path / "daemon.toml"
    good.write_text(text.replace("[calibration]\n", "[calibration]\nweight_factor = 0.97\n"
                                 "weight_factor_std = 0.02\nweight_mismatch_tolerance = 0.03\n"))
    _, steps = calibration_steps_for(load_daemon_config(good))
    step = next(s for s in steps if isinstance(s, CalibrationStep))
    joint = step.settings.joint
    weight = joint.parameters.get("weight_factor")
    assert (weight.prior, weight.prior_std, joint.mismatch_tolerance) == (0.97, 0.02, 0.03)
    assert step.state.windows.joint is not None
    assert step.state.windows.joint.mean[1] == 0.97
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[calibration]\n", "[calibration]\nweight_factor_std = 0\n"))
    with pytest.raises(ConfigError, match="weight_factor_std"):
        load_daemon_config(bad)
