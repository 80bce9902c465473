"""Torque and drag: Example 7.1 both ways, an independent ODE solution on a 3D well,
friction inputs, operations and errors."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from tdmon.errors import ModelError
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import interpolate_survey, minimum_curvature, tvd_and_inclination
from tdmon.model.torque_drag import Operation, WellModel, torque_drag
from tdmon.model.well import Fluid, HoleSection, Well, hole_grid

KN = 1e3

# Example 7.1 section tops (thesis Table 5, exact from the geometry)
END_OF_BUILD = 1500.0 + 500.0 * math.radians(60.0)
TOP_OF_BHA = END_OF_BUILD + 2000.0
TOTAL_DEPTH = TOP_OF_BHA + 200.0


def _at(md: np.ndarray, values: np.ndarray, depth: float) -> float:
    index = int(np.argmin(np.abs(md - depth)))
    assert abs(md[index] - depth) < 1e-6, f"no string node at {depth} m"
    return float(values[index])


# --- Example 7.1 --------------------------------------------------------------------------


def test_example_71_aadnoy_reproduces_the_thesis(example_71: Well) -> None:
    # Thesis Tables 6-9 (Aadnoy's formulas as published): 1180 / 1487 / 961 kN, 23.45 kN m
    loads = torque_drag(example_71, TOTAL_DEPTH, 0.15, method="aadnoy")
    assert loads.hookload["static"] == pytest.approx(1180 * KN, rel=5e-3)
    assert loads.hookload["rotating"] == pytest.approx(1180 * KN, rel=5e-3)
    assert loads.hookload["pick_up"] == pytest.approx(1487 * KN, rel=5e-3)
    assert loads.hookload["slack_off"] == pytest.approx(961 * KN, rel=5e-3)
    assert loads.surface_torque["rotating"] == pytest.approx(23.45 * KN, rel=5e-3)


def test_example_71_soft_string_reproduces_the_consistent_solution(example_71: Well) -> None:
    # docs/reference-values.md §1: numerical integration of the soft-string ODE with N = |F/R - w
    # sin a|
    loads = torque_drag(example_71, TOTAL_DEPTH, 0.15, method="soft-string")
    assert loads.hookload["static"] == pytest.approx(1179.9 * KN, rel=3e-3)
    assert loads.hookload["pick_up"] == pytest.approx(1461.5 * KN, rel=3e-3)
    assert loads.hookload["slack_off"] == pytest.approx(960.9 * KN, rel=3e-3)
    assert loads.surface_torque["rotating"] == pytest.approx(19.84 * KN, rel=3e-3)


@pytest.mark.parametrize("method", ["aadnoy", "soft-string"])
def test_example_71_section_tops_match_tables_6_to_9(example_71: Well, method: str) -> None:
    # Top of BHA, top of sail, kick-off point. Both methods agree on the straight sections;
    # at the kick-off point the thesis values (1037, 511) are the Aadnoy build formulas.
    loads = torque_drag(example_71, TOTAL_DEPTH, 0.15, method=method)
    md = loads.md
    expected = {
        "static": [300, 600, 730],
        "pick_up": [378, 756, 1037],
        "slack_off": [222, 444, 511],
    }
    for operation, values in expected.items():
        profile = loads.axial_force[operation]
        tops = [_at(md, profile, TOP_OF_BHA), _at(md, profile, END_OF_BUILD)]
        assert tops == pytest.approx([v * KN for v in values[:2]], rel=3e-3), operation
        if method == "aadnoy" or operation == "static":
            assert _at(md, profile, 1500.0) == pytest.approx(values[2] * KN, rel=3e-3)
    torque = loads.torque["rotating"]
    assert _at(md, torque, TOP_OF_BHA) == pytest.approx(6.24 * KN, rel=3e-3)
    assert _at(md, torque, END_OF_BUILD) == pytest.approx(12.48 * KN, rel=3e-3)
    # no torque is added in the vertical section, and the surface value is the KOP value
    assert _at(md, torque, 1500.0) == pytest.approx(torque[0], rel=1e-12)


def test_example_71_static_load_is_buoyed_weight_times_tvd(example_71: Well) -> None:
    # 3 kN/m x 100 m TVD + 0.3 kN/m x (1500 + 250 sqrt 3 + 1000) m TVD, independent of friction
    expected = 3000 * 100 + 300 * (1500 + 500 * math.sin(math.radians(60)) + 1000)
    for mu in (0.0, 0.15, 0.4):
        for method in ("aadnoy", "soft-string"):
            loads = torque_drag(example_71, TOTAL_DEPTH, mu, method=method)
            assert loads.hookload["static"] == pytest.approx(expected, rel=1e-9)


# --- an independent solution of the soft-string ODEs ----------------------------------------


def _tangent(inc: float, azi: float) -> np.ndarray:
    return np.array([math.sin(inc) * math.cos(azi), math.sin(inc) * math.sin(azi), math.cos(inc)])


def _soft_string_ode(
    md: np.ndarray, inc_deg: np.ndarray, azi_deg: np.ndarray, bit_depth: float,
    weight: Callable[[float], float], radius: Callable[[float], float],
    mu: Callable[[float], float], axial: float, tangential: float, breaks: list[float],
) -> tuple[float, float]:
    """Integrate dF/ds = -(w t_z + axial mu n), dT/ds = -(tangential mu n r) from the bit up,
    with n = |F dt/ds + w (e_z - t_z t)| on the circular arcs between survey stations.

    Written from the equilibrium of a cable element (s measured down the hole), sharing no code
    with tdmon's march: tangents and curvatures come straight from the arc parametrisation.
    """
    inc = np.radians(inc_deg)
    azi = np.radians(azi_deg)

    def path(s: float) -> tuple[np.ndarray, np.ndarray]:
        i = min(max(int(np.searchsorted(md, s, side="right")) - 1, 0), md.size - 2)
        t1, t2 = _tangent(inc[i], azi[i]), _tangent(inc[i + 1], azi[i + 1])
        beta = math.acos(min(1.0, float(t1 @ t2)))
        length = md[i + 1] - md[i]
        f = (s - md[i]) / length
        if beta < 1e-12:
            return t1, np.zeros(3)
        t = (math.sin((1 - f) * beta) * t1 + math.sin(f * beta) * t2) / math.sin(beta)
        dt = beta / length * (-math.cos((1 - f) * beta) * t1 + math.cos(f * beta) * t2)
        return t, dt / math.sin(beta)

    def rhs(s: float, y: np.ndarray) -> list[float]:
        t, dt = path(s)
        w = weight(s)
        contact = np.linalg.norm(y[0] * dt + w * (np.array([0.0, 0.0, 1.0]) - t[2] * t))
        return [-(w * t[2] + axial * mu(s) * contact),
                -(tangential * mu(s) * contact * radius(s))]

    stops = sorted({0.0, bit_depth, *[b for b in [*md, *breaks] if 0.0 < b < bit_depth]},
                   reverse=True)
    state = np.zeros(2)
    for lower, upper in itertools.pairwise(stops):
        solution = solve_ivp(rhs, (lower, upper), state, rtol=1e-10, atol=1e-6,
                             method="DOP853")
        state = solution.y[:, -1]
    return float(state[0]), float(state[1])


@pytest.mark.parametrize("bit_depth", [3600.0, 2075.0])
def test_soft_string_agrees_with_ode_on_3d_well(
    three_d: Well, three_d_survey_stations: tuple[np.ndarray, np.ndarray, np.ndarray],
    bit_depth: float,
) -> None:
    md, inc_deg, azi_deg = three_d_survey_stations
    bha_top = bit_depth - 150.0

    def weight(s: float) -> float:
        return 1500.0 if s > bha_top else 250.0

    def radius(s: float) -> float:
        return 0.08 if s > bha_top else 0.1651 / 2

    def mu(s: float) -> float:
        return 0.2 if s < 1000.0 else 0.3

    loads = torque_drag(three_d, bit_depth, method="soft-string")
    for operation, axial, tangential in (("pick_up", 1, 0), ("slack_off", -1, 0),
                                         ("rotating", 0, 1)):
        force, torque = _soft_string_ode(md, inc_deg, azi_deg, bit_depth, weight, radius, mu,
                                         axial, tangential, [bha_top, 1000.0])
        # required 0.5 %; found < 1e-6 with 10 m elements (Heun's step on each piece)
        assert loads.hookload[operation] == pytest.approx(force, rel=1e-4), operation
        if tangential:
            assert loads.surface_torque[operation] == pytest.approx(torque, rel=1e-4)


# --- friction inputs ----------------------------------------------------------------------


def test_friction_from_sections_float_and_array_agree(three_d: Well) -> None:
    model = WellModel(three_d)
    grid = hole_grid(three_d)
    per_element = np.where(grid.element_kind == "cased", 0.2, 0.3)
    for method in ("soft-string", "aadnoy"):
        from_sections = model.evaluate("pick_up", 3000.0, None, method=method)
        from_array = model.evaluate("pick_up", 3000.0, per_element, method=method)
        assert from_array == from_sections
        uniform = model.evaluate("slack_off", 3000.0, 0.25, method=method)
        assert model.evaluate("slack_off", 3000.0, np.full(grid.n_elements, 0.25),
                              method=method) == uniform


def test_local_friction_only_acts_where_it_is(three_d: Well) -> None:
    # Raising friction below the bit changes nothing; raising it above the bit raises pick-up.
    model = WellModel(three_d)
    mid = hole_grid(three_d).element_mid_md
    base = model.evaluate("pick_up", 2000.0, np.full(mid.size, 0.25))
    below = model.evaluate("pick_up", 2000.0, np.where(mid > 2000.0, 0.9, 0.25))
    above = model.evaluate("pick_up", 2000.0, np.where(mid < 2000.0, 0.3, 0.25))
    assert below == base
    assert above[0] > base[0] + 1e3


def test_zero_friction_makes_all_trips_equal(example_71: Well) -> None:
    for method in ("soft-string", "aadnoy"):
        loads = torque_drag(example_71, TOTAL_DEPTH, 0.0, method=method)
        assert loads.hookload["pick_up"] == pytest.approx(loads.hookload["static"], rel=1e-12)
        assert loads.hookload["slack_off"] == pytest.approx(loads.hookload["static"], rel=1e-12)
        assert loads.surface_torque["rotating"] == 0.0


def test_pick_up_rises_and_slack_off_falls_with_friction(three_d: Well) -> None:
    model = WellModel(three_d)
    for method in ("soft-string", "aadnoy"):
        pick_up = [model.evaluate("pick_up", 3600.0, mu, method=method)[0]
                   for mu in (0.1, 0.2, 0.3)]
        slack_off = [model.evaluate("slack_off", 3600.0, mu, method=method)[0]
                     for mu in (0.1, 0.2, 0.3)]
        assert pick_up[0] < pick_up[1] < pick_up[2]
        assert slack_off[0] > slack_off[1] > slack_off[2]


# --- operations ---------------------------------------------------------------------------


def _vertical_well() -> Well:
    survey = minimum_curvature([0.0, 3000.0], [0.0, 0.0], [0.0, 0.0])
    string = DrillString((StringComponent("DP", 3000.0, 0.127, 0.1086, buoyed_weight=250.0),))
    return Well(survey, string, (HoleSection(0.0, 3000.0, 0.2159, "open", 0.3),),
                Fluid(1200.0), block_weight=400e3)


def test_on_bottom_in_vertical_hole() -> None:
    # No wall contact in a vertical hole: hook load = block + w L - WOB, torque = bit torque
    loads = torque_drag(_vertical_well(), 3000.0, wob=100e3, bit_torque=5e3)
    assert loads.hookload["static"] == pytest.approx(400e3 + 250.0 * 3000.0)
    assert loads.hookload["pick_up"] == pytest.approx(loads.hookload["static"])
    assert loads.hookload["on_bottom"] == pytest.approx(400e3 + 250.0 * 3000.0 - 100e3)
    assert loads.surface_torque["on_bottom"] == pytest.approx(5e3)
    assert loads.axial_force["on_bottom"][-1] == -100e3  # bit force = -WOB (compression)
    assert loads.torque["on_bottom"][-1] == 5e3


@pytest.mark.parametrize("method", ["aadnoy", "soft-string"])
def test_on_bottom_adds_bit_loads(example_71: Well, method: str) -> None:
    off = torque_drag(example_71, TOTAL_DEPTH, method=method)
    on = torque_drag(example_71, TOTAL_DEPTH, method=method, wob=50e3, bit_torque=4e3)
    # no axial friction when rotating: the WOB comes off the hook load one to one
    assert on.hookload["on_bottom"] == pytest.approx(off.hookload["rotating"] - 50e3, rel=1e-9)
    assert on.surface_torque["on_bottom"] > 4e3
    assert on.surface_torque["on_bottom"] != pytest.approx(off.surface_torque["rotating"] + 4e3)


def test_combined_motion_splits_friction(three_d: Well) -> None:
    model = WellModel(three_d)
    pure_pull = model.evaluate("pick_up", 3600.0)
    rotating = model.evaluate("rotating", 3600.0)
    assert model.evaluate("pick_up", 3600.0, psi=math.pi / 2) == pytest.approx(pure_pull,
                                                                              abs=1e-6)
    assert model.evaluate("pick_up", 3600.0, psi=0.0) == pytest.approx(rotating)
    back_reaming = model.evaluate("pick_up", 3600.0, psi=math.radians(20.0))
    assert rotating[0] < back_reaming[0] < pure_pull[0]
    # mu cos(psi) acts tangentially on a contact force that the extra tension has raised
    assert back_reaming[1] / math.cos(math.radians(20.0)) > rotating[1] > 0.0
    reaming = model.evaluate("slack_off", 3600.0, psi=math.radians(20.0))
    assert model.evaluate("slack_off", 3600.0)[0] < reaming[0] < rotating[0]


def test_loads_profile_layout_and_block_weight(three_d: Well) -> None:
    loads = torque_drag(three_d, 2075.0)
    assert loads.md[0] == 0.0 and loads.md[-1] == 2075.0
    assert (np.diff(loads.md) > 0).all()
    assert set(loads.hookload) >= {"static", "rotating", "pick_up", "slack_off", "on_bottom"}
    for operation in Operation:
        assert loads.axial_force[operation.value][0] == loads.hookload[operation.value]
        assert loads.axial_force[operation.value].shape == loads.md.shape
    assert loads.axial_force["pick_up"][-1] == 0.0
    assert 2075.0 - 150.0 in loads.md  # the BHA top is a node
    assert loads.component[-1] == 0 and loads.component[0] == 1
    heavier = Well(three_d.survey, three_d.string, three_d.sections, three_d.fluid,
                   block_weight=500e3)
    assert torque_drag(heavier, 2075.0).hookload["pick_up"] == pytest.approx(
        loads.hookload["pick_up"] + 500e3)


@pytest.mark.parametrize("method", ["aadnoy", "soft-string"])
def test_well_model_matches_torque_drag(three_d: Well, method: str) -> None:
    model = WellModel(three_d)
    loads = torque_drag(three_d, 2075.0, 0.27, method=method, wob=30e3, bit_torque=2e3)
    for operation in Operation:
        hookload, torque = model.evaluate(operation, 2075.0, 0.27, method=method, wob=30e3,
                                          bit_torque=2e3)
        assert hookload == loads.hookload[operation.value]
        assert torque == loads.surface_torque[operation.value]


def test_element_length_barely_matters(make_example_71: Callable[..., Well]) -> None:
    coarse = torque_drag(make_example_71(30.0), TOTAL_DEPTH, 0.15)
    fine = torque_drag(make_example_71(1.0), TOTAL_DEPTH, 0.15)
    assert coarse.hookload["pick_up"] == pytest.approx(fine.hookload["pick_up"], rel=2e-4)
    assert coarse.surface_torque["rotating"] == pytest.approx(fine.surface_torque["rotating"],
                                                               rel=2e-4)


# --- errors ------------------------------------------------------------------------------


def test_bit_deeper_than_string_is_an_error(example_71: Well) -> None:
    short = Well(example_71.survey, DrillString(example_71.string.components[:1]),
                 example_71.sections, example_71.fluid)
    with pytest.raises(ModelError, match="deeper than the drill string"):
        torque_drag(short, 300.0)


def test_bit_below_hole_is_an_error(example_71: Well) -> None:
    bha, _pipe = example_71.string.components
    longer = DrillString((bha, StringComponent("drill pipe", 5000.0, 0.127, 0.108)))
    with pytest.raises(ModelError, match="below the hole"):
        WellModel(Well(example_71.survey, longer, example_71.sections, example_71.fluid)
                  ).evaluate("pick_up", TOTAL_DEPTH + 10.0)
    with pytest.raises(ModelError, match="below the top"):
        WellModel(example_71).evaluate("pick_up", 0.0)


def test_bad_inputs_are_errors(example_71: Well) -> None:
    model = WellModel(example_71)
    with pytest.raises(ModelError, match="unknown torque-and-drag method"):
        model.evaluate("pick_up", 3000.0, method="stiff")
    with pytest.raises(ModelError, match="one value per hole-grid element"):
        model.evaluate("pick_up", 3000.0, np.full(5, 0.2))
    with pytest.raises(ModelError, match=">= 0"):
        model.evaluate("pick_up", 3000.0, -0.1)
    with pytest.raises(ValueError, match="tripping"):
        model.evaluate("tripping", 3000.0)
    no_friction = Well(example_71.survey, example_71.string,
                       (HoleSection(0.0, TOTAL_DEPTH, 0.2159, "open"),), example_71.fluid)
    with pytest.raises(ModelError, match="no friction factor"):
        torque_drag(no_friction, 3000.0)


def test_case_2_geothermal_local_friction(example_71: Well) -> None:
    # docs/reference-values.md section 3, Case 2 geothermal: Glydril mu = 0.23 + 0.0013 T with T
    # linear in TVD from 15.3 C at surface to 85.5 C at 3033 m, each element at its own temperature.
    # Consistent soft string: 1868 / 768 kN, 42.4 kN m; element-wise thesis-style normal forces:
    # pick-up 1924 kN, slack-off 768 kN.
    grid = hole_grid(example_71)
    tvd = interpolate_survey(example_71.survey, grid.element_mid_md).tvd
    mu = 0.23 + 0.0013 * (15.3 + (85.5 - 15.3) * tvd / 3033.0)
    soft = torque_drag(example_71, TOTAL_DEPTH, mu, method="soft-string")
    assert soft.hookload["pick_up"] == pytest.approx(1868 * KN, rel=1e-3)
    assert soft.hookload["slack_off"] == pytest.approx(768 * KN, rel=1e-3)
    assert soft.surface_torque["rotating"] == pytest.approx(42.4 * KN, rel=2e-3)
    thesis = torque_drag(example_71, TOTAL_DEPTH, mu, method="aadnoy")
    assert thesis.hookload["pick_up"] == pytest.approx(1924 * KN, rel=1e-3)
    assert thesis.hookload["slack_off"] == pytest.approx(768 * KN, rel=1e-3)
    # Table 9's closed-form build torque (what "aadnoy" applies) exceeds the element-wise
    # added-normal-force integral (46.0 kN m) in the same ratio as at constant friction
    # (23.45 / 21.64 kN m)
    assert thesis.surface_torque["rotating"] / (46.0 * KN) == pytest.approx(23.45 / 21.64,
                                                                            rel=5e-3)


def test_aadnoy_uses_the_2010_interval_formulas_on_a_horizontal_turn() -> None:
    # Horizontal well: 500 m straight below a 30 deg turn of 300 m at 90 deg inclination.
    # Pick-up at the bottom of the turn: mu w L (eq 42 at 90 deg); over the turn the Aadnoy,
    # Fazaelizadeh and Hareland (2010) formula F2 = F1 e^(mu theta) + w L (sin a2 - sin a1) /
    # (a2 - a1) with a1 = a2 = 90 deg adds no weight: F2 = F1 e^(mu theta).
    kop, radius = 500.0, 600.0
    heel = kop + radius * math.pi / 2
    md = [0.0, kop, heel, heel + 200.0, heel + 500.0, heel + 1000.0]
    survey = minimum_curvature(md, [0, 0, 90, 90, 90, 90], [0, 0, 0, 0, 30, 30])
    string = DrillString((StringComponent("DP", md[-1], 0.127, 0.1086, buoyed_weight=250.0),))
    well = Well(survey, string, (HoleSection(0.0, md[-1], 0.2159, "open", 0.3),), Fluid(1200.0))
    loads = torque_drag(well, md[-1], method="aadnoy")
    turn_bottom = _at(loads.md, loads.axial_force["pick_up"], md[4])
    turn_top = _at(loads.md, loads.axial_force["pick_up"], md[3])
    assert turn_bottom == pytest.approx(0.3 * 250.0 * 500.0, rel=1e-9)
    assert turn_top == pytest.approx(turn_bottom * math.exp(0.3 * math.radians(30.0)), rel=1e-9)
    # rotating: no axial force in the horizontal, so the turn adds no torque (T = mu r |F1| theta)
    torque = loads.torque["rotating"]
    assert _at(loads.md, torque, md[3]) == pytest.approx(_at(loads.md, torque, md[4]), rel=1e-9)
    assert _at(loads.md, torque, md[4]) == pytest.approx(0.3 * 250.0 * 500.0 * 0.0635, rel=1e-9)


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
@pytest.mark.parametrize("operations", [
    ["pick_up", "rotating"], [Operation.SLACK_OFF], ["rotating", "rotating"],
    ["on_bottom", "static", "pick_up"],
])
def test_loads_of_some_operations_are_those_of_all(three_d: Well, method: str,
                                                    operations: list[str]) -> None:
    # each operation's loads are its own march's: choosing a few changes no bit
    model = WellModel(three_d)
    mu = np.linspace(0.15, 0.35, model.n_elements)
    for bit_depth, psi in ((1800.0, None), (3599.0, 0.3)):
        every = model.loads(bit_depth, mu, method=method, wob=4e4, bit_torque=3e3, psi=psi)
        some = model.loads(bit_depth, mu, method=method, wob=4e4, bit_torque=3e3, psi=psi,
                           operations=operations)
        names = list(dict.fromkeys(Operation(op).value for op in operations))
        assert list(some.hookload) == list(some.axial_force) == list(some.torque) == names
        for name in names:
            assert some.hookload[name] == every.hookload[name]
            assert some.surface_torque[name] == every.surface_torque[name]
            assert some.axial_force[name].tobytes() == every.axial_force[name].tobytes()
            assert some.torque[name].tobytes() == every.torque[name].tobytes()
        for field in ("md", "tvd", "component", "inclination"):
            assert getattr(some, field).tobytes() == getattr(every, field).tobytes()
    with pytest.raises(ValueError, match="not a valid Operation"):
        model.loads(1000.0, mu, operations=["tripping"])


@settings(max_examples=60, deadline=None)
@given(depths=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=6),
       which=st.sampled_from(["three_d", "example_71"]))
def test_loads_tvd_and_inclination_are_the_interpolations(depths: list[float],
                                                          which: str, three_d: Well,
                                                          example_71: Well) -> None:
    # the grid nodes' numbers are taken from one interpolation of all of them: each node's
    # bits must be those of the loads' own nodes interpolated together, at any bit depth
    if which not in _MODELS:
        _MODELS[which] = WellModel(three_d if which == "three_d" else example_71)
    model = _MODELS[which]
    top = float(model.node_md[0]) + 1.0
    bottom = min(model.well.string.length, float(model.node_md[-1]))
    for fraction in (*depths, 1.0):
        loads = model.loads(top + fraction * (bottom - top), 0.25, operations=["pick_up"])
        tvd, inclination = tvd_and_inclination(model.well.survey, loads.md)
        assert loads.tvd.tobytes() == tvd.tobytes()
        assert loads.inclination is not None
        assert loads.inclination.tobytes() == inclination.tobytes()
        single = tvd_and_inclination(model.well.survey, loads.md[-1:])
        assert (single[0][0], single[1][0]) == (tvd[-1], inclination[-1])


_MODELS: dict[str, WellModel] = {}
