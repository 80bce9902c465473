"""The fluid step (tdmon.daemon.steps.fluids) and where its terms enter: the monitor's curves
(`with_fluid`) and the calibration's samples (`without_fluid`); the hydraulics message against
its JSON Schema, the trip_speed alarm once per excursion."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any, cast

import jsonschema
import pytest

from tdmon.calib.rigstate import RigSample
from tdmon.config.well import load_well_model
from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.calibrate import without_fluid
from tdmon.daemon.steps.fluids import FLUID_RESULT, FluidEffect, FluidStep
from tdmon.daemon.steps.monitor import ModelledLoads, with_fluid
from tdmon.daemon.steps.rig_state import RigStateStep
from tdmon.model.fluid_force import HydraulicModel
from tdmon.model.fluid_tracking import FluidTracker
from tdmon.model.torque_drag import WellModel
from tdmon.record.schemas import schema_for

WELLS = Path(__file__).resolve().parents[2] / "replays" / "scenarios" / "wells"
BIT = 3600.0
MU = 0.25


class _Detector:
    """What the fluid step reads of the rig-state step: the last sample's time and velocity."""

    def __init__(self) -> None:
        self.last_sample: Any = None
        self.last_detection: Any = None

    def saw(self, t: float, velocity: float) -> None:
        self.last_sample = SimpleNamespace(t=t)
        self.last_detection = SimpleNamespace(velocity=velocity)


@pytest.fixture(scope="module")
def parts() -> tuple[WellModel, HydraulicModel]:
    well = load_well_model(WELLS / "example-7-1-viscous.toml")
    model = WellModel(well)
    return model, HydraulicModel(well, model.grid)


def _step(parts: tuple[WellModel, HydraulicModel]) -> tuple[FluidStep, _Detector]:
    model, hydraulic = parts
    detector = _Detector()
    tracker = FluidTracker(model.well, model.grid, bit_depth=BIT)
    step = FluidStep(model, hydraulic, tracker, MU, rig_state=cast(RigStateStep, detector))
    return step, detector


def _frame(t: float, state: str, **values: float) -> Frame:
    return Frame(t=t, log_time_ns=int(t * 1e9), values={"bit_depth": BIT, **values}, ages={},
                 state=state)


def _run(step: FluidStep, frame: Frame) -> list[tuple[str, dict[str, Any]]]:
    out: list[tuple[str, dict[str, Any]]] = []
    step.on_frame(frame, lambda topic, message: out.append((topic, message)))
    return out


def test_a_pull_carries_the_swab_drag_of_the_measured_speed(
        parts: tuple[WellModel, HydraulicModel]) -> None:
    """Pulling at 0.3 m/s: the pick-up curve's change is the model's hook load with the fluid
    terms at -0.3 m/s less without, the slack-off curve's at +0.3 m/s, the rotating curve's
    at rest (no pumps: zero); the frame's own change is the pick-up one."""
    model, hydraulic = parts
    step, detector = _step(parts)
    detector.saw(100.0, -0.3)
    out = _run(step, _frame(100.0, "pick_up"))
    effect = out[0][1]
    frame_effect: FluidEffect = step_effect(step, detector)
    up = hydraulic.forces(BIT, -0.3).terms
    down = hydraulic.forces(BIT, 0.3).terms
    expected_up = (model.evaluate("pick_up", BIT, MU, fluid=up)[0]
                   - model.evaluate("pick_up", BIT, MU)[0])
    expected_down = (model.evaluate("slack_off", BIT, MU, fluid=down)[0]
                     - model.evaluate("slack_off", BIT, MU)[0])
    assert expected_up == pytest.approx(22.2e3, rel=0.02)  # 0.3 m/s swab: about 22 kN
    assert frame_effect.curve_hookload["pick_up"] == pytest.approx(expected_up, rel=1e-9)
    assert frame_effect.curve_hookload["slack_off"] == pytest.approx(expected_down, rel=1e-9)
    assert expected_down < -10e3
    assert frame_effect.curve_hookload["rotating"] == 0.0
    assert effect["fluid_hookload_N"] == pytest.approx(expected_up, rel=1e-9)
    assert effect["surge_Pa"]["bit"] < -5e5  # swab at the bit
    assert effect["density_kg_m3"]["bit"] < 1400.0


def step_effect(step: FluidStep, detector: _Detector) -> FluidEffect:
    """The step's effect on a fresh pick-up frame at the detector's last time."""
    frame = _frame(detector.last_sample.t, "pick_up")
    _run(step, frame)
    return cast(FluidEffect, frame.results[FLUID_RESULT]["effect"])


def test_the_hydraulics_message_meets_its_schema(parts: tuple[WellModel, HydraulicModel]) -> None:
    step, detector = _step(parts)
    detector.saw(10.0, 0.4)
    out = _run(step, _frame(10.0, "slack_off", flow_in=0.0))
    topics = [topic for topic, _ in out]
    assert topics == ["hydraulics"]
    jsonschema.validate(out[0][1], schema_for("/tdmon/hydraulics"))
    limits = out[0][1]["trip_speed_limit_m_s"]
    assert 0.3 < limits["pulling_out"] < 0.6  # swab to the 1360 kg/m3 pore density
    assert limits["running_in"] > 2.0


def test_the_trip_speed_alarm_fires_once_per_excursion(
        parts: tuple[WellModel, HydraulicModel]) -> None:
    """The pulling-out limit is about 0.42 m/s at 3600 m: 0.6 m/s alarms once, again only
    after the string stood still."""
    step, detector = _step(parts)
    kinds = []
    for t, velocity in ((1.0, -0.2), (2.0, -0.6), (3.0, -0.6), (4.0, 0.0), (5.0, -0.6)):
        detector.saw(t, velocity)
        kinds += [m for topic, m in _run(step, _frame(t, "pick_up")) if topic == "alarm"]
    assert [a["t"] for a in kinds] == [2.0, 5.0]
    assert {a["kind"] for a in kinds} == {"trip_speed"}
    assert kinds[0]["value"] == pytest.approx(0.6)
    assert 0.3 < kinds[0]["limit"] < 0.6


def test_circulating_pushes_the_string_up_by_the_jets(
        parts: tuple[WellModel, HydraulicModel]) -> None:
    """Pumps at 2000 L/min through three 12/32 in nozzles, string still: the hook load of a
    hang falls by the jets' force (about 7.3 kN, bit_force) and the annular flow's drag."""
    model, hydraulic = parts
    step, detector = _step(parts)
    detector.saw(1.0, 0.0)
    flow = 2000.0 / 60000.0
    frame = _frame(1.0, "circulating", flow_in=flow)
    message = _run(step, frame)[0][1]
    terms = hydraulic.forces(BIT, 0.0, flow_rate=flow).terms
    expected = (model.evaluate("static", BIT, MU, fluid=terms)[0]
                - model.evaluate("static", BIT, MU)[0])
    assert message["bit_force_N"] == pytest.approx(-7.28e3, rel=0.01)
    assert message["fluid_hookload_N"] == pytest.approx(expected, rel=1e-9)
    assert expected < -7.28e3


def test_the_monitor_adds_and_the_calibration_takes_off_the_change() -> None:
    effect = FluidEffect({"pick_up": 20e3, "slack_off": -15e3, "rotating": -5e3},
                         {"pick_up": 0.0, "slack_off": 0.0, "rotating": -300.0},
                         hookload=20e3, torque=0.0)
    loads = ModelledLoads(3000.0, 1.0e6, 0.8e6, 0.9e6, 20e3, (0.1, 0.3), (0.95e6, 1.05e6),
                          (0.85e6, 0.75e6))
    shown = with_fluid(loads, effect)
    assert (shown.pick_up, shown.slack_off, shown.rotating) == (1.02e6, 0.785e6, 0.895e6)
    assert shown.torque_rotating == 19.7e3
    assert shown.band_pick_up == (0.97e6, 1.07e6)
    assert shown.band_slack_off == (0.835e6, 0.735e6)
    sample = RigSample(t=1.0, hookload=1.03e6, bit_depth=3000.0, block_position=10.0,
                       rpm=None, flow=None, spp=None, hole_depth=None, torque=500.0, wob=None)
    corrected = without_fluid(sample, effect)
    assert corrected.hookload == pytest.approx(1.01e6)
    assert corrected.torque == 500.0
    assert without_fluid(sample, FluidEffect({}, {}, 0.0, 0.0)) is sample
