"""The monitor's drilling frames: the drilling curve at the frame's weight on bit and bit
torque (the torque step at the tag, the MWD's, or Pessier and Fear's), residuals against it,
the weight at the bit from the hook load, and the ``[monitor]`` bit model's settings."""

from __future__ import annotations

from typing import Any

import jsonschema
import numpy as np
import pytest
from daemon_support import make_config

from tdmon.calib.measurement import SensorEstimate
from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.compose import drilling_monitor
from tdmon.daemon.steps.monitor import DrillingMonitor, GridLoadModel, MonitorStep
from tdmon.errors import ConfigError
from tdmon.model.hookload_sensor import HookloadSensor
from tdmon.record.schemas import MODEL

DEPTH = 3000.0
# one grid interval: every curve constant with depth, so the loads at 3000 m are these
PICK_UP, SLACK_OFF, ROTATING, TORQUE = 1.4e6, 1.0e6, 1.2e6, 20e3
TORQUE_PER_WOB = -0.02  # [m]: 50 kN on the bit takes 1 kN m off the string's torque


def _model() -> GridLoadModel:
    rows = [PICK_UP, SLACK_OFF, ROTATING, TORQUE, PICK_UP, SLACK_OFF]
    curves = np.array([[v, v] for v in rows])
    slopes = np.array([[-1.0, -1.0], [TORQUE_PER_WOB, TORQUE_PER_WOB]])
    return GridLoadModel(np.array([0.0, 5000.0]), curves, (0.25,), slopes)


def _frame(t: float, state: str, hookload: float, torque: float, **values: float) -> Frame:
    return Frame(t, int(t * 1e9), {"hookload": hookload, "torque": torque, "bit_depth": DEPTH,
                                   "hole_depth": DEPTH, **values}, {}, state=state,
                 steady=True)


def _run(step: MonitorStep, frames: list[Frame]) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for frame in frames:
        step.on_frame(frame, lambda topic, message: out.append(message))
    return out


def _tag_then_drill(**values: float) -> list[Frame]:
    # 20 kN m off bottom; on bottom with 50 kN: 20 - 1 (the string) + 5 (the bit) = 24 kN m,
    # and the hook load 1 kN above the modelled on-bottom load
    off = [_frame(t, "rotating_off_bottom", ROTATING, TORQUE) for t in (0.0, 5.0)]
    on = [_frame(t, "drilling", ROTATING - 50e3 + 1e3, 24e3, wob=50e3, **values)
          for t in (10.0, 15.0)]
    return off + on


def test_drilling_frames_are_read_against_the_drilling_curve() -> None:
    messages = _run(MonitorStep(_model()), _tag_then_drill())
    off, drilling = messages[0], messages[-1]
    assert "drilling" not in off and set(off["hookload_N"]) == {"pick_up", "slack_off",
                                                                "rotating"}
    assert drilling["hookload_N"]["drilling"] == pytest.approx(ROTATING - 50e3)
    assert drilling["residual"]["hookload_N"] == pytest.approx(1e3)
    # the bit torque of the tag: 24 - 20 - (-1) = 5 kN m, so the drilling torque is 24 kN m
    view = drilling["drilling"]
    assert (view["bit_torque_source"], view["wob_source"]) == ("tag", "surface")
    assert view["bit_torque_Nm"] == pytest.approx(5e3)
    assert drilling["torque_Nm"]["drilling"] == pytest.approx(24e3)
    assert drilling["residual"]["torque_Nm"] == pytest.approx(0.0, abs=1e-6)
    # from the hook load: 1 kN less on the bit than the surface's 50 kN; no sensor estimate,
    # so no standard deviation
    assert view["wob_estimated_N"] == pytest.approx(49e3)
    assert view["wob_estimated_std_N"] is None and view["wob_downhole_N"] is None
    for message in messages:
        jsonschema.validate(message, MODEL)


def test_the_mwd_weight_and_torque_win_when_present() -> None:
    frames = _tag_then_drill(downhole_wob=55e3, downhole_torque=6e3)
    drilling = _run(MonitorStep(_model()), frames)[-1]
    view = drilling["drilling"]
    assert (view["wob_source"], view["wob_N"], view["wob_surface_N"]) == ("downhole", 55e3, 50e3)
    assert (view["bit_torque_source"], view["bit_torque_Nm"]) == ("downhole", 6e3)
    assert drilling["hookload_N"]["drilling"] == pytest.approx(ROTATING - 55e3)
    # 20 - 0.02 * 55 + 6 = 24.9 kN m
    assert drilling["torque_Nm"]["drilling"] == pytest.approx(24.9e3)


def test_before_a_tag_the_bit_model_gives_the_torque_and_without_it_none() -> None:
    frame = _frame(0.0, "drilling", ROTATING - 100e3, 25e3, wob=100e3)
    bare = _run(MonitorStep(_model()), [frame])[0]
    assert bare["torque_Nm"]["drilling"] is None and bare["residual"]["torque_Nm"] is None
    assert bare["residual"]["hookload_N"] == pytest.approx(0.0, abs=1e-6)
    modelled = _run(MonitorStep(_model(), drilling=DrillingMonitor((0.2159, 0.3))), [frame])[0]
    # Pessier and Fear: 0.3 * 100 kN * 0.2159 m / 3 = 2159 N m
    assert modelled["drilling"]["bit_torque_source"] == "model"
    assert modelled["torque_Nm"]["drilling"] == pytest.approx(TORQUE - 2e3 + 2159.0)


def test_the_drilling_curve_and_the_weight_at_the_bit_through_the_sensor() -> None:
    # the sensor reads the load on the hook 5 kN high (its offset, known to 2 kN) with the
    # block 10 kN heavier than the model's 300 kN
    estimate = SensorEstimate(HookloadSensor(), 310e3, 0.0, offset=5e3, offset_std=2e3)
    step = MonitorStep(_model(), sensor=lambda: (estimate, 300e3))
    reading = ROTATING - 40e3 + 15e3
    message = _run(step, [_frame(0.0, "drilling", reading, 22e3, wob=40e3)])[0]
    assert message["hookload_N"]["drilling"] == pytest.approx(ROTATING - 40e3 + 15e3)
    assert message["residual"]["hookload_N"] == pytest.approx(0.0, abs=1e-6)
    assert message["drilling"]["wob_estimated_N"] == pytest.approx(40e3)
    assert message["drilling"]["wob_estimated_std_N"] == pytest.approx(2e3)


def test_the_bit_model_needs_both_its_settings() -> None:
    source = {"sources": {"mcap": {"path": "replay.mcap"}}}
    config = make_config({**source, "monitor": {"bit_diameter": "8.5 in", "bit_friction": 0.3}})
    monitor = drilling_monitor(config)
    assert monitor.bit == pytest.approx((0.2159, 0.3))
    assert monitor.settle == 30.0
    assert drilling_monitor(make_config(source)).bit is None
    with pytest.raises(ConfigError, match="bit_diameter and bit_friction"):
        make_config({**source, "monitor": {"bit_diameter": "8.5 in"}})
