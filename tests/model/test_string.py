"""Drill string: weight from dimensions (eq 41), buoyancy (eq 35, 36), components."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model.string import (
    GRAVITY,
    STEEL_DENSITY,
    DrillString,
    StringComponent,
    buoyancy_factor,
    buoyancy_factor_two_fluids,
    weight_per_length,
)

INCH = 0.0254


def test_buoyancy_factor_hand_values() -> None:
    # Table 4 of the thesis: mud 1.56 s.g., steel 7.85 s.g. -> 1 - 1.56/7.85 = 0.80127 ("0.8")
    assert float(buoyancy_factor(1560.0)) == pytest.approx(0.801274, abs=1e-6)
    assert float(buoyancy_factor(1000.0, steel_density=8000.0)) == 0.875
    assert float(buoyancy_factor(0.0)) == 1.0


def test_buoyancy_factor_arrays_match_scalars() -> None:
    densities = np.array([1000.0, 1200.0, 1560.0, 2000.0])
    factors = buoyancy_factor(densities)
    assert factors.shape == (4,)
    assert factors == pytest.approx([float(buoyancy_factor(d)) for d in densities])


def test_two_fluid_buoyancy_hand_value() -> None:
    # 5" x 4.276" pipe, 1500 kg/m3 outside, 1000 kg/m3 inside, by hand:
    # 1 - (1500 * 0.127^2 - 1000 * 0.1086^2) / (7850 * (0.127^2 - 0.1086^2))
    #   = 1 - (24.1935 - 11.79396) / (7850 * 0.00433504) = 1 - 12.39954 / 34.02999 = 0.635629
    factor = buoyancy_factor_two_fluids(1500.0, 1000.0, 0.127, 0.1086)
    assert float(factor) == pytest.approx(0.635629, abs=1e-6)


def test_two_fluid_buoyancy_reduces_to_eq_35_for_one_fluid() -> None:
    outer = np.array([0.127, 0.1683, 0.2032])
    inner = np.array([0.1086, 0.0762, 0.0714])
    factors = buoyancy_factor_two_fluids(1300.0, 1300.0, outer, inner)
    assert factors == pytest.approx(np.full(3, float(buoyancy_factor(1300.0))), rel=1e-12)
    lighter_inside = buoyancy_factor_two_fluids(1300.0, 1000.0, outer, inner)
    assert (lighter_inside < factors).all()  # a lighter fluid inside makes the pipe lighter


def test_weight_per_length_hand_value() -> None:
    # 5" pipe body, 0.1086 m bore (19.5 lb/ft nominal): pi/4 (0.127^2 - 0.1086^2) = 3.40470e-3 m2
    # x 7850 kg/m3 x 9.80665 = 262.10 N/m (plain tube: the nominal weight adds tool joints)
    w = weight_per_length(5 * INCH, 0.1086)
    assert float(w) == pytest.approx(262.10, abs=0.05)
    assert float(weight_per_length(0.2, 0.0, steel_density=1000.0)) == pytest.approx(
        math.pi / 4 * 0.04 * 1000.0 * GRAVITY)


def test_weight_per_length_arrays_match_scalars() -> None:
    outer = [0.127, 0.1683, 0.2032]
    inner = [0.1086, 0.0762, 0.0714]
    weights = weight_per_length(outer, inner)
    assert weights == pytest.approx([float(weight_per_length(o, i))
                                     for o, i in zip(outer, inner, strict=True)])


def test_component_buoyed_weight_sources() -> None:
    given = StringComponent("BHA", 200.0, 0.2, 0.07, buoyed_weight=3000.0)
    assert given.buoyed_weight_in(1560.0) == 3000.0  # used as is, whatever the mud
    in_air = StringComponent("DP", 100.0, 0.127, 0.1086, weight_in_air=300.0)
    assert in_air.buoyed_weight_in(1560.0) == pytest.approx(300.0 * (1 - 1560.0 / STEEL_DENSITY))
    assert in_air.buoyed_weight_in(1500.0, inside_density=1000.0) == pytest.approx(
        300.0 * 0.635629, rel=1e-5)
    from_size = StringComponent("DP", 100.0, 0.127, 0.1086)
    assert from_size.buoyed_weight_in(0.0) == pytest.approx(262.10, abs=0.05)


def test_component_radii_and_sections() -> None:
    plain = StringComponent("DP", 100.0, 0.127, 0.1086)
    jointed = StringComponent("DP", 100.0, 0.127, 0.1086, tool_joint_diameter=0.1683)
    assert plain.torque_radius == 0.0635
    assert jointed.torque_radius == pytest.approx(0.08415)
    assert plain.area == pytest.approx(3.40470e-3, rel=1e-5)
    assert plain.moment_of_inertia == pytest.approx(math.pi / 64 * (0.127**4 - 0.1086**4))


def test_drill_string_length_and_tops() -> None:
    string = DrillString((StringComponent("BHA", 200.0, 0.2, 0.07),
                          StringComponent("HWDP", 100.0, 0.127, 0.076),
                          StringComponent("DP", 3924.0, 0.127, 0.1086)))
    assert string.length == 4224.0
    assert string.component_tops() == pytest.approx([200.0, 300.0, 4224.0])


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"length": 0.0}, "length"),
        ({"outer_diameter": 0.1, "inner_diameter": 0.12}, "outer diameter"),
        ({"buoyed_weight": -5.0}, "buoyed_weight"),
        ({"weight_in_air": float("nan")}, "weight_in_air"),
    ],
)
def test_invalid_components_are_rejected(kwargs: dict[str, float], reason: str) -> None:
    values: dict[str, float] = {"length": 10.0, "outer_diameter": 0.127, "inner_diameter": 0.1}
    values.update(kwargs)
    with pytest.raises(ModelError, match=reason):
        StringComponent("pipe", **values)
    with pytest.raises(ModelError, match="at least one"):
        DrillString(())
