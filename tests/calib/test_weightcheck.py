"""The weight check of static hangs: three odd hangs in a row alarm, in kN and % of the
modelled string weight, and a hang no fluid or tally error could explain points at the bit
depth instead (the Volve F-4 log's depth reset to 1 m under a 1100 kN string)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from tdmon.calib.alarms import Alarm
from tdmon.calib.blockweight import BuoyancyCheck
from tdmon.calib.weightcheck import ODD_HANGS, weight_check
from tdmon.calib.windows import Window
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid
from tdmon.vocabulary import Operation, RigState, Severity

BLOCK = 400e3


def _hang(bit_depth: float, string_weight: float) -> Window:
    return Window(RigState.STATIC, 0.0, 30.0, 10, bit_depth, bit_depth, bit_depth,
                  BLOCK + string_weight, 1e3)


def _three(model: WellModel, bit_depth: float, string_weight: float
           ) -> tuple[BuoyancyCheck, Alarm | None]:
    air = WellModel(replace(model.well, fluid=Fluid(0.0)))
    odd, alarm = 0, None
    for _ in range(ODD_HANGS):
        checked = weight_check(model, air, _hang(bit_depth, string_weight), BLOCK, odd,
                               0.02)
        assert checked is not None
        check, odd, alarm = checked
    return check, alarm


def test_a_lighter_string_is_reported_in_kn_and_percent(model_open: WellModel) -> None:
    depth = 3000.0
    modelled = model_open.evaluate(Operation.STATIC, depth, 0.0)[0] - model_open.well.block_weight
    check, alarm = _three(model_open, depth, 0.95 * modelled)
    assert check.ratio == pytest.approx(0.95, abs=1e-6)
    assert alarm is not None and alarm.severity == Severity.INFO
    assert f"{0.05 * modelled / 1e3:.0f} kN (5.0 %) lighter" in alarm.message
    assert "kg/m3" not in alarm.message


def test_a_hang_no_weight_error_explains_points_at_the_bit_depth(model_open: WellModel) -> None:
    # a 1100 kN string hanging while the bit depth reads 1 m
    check, alarm = _three(model_open, 1.0, 1100e3)
    assert check.ratio > 100
    assert alarm is not None and alarm.severity == Severity.WARNING
    assert "check the bit-depth tracking" in alarm.message
    assert "%" not in alarm.message and "1100 kN of string" in alarm.message
