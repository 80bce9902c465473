"""Limits: eq 28-31 by hand, arrays vs scalars, and every limit crossed and flagged."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tdmon.model.limits import (
    Limit,
    LimitFlag,
    check_limits,
    combined_tensile_limit,
    helical_buckling_load,
    operating_window,
    radial_clearance,
    sinusoidal_buckling_load,
    tensile_limit,
    true_axial_force,
)
from tdmon.model.string import GRAVITY, DrillString, StringComponent
from tdmon.model.torque_drag import torque_drag
from tdmon.model.well import LimitSettings, Well

OD, ID = 0.127, 0.1086  # 5" drill pipe body
AREA = math.pi / 4 * (OD**2 - ID**2)  # 3.40470e-3 m2
INERTIA = math.pi / 64 * (OD**4 - ID**4)  # 5.9387e-6 m4
E75 = 517e6  # API grade E-75 minimum yield [Pa]
TOTAL_DEPTH = 1500.0 + 500.0 * math.radians(60.0) + 2200.0  # Example 7.1


def test_tensile_limit_hand_value() -> None:
    # eq 28: 3.40470e-3 m2 x 517 MPa / 1.25 = 1408.2 kN
    assert float(tensile_limit(AREA, E75, 1.25)) == pytest.approx(1408.20e3, rel=1e-5)
    limits = tensile_limit([AREA, 2 * AREA], [E75, E75], 1.25)
    assert limits == pytest.approx([1408.20e3, 2816.39e3], rel=1e-5)


def test_combined_limit_is_the_principal_stress_criterion() -> None:
    torque = 30e3
    limit = float(combined_tensile_limit(AREA, E75, torque, OD, ID))
    # independent check: at that axial stress the largest principal stress equals yield
    tau = torque * (OD / 2) / (math.pi / 32 * (OD**4 - ID**4))  # 160.4 MPa
    sigma_a = limit / AREA
    assert sigma_a / 2 + math.sqrt((sigma_a / 2) ** 2 + tau**2) == pytest.approx(E75, rel=1e-12)
    assert limit == pytest.approx(AREA * (E75 - tau**2 / E75), rel=1e-12)  # eq 29, sigma_t = 0
    assert float(combined_tensile_limit(AREA, E75, 0.0, OD, ID)) == pytest.approx(AREA * E75)
    torques = np.array([0.0, 10e3, 30e3, 1e6])
    array = combined_tensile_limit(AREA, E75, torques, OD, ID, safety_factor=1.25)
    scalars = [float(combined_tensile_limit(AREA, E75, t, OD, ID, safety_factor=1.25))
               for t in torques]
    assert array == pytest.approx(scalars)
    assert array[-1] == 0.0  # torsion alone past yield: no tensile capacity left


def test_buckling_loads_hand_values() -> None:
    # eq 30 with E 206 GPa, I 5.9387e-6 m4, w 300 N/m, 60 deg, clearance (0.2159 - 0.127)/2
    clearance = float(radial_clearance(0.2159, OD))
    assert clearance == pytest.approx(0.04445)
    expected = math.sqrt(4 * 2.06e11 * INERTIA * 300.0 * math.sin(math.radians(60)) / 0.04445)
    sinusoidal = float(sinusoidal_buckling_load(2.06e11, INERTIA, 300.0, math.radians(60),
                                                clearance))
    assert sinusoidal == pytest.approx(expected, rel=1e-12)
    assert sinusoidal == pytest.approx(169.2e3, rel=1e-3)
    assert float(helical_buckling_load(sinusoidal)) == pytest.approx(math.sqrt(2) * sinusoidal)
    # Chen and Cheatham's full helical load 2 (2 sqrt 2 - 1) sqrt(E I w sin a / r) is
    # (2 sqrt 2 - 1) = 1.83 times the Dawson-Paslay load 2 sqrt(E I w sin a / r)
    assert float(helical_buckling_load(sinusoidal, 2 * math.sqrt(2) - 1)) == pytest.approx(
        1.8284 * sinusoidal, rel=1e-4)
    inclinations = np.radians([0.0, 30.0, 90.0])
    array = sinusoidal_buckling_load(2.06e11, INERTIA, 300.0, inclinations, clearance)
    assert array[0] == 0.0
    assert array[1:] == pytest.approx(
        [float(sinusoidal_buckling_load(2.06e11, INERTIA, 300.0, a, clearance))
         for a in inclinations[1:]])


def test_true_force_of_a_hanging_string_end() -> None:
    # zero effective force at the open end of a string in mud = compression p A_steel
    force = true_axial_force(0.0, 3000.0, 1500.0, 1500.0, OD, ID)
    assert float(force) == pytest.approx(-1500.0 * GRAVITY * 3000.0 * AREA)
    lighter_inside = true_axial_force(0.0, 3000.0, 1500.0, 1000.0, OD, ID)
    assert float(lighter_inside) < float(force)


def _all_drill_pipe(example_71: Well, *, safety_factor: float = 1.0, **pipe: float) -> Well:
    string = DrillString((StringComponent("drill pipe", TOTAL_DEPTH, OD, ID, buoyed_weight=300.0,
                                          **pipe),))
    return Well(example_71.survey, string, example_71.sections, example_71.fluid,
                limits=LimitSettings(safety_factor=safety_factor))


def _with_bha(example_71: Well, *, safety_factor: float = 1.0, **pipe: float) -> Well:
    """Example 7.1 exactly (3 kN/m BHA, 0.3 kN/m pipe), the pipe given yield/make-up data."""
    bha = example_71.string.components[0]
    string = DrillString((bha, StringComponent("drill pipe", TOTAL_DEPTH - 200.0, OD, ID,
                                               buoyed_weight=300.0, **pipe)))
    return Well(example_71.survey, string, example_71.sections, example_71.fluid,
                limits=LimitSettings(safety_factor=safety_factor))


def _flags(well: Well, *, wob: float = 0.0,
           bit_torque: float = 0.0) -> dict[tuple[str, str], LimitFlag]:
    loads = torque_drag(well, TOTAL_DEPTH, 0.15, wob=wob, bit_torque=bit_torque)
    return {(flag.limit.value, flag.operation): flag for flag in check_limits(well, loads)}


def test_tensile_limit_crossed_by_pick_up_only(example_71: Well) -> None:
    # pick-up ~1461 kN > 1408 kN (E-75, SF 1.25) > static 1180 kN
    well = _with_bha(example_71, safety_factor=1.25, yield_strength=E75)
    flags = _flags(well)
    flag = flags[("tensile", "pick_up")]
    assert flag.md == 0.0
    assert flag.limit_value == pytest.approx(1408.20e3, rel=1e-5)
    assert flag.excess == pytest.approx(
        torque_drag(well, TOTAL_DEPTH, 0.15).hookload["pick_up"] - 1408.20e3, rel=1e-4)
    assert not any(limit == "tensile" and op != "pick_up" for limit, op in flags)


def test_combined_limit_crossed_by_rotation_where_tension_alone_is_safe(
        example_71: Well) -> None:
    # rotating 1179.9 kN lies between the combined (1162.9 kN with 19.84 kN m) and the tensile
    # (1213.9 kN) limits of E-75 pipe with SF 1.45
    well = _with_bha(example_71, safety_factor=1.45, yield_strength=E75,
                     tool_joint_diameter=0.16)
    loads = torque_drag(well, TOTAL_DEPTH, 0.15)
    window = operating_window(well, loads)
    surface = loads.axial_force["rotating"][0]
    assert window.combined[0] < surface < window.tensile[0]  # the case is what it claims
    flags = _flags(well)
    assert ("combined", "rotating") in flags
    assert ("tensile", "rotating") not in flags and ("tensile", "static") not in flags


def test_makeup_torque_crossed(example_71: Well) -> None:
    well = _with_bha(example_71, makeup_torque=15e3, tool_joint_diameter=0.16)
    flags = _flags(well, wob=50e3, bit_torque=3e3)
    flag = flags[("makeup_torque", "rotating")]
    assert flag.load == pytest.approx(19.84e3, rel=3e-3)
    assert flag.md_top == 0.0
    assert ("makeup_torque", "on_bottom") in flags
    assert ("makeup_torque", "pick_up") not in flags  # no rotation, no torque


def test_buckling_sinusoidal_then_helical_on_bottom(example_71: Well) -> None:
    well = _all_drill_pipe(example_71)
    # F_sin = 169.2 kN, F_hel = 239.3 kN at 60 deg: 200 kN WOB buckles sinusoidally only
    flags = _flags(well, wob=200e3)
    flag = flags[("sinusoidal_buckling", "on_bottom")]
    assert flag.md == pytest.approx(TOTAL_DEPTH)
    assert flag.load == pytest.approx(200e3)
    assert flag.limit_value == pytest.approx(169.2e3, rel=1e-3)
    assert ("helical_buckling", "on_bottom") not in flags
    flags = _flags(well, wob=300e3)
    assert ("helical_buckling", "on_bottom") in flags
    assert ("sinusoidal_buckling", "on_bottom") in flags
    # the full-helical factor 1.83 moves the helical limit above 300 kN
    lenient = Well(well.survey, well.string, well.sections, well.fluid,
                   limits=LimitSettings(helical_factor=2 * math.sqrt(2) - 1))
    assert ("helical_buckling", "on_bottom") not in _flags(lenient, wob=300e3)


def test_compressive_yield_uses_the_true_force(example_71: Well) -> None:
    # 300 kN WOB plus the mud pressure on the pipe end: true compression at the bit is
    # 300 kN + 1560 x 9.80665 x 3033 x A_steel = 458 kN, above 120 MPa x A = 409 kN
    well = _all_drill_pipe(example_71, yield_strength=120e6)
    flags = _flags(well, wob=300e3)
    flag = flags[("compressive_yield", "on_bottom")]
    tvd_bit = 1500 + 500 * math.sin(math.radians(60)) + 2200 * 0.5
    expected = 300e3 + 1560.0 * GRAVITY * tvd_bit * AREA
    assert flag.load == pytest.approx(expected, rel=1e-6)
    assert ("compressive_yield", "rotating") not in flags


def test_no_flags_within_limits(example_71: Well) -> None:
    well = _all_drill_pipe(example_71, yield_strength=931e6, makeup_torque=40e3)
    assert check_limits(well, torque_drag(well, TOTAL_DEPTH, 0.15)) == ()
    assert {f.limit for f in check_limits(well, torque_drag(well, TOTAL_DEPTH, 0.15,
                                                               wob=400e3))} >= {
        Limit.SINUSOIDAL_BUCKLING, Limit.HELICAL_BUCKLING}


def test_operating_window_on_a_model_s_grid(example_71: Well) -> None:
    # the hole grid a WellModel holds gives the limit lines that building it anew gives
    from tdmon.model.torque_drag import WellModel

    model = WellModel(example_71)
    loads = model.loads(3000.0, np.full(model.n_elements, 0.25))
    built = operating_window(example_71, loads)
    given = operating_window(example_71, loads, grid=model.grid)
    for name in ("tensile", "combined", "sinusoidal_buckling", "helical_buckling",
                 "makeup_torque"):
        np.testing.assert_array_equal(getattr(given, name), getattr(built, name))
    assert built.tensile.shape == loads.md.shape and np.isfinite(built.sinusoidal_buckling).any()


def test_loads_carry_the_nodes_inclination(example_71: Well) -> None:
    # WellModel.loads interpolates the survey once for TVD and inclination; the limit lines
    # from that inclination equal those from interpolating the survey again
    import dataclasses

    from tdmon.model.survey import interpolate_survey

    loads = torque_drag(example_71, 3000.0, 0.25)
    assert loads.inclination is not None
    np.testing.assert_array_equal(loads.inclination,
                                  interpolate_survey(example_71.survey, loads.md).inclination)
    assert np.ptp(loads.inclination) > 1.0  # vertical, build and tangent nodes: not a constant
    without = dataclasses.replace(loads, inclination=None)
    given, again = operating_window(example_71, loads), operating_window(example_71, without)
    np.testing.assert_array_equal(given.sinusoidal_buckling, again.sinusoidal_buckling)
    np.testing.assert_array_equal(given.helical_buckling, again.helical_buckling)


def test_component_table_is_each_component_s_properties(example_71: Well) -> None:
    # the per-component arrays are built once per string and fluid: each column is the
    # component by component list it replaced (None as NaN), read-only
    from dataclasses import replace

    from tdmon.model.limits import _COMPONENT_PROPERTIES, _component_table
    from tdmon.model.survey import tangent_vectors

    tube = StringComponent("tube", 500.0, outer_diameter=0.127, inner_diameter=0.1086,
                           yield_strength=5.2e8, makeup_torque=3e4)
    for components in (example_71.string.components, (tube, *example_71.string.components)):
        for density, inside in ((1200.0, None), (1400.0, 1000.0)):
            table = _component_table(components, density, inside)
            columns = [[c.buoyed_weight_in(density, inside) for c in components],
                       *([getattr(c, name) for c in components]
                         for name in _COMPONENT_PROPERTIES)]
            assert len(table) == len(columns)
            for array, values in zip(table, columns, strict=True):
                expected = np.array([np.nan if v is None else v for v in values])
                assert array.tobytes() == expected.tobytes()
                assert not array.flags.writeable
            assert _component_table(components, density, inside) is table
    survey = example_71.survey
    assert survey.tangents.tobytes() == tangent_vectors(survey.inclination,
                                                        survey.azimuth).tobytes()
    assert replace(survey).tangents is not survey.tangents
