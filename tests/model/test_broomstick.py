"""Broomstick: one compiled sweep equal to the single-depth model, per-element friction cases."""

from __future__ import annotations

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model.broomstick import broomstick, broomstick_from_model
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.torque_drag import WellModel, torque_drag
from tdmon.model.well import Well, hole_grid


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_broomstick_equals_single_depth_model(three_d: Well, method: str) -> None:
    depths = np.array([500.0, 1234.5, 2075.0, 3000.0, 3600.0])
    mus = [0.1, 0.25, 0.4]
    result = broomstick(three_d, depths, mus, method=method)
    assert result.hookload["pick_up"].shape == (3, 5)
    assert result.mu == pytest.approx(mus)
    for i, mu in enumerate(mus):
        for j, depth in enumerate(depths):
            loads = torque_drag(three_d, depth, mu, method=method)
            for operation in ("pick_up", "slack_off", "rotating"):
                assert result.hookload[operation][i, j] == loads.hookload[operation]
            assert result.surface_torque["rotating"][i, j] == loads.surface_torque["rotating"]


def test_broomstick_with_per_element_friction(three_d: Well) -> None:
    grid = hole_grid(three_d)
    mid = grid.element_mid_md
    cases = np.stack([
        np.where(grid.element_kind == "cased", 0.2, 0.3),  # the sections' own friction
        0.2 + 1e-4 * mid / 10.0,  # rising with depth, as a temperature-dependent mu would
    ])
    depths = [1500.0, 3600.0]
    result = broomstick(three_d, depths, cases)
    from_sections = WellModel(three_d)
    for j, depth in enumerate(depths):
        assert result.hookload["pick_up"][0, j] == from_sections.evaluate("pick_up", depth)[0]
        loads = torque_drag(three_d, depth, cases[1])
        assert result.hookload["slack_off"][1, j] == loads.hookload["slack_off"]
        assert result.surface_torque["rotating"][1, j] == loads.surface_torque["rotating"]
    # case labels: the length-weighted mean friction of each case
    lengths = np.diff(grid.md)
    assert result.mu == pytest.approx(cases @ lengths / lengths.sum())


def test_broomstick_fans_out_with_friction(example_71: Well) -> None:
    result = broomstick(example_71, np.linspace(500.0, 4223.0, 12), [0.0, 0.2, 0.4])
    pick_up, slack_off = result.hookload["pick_up"], result.hookload["slack_off"]
    assert np.array_equal(pick_up[0], slack_off[0])  # no friction, no spread
    assert (np.diff(pick_up[:, -1]) > 0).all() and (np.diff(slack_off[:, -1]) < 0).all()
    assert np.array_equal(result.hookload["rotating"][0], result.hookload["rotating"][2])
    # in the vertical part (above the 1500 m kick-off) there is no spread at all
    assert pick_up[2, 0] == pytest.approx(slack_off[2, 0], rel=1e-12)


def test_broomstick_limit_lines(example_71: Well) -> None:
    bha, _pipe = example_71.string.components
    pipe = StringComponent("drill pipe", 4100.0, 0.127, 0.1086, buoyed_weight=300.0,
                           yield_strength=517e6, makeup_torque=30e3)
    well = Well(example_71.survey, DrillString((bha, pipe)), example_71.sections,
                example_71.fluid, block_weight=100e3)
    result = broomstick(well, [150.0, 3000.0], [0.2])
    assert np.isnan(result.hookload_limit[0])  # only the BHA (no yield given) is in the hole
    assert result.hookload_limit[1] == pytest.approx(pipe.area * 517e6 + 100e3)
    assert result.makeup_torque_limit[1] == 30e3


def test_broomstick_rejects_bad_inputs(example_71: Well) -> None:
    model = WellModel(example_71)
    with pytest.raises(ModelError, match=r"below the hole|deeper than the drill string"):
        broomstick_from_model(model, [1000.0, 9000.0], [0.2])
    with pytest.raises(ModelError, match="one value per hole-grid element"):
        broomstick_from_model(model, [1000.0], np.full((2, 7), 0.2))
    with pytest.raises(ModelError, match="2-D array"):
        broomstick_from_model(model, [1000.0], np.full((2, 2, 2), 0.2))
