"""The fluid's forces in the torque-and-drag march: the per-element axial force against an
independent integration of the soft-string ODE with the same force, the pressures it comes
from, the jets at the bit, the densities per element, the trip-speed limits, and every model
call with fluid terms (evaluate, cases, gradient, loads, broomstick) agreeing with the others."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tdmon.errors import ModelError
from tdmon.model import hydraulics as h
from tdmon.model.broomstick import broomstick_from_model
from tdmon.model.fluid_force import HydraulicModel
from tdmon.model.fluid_terms import FluidTerms
from tdmon.model.rheology import from_fann
from tdmon.model.string import GRAVITY, DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Fluid, HoleSection, Well

INCH = 0.0254
MUD = from_fann(65.0, 40.0)  # PV 25 cP, YP 15 lbf/100 ft^2
COLLARS = StringComponent("collars", 150.0, 6.5 * INCH, 2.8125 * INCH, weight_in_air=1330.0,
                          tool_joint_diameter=6.5 * INCH)
PIPE = StringComponent("drill pipe", 3850.0, 5.0 * INCH, 4.276 * INCH, weight_in_air=330.0,
                       tool_joint_diameter=6.625 * INCH)


def _well(stations: tuple[list[float], list[float], list[float]], **hydraulics: object) -> Well:
    md, inc, azi = stations
    return Well(
        survey=minimum_curvature(md, inc, azi), string=DrillString((COLLARS, PIPE)),
        sections=(HoleSection(0.0, 1200.0, 8.681 * INCH, "cased", friction=0.2),
                  HoleSection(1200.0, md[-1], 8.5 * INCH, "open", friction=0.3)),
        fluid=Fluid(1300.0), element_length=10.0, name="fluid test well",
        hydraulics=h.WellHydraulics(rheology=MUD, **hydraulics))  # type: ignore[arg-type]


BUILD_AND_HOLD = ([0.0, 800.0, 1400.0, 1700.0, 3400.0], [0.0, 0.0, 45.0, 45.0, 60.0],
                  [0.0, 0.0, 20.0, 35.0, 40.0])


@pytest.fixture(scope="module")
def well() -> Well:
    return _well(BUILD_AND_HOLD, float_valve=True, nozzle_area=3 * math.pi / 4 * (12 / 32 * INCH)
                 ** 2, fracture_density=1550.0, pore_density=1150.0)


@pytest.fixture(scope="module")
def model(well: Well) -> WellModel:
    return WellModel(well)


@pytest.fixture(scope="module")
def hydraulic(well: Well, model: WellModel) -> HydraulicModel:
    return HydraulicModel(well, model.grid)


# --- the force and the pressures ---------------------------------------------------------


def test_axial_force_is_the_annular_gradient_on_pipe_and_hole(hydraulic: HydraulicModel) -> None:
    """f = -(dp/dz) pi d_o d_h / 4 per metre; summed over the string it is, for each geometry,
    minus its share of the surge pressure times pi d_o d_h / 4."""
    depth, speed = 3000.0, -0.6
    forces = hydraulic.forces(depth, speed)
    axial = forces.terms.axial
    assert axial is not None
    lengths = np.diff(hydraulic.grid.md)
    covered = np.clip(depth - hydraulic.grid.md[:-1], 0.0, lengths)
    pieces = hydraulic.string_in_hole(depth)
    sections = h.AnnularSections(pieces.length, pieces.hole_diameter, pieces.outer_diameter,
                                 pieces.inner_diameter, np.full(pieces.length.size, 1300.0),
                                 np.full(pieces.length.size, 1300.0))
    gradient = h.surge_swab(sections, MUD, speed, closed=True).gradient
    expected = -np.sum(gradient * pieces.length * np.pi / 4 * pieces.outer_diameter
                       * pieces.hole_diameter)
    assert np.sum(axial * covered) == pytest.approx(expected, rel=1e-12)
    assert forces.surge_at_bit == pytest.approx(np.sum(gradient * pieces.length), rel=1e-12)
    assert forces.surge_at_bit < 0.0 < np.sum(axial * covered)  # swab; drag adds to a pull
    above_shoe = np.clip(1200.0 - pieces.top, 0.0, pieces.length)
    assert forces.surge_at_shoe == pytest.approx(np.sum(gradient * above_shoe), rel=1e-12)
    assert np.all(axial[hydraulic.grid.md[:-1] >= depth] == 0.0)


def test_no_rheology_means_no_drag(well: Well) -> None:
    unknown = HydraulicModel(replace(well, hydraulics=h.WellHydraulics()))
    forces = unknown.forces(3000.0, 0.8, flow_rate=0.04)
    assert forces.terms.axial is None and forces.terms.bit_force == 0.0
    assert forces.surge_at_bit == 0.0 and math.isnan(forces.bit_pressure_drop)
    assert forces.density_at_bit == pytest.approx(1300.0)


def test_jets_push_the_string_up_while_circulating(hydraulic: HydraulicModel) -> None:
    flow = 2000.0 / 60000.0
    forces = hydraulic.forces(3000.0, 0.0, flow_rate=flow)
    area = hydraulic.hydraulics.nozzle_area
    assert area is not None
    assert forces.bit_pressure_drop == pytest.approx(1300.0 * flow**2 / (2 * 0.95**2 * area**2))
    assert forces.terms.bit_force == pytest.approx(-1300.0 * flow**2 / area, rel=1e-12)
    # the flow up the annulus drags the string up too, and its pressure is the ECD's
    assert forces.terms.axial is not None and np.all(forces.terms.axial <= 0.0)
    assert forces.density_at_bit > 1300.0
    assert forces.string_loss > forces.surge_at_bit > 0.0


def test_the_bit_drop_from_the_standpipe_pressure(well: Well) -> None:
    """Without nozzles the bit's drop is the standpipe pressure less the modelled losses."""
    no_nozzles = HydraulicModel(replace(well, hydraulics=replace(well.hydraulics,
                                                                 nozzle_area=None)))
    flow = 0.03
    known = no_nozzles.forces(3000.0, 0.0, flow_rate=flow)
    assert math.isnan(known.bit_pressure_drop) and known.terms.bit_force == 0.0
    spp = known.string_loss + known.surge_at_bit + 60e5
    forces = no_nozzles.forces(3000.0, 0.0, flow_rate=flow, standpipe_pressure=spp + 5e5,
                               surface_loss=5e5)
    assert forces.bit_pressure_drop == pytest.approx(60e5)
    assert forces.terms.bit_force == pytest.approx(-0.95 * flow * math.sqrt(2 * 1300 * 60e5))
    tools = HydraulicModel(replace(well, hydraulics=replace(well.hydraulics, nozzle_area=None,
                                                            pump_open_area=0.01)))
    with_tools = tools.forces(3000.0, 0.0, flow_rate=flow, standpipe_pressure=spp + 5e5,
                              surface_loss=5e5)
    assert with_tools.terms.bit_force == pytest.approx(forces.terms.bit_force - 0.01 * 60e5)


def test_trip_speed_limits_reach_the_window(hydraulic: HydraulicModel) -> None:
    depth = 3000.0
    limits = hydraulic.trip_speed_limits(depth)
    assert 0.0 < limits.pulling_out < limits.running_in < 5.0
    # the pressure rises with the speed, by jumps where the flow turns turbulent: the limit
    # is where the window is left, inside just below it and outside just above
    for factor, inside in ((0.999, True), (1.001, False)):
        swab = hydraulic.forces(depth, -factor * limits.pulling_out)
        assert (swab.density_at_bit > 1150.0) is inside
        surge = hydraulic.forces(depth, factor * limits.running_in)
        assert (max(surge.density_at_bit, surge.density_at_shoe) < 1550.0) is inside


def test_uniform_densities_are_the_well_with_that_fluid(well: Well, model: WellModel) -> None:
    """A density on every element equal to another fluid's gives that fluid's well (eq 36 is
    linear in the densities: only the last bits differ)."""
    n = model.n_elements
    heavy = FluidTerms(outside_density=np.full(n, 1500.0), inside_density=np.full(n, 1450.0))
    other = WellModel(replace(well, fluid=Fluid(1500.0, inside_density=1450.0)))
    for operation in ("static", "pick_up", "slack_off", "rotating"):
        got = model.evaluate(operation, 3300.0, 0.25, fluid=heavy)
        expected = other.evaluate(operation, 3300.0, 0.25)
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-6)
    static, _ = model.evaluate("static", 3300.0, 0.0)
    assert other.evaluate("static", 3300.0, 0.0)[0] < static


def test_a_pill_weighs_its_volume_times_the_density_difference(well: Well) -> None:
    """A 400 m column of 1900 kg/m^3 inside the vertical drill pipe (MD 100-500 m) adds
    (1900 - 1300) g A_i 400 m to the static hook load, for a plain tube (eq 41's weight; eq 36
    applied to a weight in air with tool joints scales the bore with that weight)."""
    plain = replace(PIPE, weight_in_air=None)
    model = WellModel(replace(well, string=DrillString((COLLARS, plain))))
    md = model.grid.md
    inside = np.where((md[:-1] >= 100.0) & (md[1:] <= 500.0), 1900.0, 1300.0)
    pill = FluidTerms(inside_density=inside)
    extra = model.evaluate("static", 3300.0, 0.0, fluid=pill)[0] - model.evaluate(
        "static", 3300.0, 0.0)[0]
    assert extra == pytest.approx(600.0 * GRAVITY * math.pi / 4 * (4.276 * INCH) ** 2 * 400.0,
                                  rel=1e-10)


def test_fluid_terms_are_checked(model: WellModel) -> None:
    with pytest.raises(ModelError, match="one value per hole-grid element"):
        model.evaluate("pick_up", 3000.0, 0.2, fluid=FluidTerms(axial=np.zeros(5)))
    with pytest.raises(ModelError, match="finite"):
        FluidTerms(axial=np.full(model.n_elements, np.nan))
    with pytest.raises(ModelError, match="share their fluid densities"):
        model.loads(3000.0, 0.2, operations=["pick_up", "slack_off"], fluid={
            "pick_up": FluidTerms(outside_density=np.full(model.n_elements, 1300.0)),
            "slack_off": FluidTerms(outside_density=np.full(model.n_elements, 1400.0))})


# --- against an independent integration ---------------------------------------------------


def _tangent(inc: float, azi: float) -> np.ndarray:
    return np.array([math.sin(inc) * math.cos(azi), math.sin(inc) * math.sin(azi), math.cos(inc)])


def _ode_hook_load(stations: tuple[list[float], list[float], list[float]], bit_depth: float,
                   axial_factor: float, fluid_per_metre: float, bit_force: float) -> float:
    """dF/ds = -(w t_z + a mu n + f) from the bit up (s down the hole), n = |F dt/ds + w (e_z -
    t_z t)| on the stations' circular arcs, F(bit) = the jets' force: written from a cable
    element's equilibrium with the fluid's axial force f, sharing no code with the march.
    The string: 150 m of collars under drill pipe, weights buoyed by eq 36 at 1300 kg/m^3;
    f is the drill pipe's or the collars' (per metre, in the hole section it lies in)."""
    md, inc, azi = (np.asarray(v, dtype=float) for v in stations)
    inc, azi = np.radians(inc), np.radians(azi)
    collar_top = bit_depth - 150.0

    def weight(s: float) -> float:
        return (COLLARS if s > collar_top else PIPE).buoyed_weight_in(1300.0)

    def path(s: float) -> tuple[np.ndarray, np.ndarray]:
        i = min(max(int(np.searchsorted(md, s, side="right")) - 1, 0), md.size - 2)
        t1, t2 = _tangent(inc[i], azi[i]), _tangent(inc[i + 1], azi[i + 1])
        beta = math.acos(min(1.0, float(t1 @ t2)))
        if beta < 1e-12:
            return t1, np.zeros(3)
        f = (s - md[i]) / (md[i + 1] - md[i])
        t = (math.sin((1 - f) * beta) * t1 + math.sin(f * beta) * t2) / math.sin(beta)
        dt = beta / (md[i + 1] - md[i]) * (-math.cos((1 - f) * beta) * t1
                                           + math.cos(f * beta) * t2)
        return t, dt / math.sin(beta)

    def rhs(s: float, y: np.ndarray) -> list[float]:
        t, dt = path(s)
        w = weight(s)
        mu = 0.2 if s < 1200.0 else 0.3
        contact = np.linalg.norm(y[0] * dt + w * (np.array([0.0, 0.0, 1.0]) - t[2] * t))
        return [-(w * t[2] + axial_factor * mu * contact + fluid_per_metre(s))]

    stops = sorted({0.0, bit_depth, collar_top, 1200.0, *[m for m in md if m < bit_depth]},
                   reverse=True)
    state = np.array([bit_force])
    for lower, upper in itertools.pairwise(stops):
        state = solve_ivp(rhs, (lower, upper), state, rtol=1e-11, atol=1e-6,
                          method="DOP853").y[:, -1]
    return float(state[0])


@pytest.mark.parametrize(("operation", "speed", "flow"), [
    ("pick_up", -0.8, 0.0), ("slack_off", 0.8, 0.0), ("pick_up", -0.3, 0.035),
    ("static", 0.0, 0.035)])
def test_march_with_fluid_agrees_with_the_ode(well: Well, model: WellModel,
                                              hydraulic: HydraulicModel, operation: str,
                                              speed: float, flow: float) -> None:
    depth = 3300.0
    forces = hydraulic.forces(depth, speed, flow_rate=flow)
    collar_top = depth - 150.0
    # the ODE's fluid force per metre, from the annulus formulas directly: closed string,
    # annular flow v_p A_o + q up, Burkhardt's effective velocity on each geometry
    per_geometry = {}
    for d_h, comp in itertools.product((8.681 * INCH, 8.5 * INCH), (COLLARS, PIPE)):
        d_o = comp.outer_diameter
        annulus = math.pi / 4 * (d_h**2 - d_o**2)
        mean = (speed * math.pi / 4 * d_o**2 + flow) / annulus
        velocity = float(h.effective_annular_velocity(MUD, 1300.0, mean * annulus, -speed,
                                                      d_h, d_o))
        gradient = float(h.annulus_pressure_gradient(MUD, 1300.0, velocity, d_h, d_o))
        per_geometry[(d_h, comp.name)] = -gradient * math.pi / 4 * d_o * d_h

    def fluid(s: float) -> float:
        return per_geometry[(8.681 * INCH if s < 1200.0 else 8.5 * INCH,
                             "collars" if s > collar_top else "drill pipe")]

    factor = {"pick_up": 1.0, "slack_off": -1.0, "static": 0.0}[operation]
    expected = _ode_hook_load(BUILD_AND_HOLD, depth, factor, fluid, forces.terms.bit_force)
    hookload, _ = model.evaluate(operation, depth, None, fluid=forces.terms)
    # 10 m elements and Heun's step: 1e-6 found without fluid terms (test_torque_drag)
    assert hookload == pytest.approx(expected, rel=2e-6)
    assert hookload != pytest.approx(model.evaluate(operation, depth, None)[0], rel=1e-3)


def test_aadnoy_adds_the_fluid_force_where_the_weight_lifts() -> None:
    """A vertical hole: Aadnoy's straight runs, F = w L + f L for every operation."""
    vertical = _well(([0.0, 3400.0], [0.0, 0.0], [0.0, 0.0]), float_valve=True)
    model = WellModel(vertical)
    n = model.n_elements
    terms = FluidTerms(axial=np.full(n, 12.0), bit_force=-3000.0)
    for method in ("aadnoy", "soft-string"):
        without, _ = model.evaluate("pick_up", 3000.0, 0.3, method=method)
        with_fluid, _ = model.evaluate("pick_up", 3000.0, 0.3, method=method, fluid=terms)
        assert with_fluid - without == pytest.approx(12.0 * 3000.0 - 3000.0, rel=1e-12)


# --- every call with fluid terms ----------------------------------------------------------


def _terms(model: WellModel, hydraulic: HydraulicModel, depth: float,
           speed: float) -> FluidTerms:
    forces = hydraulic.forces(depth, speed)
    md = model.grid.md
    pill = np.where((md[:-1] > 300.0) & (md[:-1] < 900.0), 1800.0, 1300.0)
    return replace(forces.terms, inside_density=pill,
                   outside_density=np.full(model.n_elements, 1320.0))


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_cases_loads_and_broomstick_are_evaluate_s_with_fluid(
        model: WellModel, hydraulic: HydraulicModel, method: str) -> None:
    depth = 3250.0
    up, down = _terms(model, hydraulic, depth, -0.7), _terms(model, hydraulic, depth, 0.7)
    down = replace(down, inside_density=up.inside_density,
                   outside_density=up.outside_density)
    cases = np.stack([model.friction(mu) for mu in (0.1, 0.25, 0.4)])
    for operation, terms in (("pick_up", up), ("slack_off", down)):
        single = model.evaluate(operation, depth, cases[1], method=method, fluid=terms)
        hookloads, torques = model.evaluate_cases(operation, depth, cases, method=method,
                                                  fluid=terms)
        assert (hookloads[1], torques[1]) == single
    loads = model.loads(depth, cases[1], method=method, operations=["pick_up", "slack_off"],
                        fluid={"pick_up": up, "slack_off": down})
    assert loads.hookload["pick_up"] == model.evaluate("pick_up", depth, cases[1],
                                                       method=method, fluid=up)[0]
    assert loads.hookload["slack_off"] == model.evaluate("slack_off", depth, cases[1],
                                                         method=method, fluid=down)[0]
    value, _ = model.evaluate_gradient("pick_up", depth, cases[1], method=method, fluid=up)
    assert value == loads.hookload["pick_up"]
    broom = broomstick_from_model(
        model, [2000.0, depth], [0.1, 0.25], method=method,
        fluid=lambda d, op: (hydraulic.forces(d, {"pick_up": -0.7, "slack_off": 0.7}
                                              .get(op.value, 0.0)).terms))
    assert broom.hookload["pick_up"][1, 1] == model.evaluate(
        "pick_up", depth, 0.25, method=method, fluid=hydraulic.forces(depth, -0.7).terms)[0]


@pytest.mark.parametrize("method", ["soft-string", "aadnoy"])
def test_gradient_with_fluid_matches_central_differences(
        model: WellModel, hydraulic: HydraulicModel, method: str) -> None:
    depth = 3250.0
    terms = _terms(model, hydraulic, depth, -0.7)
    mu = np.random.default_rng(5).uniform(0.1, 0.4, model.n_elements)
    for operation, quantity in (("pick_up", 0), ("slack_off", 0), ("rotating", 1)):
        _, gradient = model.evaluate_gradient(operation, depth, mu, quantity_index=quantity,
                                              method=method, fluid=terms)
        expected = np.zeros(model.n_elements)
        for e in np.flatnonzero(model.node_md[:-1] < depth)[::7]:
            step = np.zeros(model.n_elements)
            step[e] = 1e-5
            high = model.evaluate(operation, depth, mu + step, method=method, fluid=terms)
            low = model.evaluate(operation, depth, mu - step, method=method, fluid=terms)
            expected[e] = (high[quantity] - low[quantity]) / 2e-5
        checked = expected != 0.0
        scale = np.max(np.abs(expected))
        assert np.max(np.abs(gradient[checked] - expected[checked])) < 1e-6 * scale


def test_zero_fluid_terms_change_no_bit(model: WellModel) -> None:
    n = model.n_elements
    nothing = FluidTerms(axial=np.zeros(n), outside_density=np.full(n, 1300.0),
                         inside_density=np.full(n, 1300.0))
    for method in ("soft-string", "aadnoy"):
        for operation in ("pick_up", "slack_off", "rotating"):
            assert model.evaluate(operation, 3100.0, 0.27, method=method, fluid=nothing) == \
                model.evaluate(operation, 3100.0, 0.27, method=method)
        with_terms = model.loads(3100.0, 0.27, method=method, fluid=nothing)
        without = model.loads(3100.0, 0.27, method=method)
        for name, force in without.axial_force.items():
            assert force.tolist() == with_terms.axial_force[name].tolist()


def test_terms_are_packed_once_and_kept_from_the_caller_s_edits(model: WellModel) -> None:
    n = model.n_elements
    axial = np.full(n, 15.0)
    terms = FluidTerms(axial=axial)
    assert terms.axial is not None and not terms.axial.flags.writeable
    first = model.evaluate("pick_up", 3000.0, 0.2, fluid=terms)
    packed = model.kernel_fluid((terms,))
    assert model.kernel_fluid((terms,)) is packed  # kept while the same terms come
    axial[:] = 1000.0  # the caller's array: the terms hold a copy
    assert model.evaluate("pick_up", 3000.0, 0.2, fluid=terms) == first
    other = FluidTerms(axial=axial)
    assert model.kernel_fluid((other,)) is not packed
    assert model.evaluate("pick_up", 3000.0, 0.2, fluid=other)[0] > first[0] + 1e6
    assert model.kernel_fluid((terms, None)).shape == (4, n)
