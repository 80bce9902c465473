"""Drilling: the hole deepening under the bit as the rig state's evidence, tags and the bit
torque of each, Pessier and Fear's bit torque and the weight at the bit from the hook load,
by hand and against the torque-and-drag model's own on-bottom load."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tdmon.calib.drilling import (
    DrillingState,
    bit_torque_pessier,
    bit_torque_step,
    downhole_wob,
    drilling_friction,
    track,
)
from tdmon.calib.joint import JointSettings, _linearise, drilling_measurements
from tdmon.calib.measurement import SensorEstimate
from tdmon.calib.rigstate import RigStateThresholds, detect_series
from tdmon.calib.windows import Window
from tdmon.errors import FitError
from tdmon.model.hookload_sensor import HookloadSensor, SensorLocation
from tdmon.model.torque_drag import Operation, WellModel
from tdmon.vocabulary import RigState

TH = RigStateThresholds(block_weight=400e3)
RPM_120 = 120 * 2 * math.pi / 60
ROP = 21.0 / 3600.0  # the 21 m/h [m/s]


def _drilling_record(hole_advances: bool, bit_above: float = 0.0, n: int = 120
                     ) -> dict[str, np.ndarray]:
    # every 5 s for 10 minutes: the string turns at 120 rpm with a surface WOB of 8 kN, under
    # the 10 kN drilling threshold (the 6-10 kN while the MWD read 18 kN)
    t = np.arange(n) * 5.0
    hole = 3000.0 + (ROP if hole_advances else 0.0) * t
    return {"t": t, "hookload": np.full(n, 1.2e6), "bit_depth": hole - bit_above,
            "hole_depth": np.round(hole, 2), "rpm": np.full(n, RPM_120),
            "wob": np.full(n, 8e3), "flow": np.full(n, 0.03)}


def test_a_low_surface_wob_drills_while_the_hole_deepens_under_the_bit() -> None:
    record = _drilling_record(hole_advances=True)
    states, _ = detect_series(record.pop("t"), record.pop("hookload"),
                              record.pop("bit_depth"), TH, **record)
    # the first deepening of 5 cm (the third sample, 2.9 cm a sample) starts drilling
    assert set(states[:2]) == {"rotating_off_bottom"}
    assert set(states[3:]) == {"drilling"}


def test_the_same_string_turning_without_the_hole_deepening_is_off_bottom() -> None:
    for record in (_drilling_record(hole_advances=False),
                   _drilling_record(hole_advances=True, bit_above=1.0)):
        states, _ = detect_series(record.pop("t"), record.pop("hookload"),
                                  record.pop("bit_depth"), TH, **record)
        assert set(states) == {"rotating_off_bottom"}


def test_a_noisy_hole_depth_does_not_put_a_bit_10_m_off_bottom_on_bottom() -> None:
    # a synthetic replay's hole depth with 0.4 % noise (14 m at 3600 m) ten metres below the bit
    rng = np.random.default_rng(7)
    n = 400
    states, _ = detect_series(
        np.arange(n) * 5.0, np.full(n, 1.2e6), np.full(n, 3600.0), TH,
        hole_depth=3610.0 + 14.4 * rng.standard_normal(n), rpm=np.full(n, RPM_120),
        wob=np.zeros(n))
    assert "drilling" not in set(states)


def test_sliding_ahead_without_rotation_is_never_steady() -> None:
    record = _drilling_record(hole_advances=True)
    record["rpm"] = np.zeros_like(record["rpm"])
    states, steady = detect_series(record.pop("t"), record.pop("hookload"),
                                   record.pop("bit_depth"), TH, **record)
    assert set(states) == {"circulating"}  # 21 m/h is not a slack-off
    assert steady[:3].any() and not steady[3:].any()


def test_tags_and_the_bit_torque_of_the_torque_step() -> None:
    state = DrillingState()
    # steady off bottom: 20.0 and 20.2 kN m, mean 20.1
    for t, torque in ((0.0, 20.0e3), (5.0, 20.2e3)):
        state = track(state, t, "rotating_off_bottom", True, 2999.0, 3000.0, 1.2e6, torque)
    assert state.off_bottom_samples == 2 and state.off_bottom_torque == pytest.approx(20.1e3)
    # on bottom: 26 and 26.4 kN m, the weight on bit taking 0.5 kN m off the string's torque
    for t, torque in ((10.0, 26.0e3), (15.0, 26.4e3)):
        state = track(state, t, "drilling", True, 3000.0, 3000.0, 1.15e6, torque,
                      string_torque_change=-0.5e3, settle=30.0)
    [tag] = state.tags
    assert (tag.kind, tag.t, tag.off_bottom_torque) == ("on_bottom", 10.0, pytest.approx(20.1e3))
    assert tag.off_bottom_hookload == pytest.approx(1.2e6)
    # (26.0 - 20.1 + 0.5 + 26.4 - 20.1 + 0.5) / 2 = 6.6 kN m
    assert state.bit_torque == pytest.approx(6.6e3)
    # after the settling time the bit torque is kept
    state = track(state, 60.0, "drilling", True, 3000.4, 3000.4, 1.15e6, 40e3, settle=30.0)
    assert state.bit_torque == pytest.approx(6.6e3)
    state = track(state, 65.0, "pick_up", True, 2999.0, 3000.4, 1.3e6, 0.0)
    assert [tag.kind for tag in state.tags] == ["on_bottom", "off_bottom"]
    assert state.tags[-1].bit_depth == 2999.0 and state.off_bottom_torque is None
    assert bit_torque_step(26.0e3, 20.1e3, -0.5e3) == pytest.approx(6.4e3)


def test_pessier_and_fear_bit_torque_by_hand() -> None:
    # an 8 1/2 in bit (0.2159 m), 100 kN on it, mu_b 0.3: 0.3 * 1e5 * 0.2159 / 3 = 2159 N m
    torque = bit_torque_pessier(100e3, 0.2159, 0.3)
    assert torque == pytest.approx(2159.0)
    # their definition in field units, mu_b = 36 T / (D W), T [ft lbf], D [in], W [lbf]
    lbf, ft = 0.45359237 * 9.80665, 0.3048
    assert 36.0 * (torque / (lbf * ft)) / (8.5 * 100e3 / lbf) == pytest.approx(0.3)


def test_the_weight_at_the_bit_from_a_reading_by_hand() -> None:
    # a load cell: reading = B + F + o; B = 300 kN, o = 5 kN, off bottom F0 = 1000 kN
    estimate = SensorEstimate(HookloadSensor(), 300e3, 4e3, offset=5e3, offset_std=3e3)
    reading = 300e3 + (1000e3 - 80e3) + 5e3
    wob, std = downhole_wob(reading, 1000e3, estimate)
    assert wob == pytest.approx(80e3)
    assert std == pytest.approx(math.hypot(3e3, 4e3))  # 5 kN: the offset and block weight
    # what is not known of the string's weight adds in quadrature
    assert downhole_wob(reading, 1000e3, estimate, weight_std=12e3).std == pytest.approx(13e3)


def test_the_weight_at_the_bit_recovers_the_models_own(model_open: WellModel) -> None:
    # independent of the slope taken: the model's on-bottom hook load with 120 kN on the bit,
    # read by a deadline sensor lowering at the rate of penetration
    sensor = HookloadSensor(SensorLocation.DEADLINE, lines=10, efficiency=0.96)
    block = model_open.well.block_weight
    depth, wob = 3000.0, 120e3
    on_bottom = model_open.evaluate(Operation.ON_BOTTOM, depth, 0.25, wob=wob)[0]
    off_bottom = model_open.evaluate(Operation.ROTATING, depth, 0.25)[0] - block
    reading = float(sensor.reading(on_bottom, -1)) + 7e3
    estimate = SensorEstimate(sensor, block, 0.0, offset=7e3, efficiency=0.96)
    assert downhole_wob(reading, off_bottom, estimate).wob == pytest.approx(wob, rel=1e-9)


def _drilling_window(hookload: float, torque: float, wob: float | None,
                     bit_torque: float | None) -> Window:
    return Window(RigState.DRILLING, 0.0, 30.0, 30, 3000.0, 2999.9, 3000.1, hookload, 2e3,
                  torque=torque, torque_se=100.0, rpm=12.0, wob=wob, bit_torque=bit_torque)


def test_friction_from_the_models_own_drilling_torque(model_open: WellModel) -> None:
    # the model's surface torque on bottom at friction 0.3, 100 kN and a 2 kN m bit
    torque = model_open.evaluate(Operation.ON_BOTTOM, 3000.0, 0.3, wob=100e3,
                                 bit_torque=2e3)[1]
    solved = drilling_friction(model_open, 3000.0, 100e3, torque, 150.0, 2e3, 200.0)
    assert solved.mu == pytest.approx(0.3, abs=1e-5)
    assert solved.string_torque == pytest.approx(torque - 2e3)
    # the uncertainty: the torque's and the bit torque's through the slope dT/dmu
    assert solved.mu_std == pytest.approx(250.0 / solved.slope)
    with pytest.raises(FitError, match="cannot be matched"):
        drilling_friction(model_open, 3000.0, 100e3, 1e3, 150.0, 2e3)


def test_what_a_drilling_window_offers_the_joint_estimate(model_open: WellModel) -> None:
    window = _drilling_window(1.0e6, 18e3, 80e3, 2e3)
    hookload, torque = drilling_measurements(window)
    assert (hookload.operation, hookload.kind, hookload.motion, hookload.wob) == (
        "on_bottom", "drilling_hookload", -1, 80e3)
    assert (torque.kind, torque.value, torque.wob) == ("drilling_torque", 16e3, 80e3)
    assert drilling_measurements(_drilling_window(1.0e6, 18e3, 80e3, None)) == (hookload,)
    assert drilling_measurements(_drilling_window(1.0e6, 18e3, None, 2e3)) == ()
    # the weight factor scales the string, not the weight on the bit:
    # reading = B + w F_0 - W with F_0 the rotating top force
    block = model_open.well.block_weight
    f0 = model_open.evaluate(Operation.ROTATING, 3000.0, 0.25)[0] - block
    linear = _linearise(model_open, hookload, 3000.0, block, 0.0, JointSettings(), "soft-string")
    assert linear(np.array([0.25, 1.05])).predicted == pytest.approx(block + 1.05 * f0 - 80e3)
