"""The fluids in a well as plug flow moves them (tdmon.model.fluid_state): a pill pumped and
chased, the returns, a trip with and without fill, a U-tube, the per-element densities; hand
values in a vertical well of one hole size and one pipe, and mass kept in a deviated one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model.fluid_state import (
    FluidPath,
    element_densities,
    initial_state,
    move_string,
    pump,
    u_tube,
)
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.well import Fluid, HoleSection, Well

INCH = 0.0254
BORE = math.pi / 4 * (4.276 * INCH) ** 2  # 0.009265 m^3/m
STEEL = math.pi / 4 * (5.0 * INCH) ** 2  # closed-end displacement, 0.012668 m^3/m
HOLE = math.pi / 4 * (8.5 * INCH) ** 2
ANNULUS = HOLE - STEEL
MUD, PILL = 1300.0, 1800.0


def _vertical() -> FluidPath:
    pipe = StringComponent("drill pipe", 3000.0, 5.0 * INCH, 4.276 * INCH, weight_in_air=330.0)
    well = Well(survey=minimum_curvature([0.0, 3000.0], [0.0, 0.0], [0.0, 0.0]),
                string=DrillString((pipe,)),
                sections=(HoleSection(0.0, 3000.0, 8.5 * INCH, "open", friction=0.3),),
                fluid=Fluid(MUD), element_length=10.0, name="vertical")
    return FluidPath(well)


def _mass(state: object, path: FluidPath, bit_depth: float) -> float:
    """Fluid mass in the well [kg], from the layers and the volumes they span."""
    inside = path.bore(state.inside_bounds)  # type: ignore[attr-defined]
    knots, cumulative = path.open_volume(bit_depth)
    bounds = state.outside_bounds  # type: ignore[attr-defined]
    above = np.interp(np.minimum(bounds, bit_depth), knots, cumulative)
    below = np.maximum(bounds - bit_depth, 0.0) * HOLE
    outside = above + below
    return float(np.sum(state.inside_density * np.diff(inside))  # type: ignore[attr-defined]
                 + np.sum(state.outside_density * np.diff(outside)))  # type: ignore[attr-defined]


def test_a_pill_pumped_and_chased_sits_where_its_volume_says() -> None:
    path = _vertical()
    state = initial_state(path, 3000.0)
    state, returns = pump(state, path, 3000.0, 3.0, PILL)  # 3 m^3: 323.8 m of bore
    pill_length = 3.0 / BORE
    assert pill_length == pytest.approx(323.8, abs=0.1)
    # the pill on top, the mud it pushed out at the bit in the annulus, returned at surface
    assert state.inside_density.tolist() == [MUD, PILL]
    assert state.inside_bounds == pytest.approx([0.0, 3000.0 - pill_length, 3000.0])
    assert returns.volume.sum() == pytest.approx(3.0) and returns.mean_density == MUD
    # chased by 10 m^3 of mud: the pill's top at 10 m^3 of bore below surface
    state, _ = pump(state, path, 3000.0, 10.0, MUD)
    top = 3000.0 - 10.0 / BORE
    assert state.inside_density.tolist() == [MUD, PILL, MUD]
    assert state.inside_bounds == pytest.approx([0.0, top - pill_length, top, 3000.0])
    # per element: the elements between MD 10/A_i and 13/A_i hold the pill
    outside, inside = element_densities(state, path, 3000.0)
    md = path.grid.md
    mid = 0.5 * (md[:-1] + md[1:])
    expected = np.where((mid > 10.0 / BORE) & (mid < 13.0 / BORE), PILL, MUD)
    whole = (md[:-1] >= 10.0 / BORE) & (md[1:] <= 13.0 / BORE) | (md[1:] <= 10.0 / BORE) \
        | (md[:-1] >= 13.0 / BORE)
    assert inside[whole] == pytest.approx(expected[whole])
    cut = int(np.searchsorted(md, 10.0 / BORE)) - 1  # the element the pill's top cuts
    share = (md[cut + 1] - 10.0 / BORE) / (md[cut + 1] - md[cut])
    assert inside[cut] == pytest.approx(MUD + share * (PILL - MUD))
    assert np.all(outside == MUD)


def test_past_the_bit_the_pill_rises_by_volume_over_annular_capacity() -> None:
    path = _vertical()
    capacity = BORE * 3000.0
    state, _ = pump(initial_state(path, 3000.0), path, 3000.0, 3.0, PILL)
    start = _mass(state, path, 3000.0)
    # chase the pill all the way out of the string and 5 m^3 up the annulus
    chase = capacity + 5.0 - 3.0
    state, returns = pump(state, path, 3000.0, chase, MUD)
    assert state.inside_density.tolist() == [MUD]
    assert state.outside_density.tolist() == [MUD, PILL, MUD]
    top, bottom = 3000.0 - 5.0 / ANNULUS, 3000.0 - 2.0 / ANNULUS
    assert state.outside_bounds == pytest.approx([0.0, top, bottom, 3000.0])
    # what came back is mud, as much as was pumped; the mass in the well is unchanged
    assert returns.volume.sum() == pytest.approx(chase) and returns.mean_density == MUD
    assert _mass(state, path, 3000.0) == pytest.approx(start, rel=1e-12)
    # pumping on brings the pill back: out comes mud, then 3 m^3 of pill
    state, returns = pump(state, path, 3000.0, 3000.0 * ANNULUS, MUD)
    assert state.outside_density.tolist() == [MUD]
    assert returns.mean_density == pytest.approx((PILL * 3.0 + MUD * (3000.0 * ANNULUS - 3.0))
                                                 / (3000.0 * ANNULUS))


def test_pulling_out_with_and_without_fill() -> None:
    path = _vertical()
    state = initial_state(path, 3000.0)
    # 300 m pulled closed (the bore's mud leaves with the pipe): the hole takes 300 A_o of fill
    filled = move_string(state, path, 3000.0, 2700.0, fill_density=1200.0)
    depth = 300.0 * STEEL / ANNULUS
    assert filled.outside_density.tolist() == [1200.0, MUD]
    assert filled.outside_bounds == pytest.approx([0.0, depth, 3000.0])
    assert filled.level == pytest.approx(2700.0)  # the string stays full
    # without fill the annulus's level falls by as much
    dry = move_string(state, path, 3000.0, 2700.0, fill_density=None)
    assert dry.annulus_level == pytest.approx(depth)
    assert dry.outside_density.tolist() == [MUD]
    # running back in, the pipe brings its steel and pushes the fill out
    back = move_string(filled, path, 2700.0, 3000.0, fill_density=None)
    assert back.outside_bounds == pytest.approx([0.0, 3000.0])
    assert back.outside_density.tolist() == [MUD]
    # its new stands came empty: the string is full to 300 m below the top only
    assert back.level == pytest.approx(2700.0)


def test_a_heavy_pill_u_tubes_out_of_an_open_string() -> None:
    """Pressures at the bit equal after settling: 1800 h + 1300 (3000 - x - h) = 1300 x 3000
    with the annulus full of mud, so the string falls dry by x = 500 h / 1300."""
    path = _vertical()
    state, _ = pump(initial_state(path, 3000.0), path, 3000.0, 3.0, PILL)
    pill = 3.0 / BORE
    settled = u_tube(state, path, 3000.0)
    dry = (PILL - MUD) * pill / MUD
    assert dry == pytest.approx(124.5, abs=0.1)
    assert settled.level == pytest.approx(3000.0 - dry, abs=1e-4)
    assert settled.inside_density.tolist() == [MUD, PILL]
    assert settled.outside_bounds == pytest.approx([0.0, 3000.0]) and \
        settled.outside_density.tolist() == [MUD]
    # a trip of an open string settles the same way; a closed one keeps its column
    assert move_string(state, path, 3000.0, 3000.0, fill_density=MUD,
                       closed=False).level == pytest.approx(settled.level, abs=1e-4)
    assert move_string(state, path, 3000.0, 3000.0, fill_density=MUD).level == 3000.0


def test_a_string_run_unfilled_draws_mud_in_and_a_fill_up_tops_it() -> None:
    path = _vertical()
    state = initial_state(path, 2000.0)
    ran = move_string(state, path, 2000.0, 3000.0, fill_density=None)
    assert ran.level == pytest.approx(2000.0)  # 1000 m of empty pipe on top
    # open, it takes in mud at the bit until the pressures balance: the string fills to the
    # annulus's level, which falls by what went in: x A_a = (1000 - x) A_i... from the top
    settled = u_tube(ran, path, 3000.0)
    drop = 1000.0 * BORE / (BORE + ANNULUS)  # level inside = level outside, volume kept
    assert settled.annulus_level == pytest.approx(drop, abs=1e-4)
    assert settled.level == pytest.approx(3000.0 - drop, abs=1e-4)
    # a fill-up from the top: 1000 m of bore, nothing returns
    full, returns = pump(ran, path, 3000.0, 1000.0 * BORE, MUD)
    assert full.level == pytest.approx(3000.0) and returns.volume.size == 0


def test_mass_is_kept_in_a_deviated_well_of_two_sizes() -> None:
    collars = StringComponent("collars", 150.0, 6.5 * INCH, 2.8125 * INCH, weight_in_air=1330.0)
    pipe = StringComponent("drill pipe", 3250.0, 5.0 * INCH, 4.276 * INCH, weight_in_air=330.0)
    well = Well(survey=minimum_curvature([0.0, 800.0, 1400.0, 3400.0], [0.0, 0.0, 45.0, 60.0],
                                         [0.0, 0.0, 20.0, 40.0]),
                string=DrillString((collars, pipe)),
                sections=(HoleSection(0.0, 1200.0, 8.681 * INCH, "cased", friction=0.2),
                          HoleSection(1200.0, 3400.0, 8.5 * INCH, "open", friction=0.3)),
                fluid=Fluid(MUD), element_length=10.0, name="deviated")
    path = FluidPath(well)
    state = initial_state(path, 3300.0)
    start = _mass_general(state, path, 3300.0)
    state, returns = pump(state, path, 3300.0, 40.0, PILL)
    pumped_in = 40.0 * PILL - float(np.sum(returns.volume * returns.density))
    assert returns.volume.sum() == pytest.approx(40.0)
    assert _mass_general(state, path, 3300.0) == pytest.approx(start + pumped_in, rel=1e-10)
    # the string is all pill (its bore holds 29.2 m^3), 10.8 m^3 of it round the collars:
    # open, it settles with its top dry, the mud it displaces overflowing at surface
    assert state.inside_density.tolist() == [PILL]
    settled = u_tube(state, path, 3300.0)
    assert settled.level < state.level - 100.0
    drained = float(path.bore(np.array([state.level]))[0] - path.bore(np.array([settled.level]))[0])
    assert _mass_general(settled, path, 3300.0) == pytest.approx(
        _mass_general(state, path, 3300.0) - drained * MUD, rel=1e-10)
    # and the pressures at the bit are equal: rho g dTVD summed inside and outside
    inside_md = 3300.0 - settled.inside_bounds
    inside = np.sum(settled.inside_density * -np.diff(path.tvd(inside_md)))
    outside_md = np.minimum(settled.outside_bounds, 3300.0)
    outside = np.sum(settled.outside_density * np.diff(path.tvd(outside_md)))
    assert inside == pytest.approx(outside, rel=1e-8)


def _mass_general(state: object, path: FluidPath, bit_depth: float) -> float:
    inside = path.bore(state.inside_bounds)  # type: ignore[attr-defined]
    knots, cumulative = path.open_volume(bit_depth)
    bottom_area = path.hole_area[-1]
    bounds = state.outside_bounds  # type: ignore[attr-defined]
    outside = np.interp(np.minimum(bounds, bit_depth), knots, cumulative) \
        + np.maximum(bounds - bit_depth, 0.0) * bottom_area
    return float(np.sum(state.inside_density * np.diff(inside))  # type: ignore[attr-defined]
                 + np.sum(state.outside_density * np.diff(outside)))  # type: ignore[attr-defined]


def test_bad_input_is_refused() -> None:
    path = _vertical()
    with pytest.raises(ModelError, match="pumped volume must be >= 0"):
        pump(initial_state(path, 3000.0), path, 3000.0, -1.0, MUD)
    unknown = Well(survey=path.well.survey, string=path.well.string,
                   sections=path.well.sections, fluid=Fluid(math.nan), element_length=10.0)
    with pytest.raises(ModelError, match=r"\[fluid\] density"):
        initial_state(FluidPath(unknown), 3000.0)
