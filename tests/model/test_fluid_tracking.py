"""The fluid state followed through rig samples (tdmon.model.fluid_tracking): pumped volumes,
a pill's mass, trips with the hole kept full, the first sample's placement."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tdmon.config.well import load_well_model
from tdmon.model.fluid_tracking import FluidTracker, hydraulics_configured
from tdmon.model.well import Well

WELLS = Path(__file__).resolve().parents[2] / "replays" / "scenarios" / "wells"
MUD = 1400.0
BIT = 3600.0


@pytest.fixture(scope="module")
def well() -> Well:
    return load_well_model(WELLS / "example-7-1-float-valve.toml")


def _inside_excess_mass(tracker: FluidTracker, well: Well) -> float:
    """Mass inside the string above the mud's [kg], summed over the grid's elements."""
    _, inside = tracker.densities()
    grid = tracker.path.grid
    md = grid.md
    middle = 0.5 * (md[:-1] + md[1:])
    tops = well.string.component_tops()
    bit = tracker.bit_depth
    component = np.minimum(np.searchsorted(tops, bit - middle), tops.size - 1)
    bore = np.array([math.pi / 4 * c.inner_diameter**2 for c in well.string.components])
    in_string = middle < bit
    return float(np.sum(((inside - MUD) * bore[component] * np.diff(md))[in_string]))


def test_a_float_valve_well_file_asks_for_the_fluid_terms(well: Well) -> None:
    assert hydraulics_configured(well)
    plain = load_well_model(WELLS / "example-7-1-weights.toml")
    assert not hydraulics_configured(plain)


def test_the_first_sample_places_the_well_full_of_its_mud(well: Well) -> None:
    tracker = FluidTracker(well, bit_depth=0.0)
    tracker.update(0.0, BIT)
    outside, inside = tracker.densities()
    assert tracker.uniform()
    np.testing.assert_allclose(outside, MUD, rtol=1e-12)
    np.testing.assert_allclose(inside, MUD, rtol=1e-12)


def test_a_pill_pumped_at_a_rate_holds_its_mass_in_the_pipe(well: Well) -> None:
    """2 m3 of 2000 kg/m3 at 2000 L/min for 60 s: 600 kg/m3 over the mud times 2 m3 = 1200 kg
    more inside the string; 4.276 in drill pipe (bore 9.265e-3 m2) holds it over 215.9 m from
    the top, where the bore is the pill's."""
    tracker = FluidTracker(well, bit_depth=BIT)
    flow = 2.0 / 60.0
    tracker.update(0.0, BIT, flow, 2000.0)
    tracker.update(60.0, BIT, 0.0, 2000.0)  # the rate held for 60 s: 2 m3
    assert tracker.pumped == pytest.approx(2.0)
    assert _inside_excess_mass(tracker, well) == pytest.approx(1200.0, rel=1e-9)
    _, inside = tracker.densities()
    md = tracker.path.grid.md
    bore = math.pi / 4 * (4.276 * 0.0254) ** 2
    length = 2.0 / bore
    assert length == pytest.approx(215.9, abs=0.1)
    assert inside[(md[1:] <= length)].min() == pytest.approx(2000.0)
    assert inside[(md[:-1] >= length) & (md[1:] < BIT)].max() == pytest.approx(MUD)
    assert not tracker.uniform()


def test_the_last_rate_and_density_pump_until_the_next_sample(well: Well) -> None:
    """Samples at 0, 10 and 25 s with rates 0.01, 0.02 and 0 m3/s: 0.1 + 0.3 m3 pumped."""
    tracker = FluidTracker(well, bit_depth=BIT)
    tracker.update(0.0, BIT, 0.01, 1900.0)
    tracker.update(10.0, BIT, 0.02, 1900.0)
    tracker.update(25.0, BIT, 0.0)
    assert tracker.pumped == pytest.approx(0.4)
    assert _inside_excess_mass(tracker, well) == pytest.approx(0.4 * 500.0, rel=1e-9)


def test_a_trip_out_keeps_the_hole_full_of_the_mud(well: Well) -> None:
    tracker = FluidTracker(well, bit_depth=BIT)
    tracker.update(0.0, BIT)
    for k, depth in enumerate(np.linspace(BIT, BIT - 90.0, 10)[1:]):
        tracker.update(10.0 * (k + 1), float(depth))
    assert tracker.bit_depth == pytest.approx(BIT - 90.0)
    assert tracker.uniform()
    outside, _ = tracker.densities()
    np.testing.assert_allclose(outside, MUD, rtol=1e-12)


def test_a_trip_out_without_fill_lowers_the_annulus(well: Well) -> None:
    """Pulling 90 m of string without filling: the hole loses the closed volume of the 90 m of
    5 in drill pipe that leave it at surface (the bore's mud leaves with them), taken from the
    top of the annulus between the 8.681 in casing and the 5 in pipe: 44.68 m."""
    tracker = FluidTracker(well, bit_depth=BIT, keep_full=False)
    tracker.update(0.0, BIT)
    tracker.update(60.0, BIT - 90.0)
    pipe_area = math.pi / 4 * (5 * 0.0254) ** 2
    casing_area = math.pi / 4 * (8.681 * 0.0254) ** 2
    drop = pipe_area * 90.0 / (casing_area - pipe_area)
    assert drop == pytest.approx(44.68, abs=0.01)
    assert tracker.state.annulus_level == pytest.approx(drop, rel=1e-9)
    outside, _ = tracker.densities()
    md = tracker.path.grid.md
    assert np.all(outside[md[1:] <= 40.0] == 0.0)  # air above the level


def test_a_noisy_mud_density_in_stays_one_mud(well: Well) -> None:
    """Mud density in read 1400 +- 15 kg/m3 while pumping and tripping: within the 20 kg/m3
    resolution it is the well's mud, and no layer is cut per sample; a 1500 kg/m3 mud is new."""
    tracker = FluidTracker(well, bit_depth=BIT)
    noise = [0.0, 12.0, -15.0, 8.0, -3.0, 14.0, -9.0, 5.0]
    for k, offset in enumerate(noise):
        tracker.update(10.0 * k, BIT - 2.0 * k, 0.03, MUD + offset)
    assert tracker.uniform()
    assert tracker.state.outside_density.size == 1
    tracker.update(80.0, BIT - 16.0, 0.03, 1500.0)
    tracker.update(90.0, BIT - 18.0, 0.0)
    assert tracker.density_in == 1500.0
    assert _inside_excess_mass(tracker, well) == pytest.approx(0.3 * 100.0, rel=1e-6)
