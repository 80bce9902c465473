"""Wells shared by the model tests, as fixtures (a helper module named conftest cannot be
imported safely when several test folders have one). The model tests run on the kernels
``TDMON_KERNELS`` chooses: numba's unless it says ``python`` (`tests/model/test_kernels.py`
holds the two engines to the same numbers)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from tdmon.model.string import DrillString, StringComponent
from tdmon.model.survey import minimum_curvature
from tdmon.model.well import Fluid, HoleSection, Well

# Aadnoy, Mechanics of Drilling, Example 7.1 (the thesis's Table 4): vertical to the kick-off
# point, build at R = 500 m to 60 deg, 2000 m drill-pipe sail, 200 m BHA at 60 deg.
KOP = 1500.0
BUILD_RADIUS = 500.0
HOLD_INCLINATION = math.radians(60.0)
END_OF_BUILD = KOP + BUILD_RADIUS * HOLD_INCLINATION  # 2023.6 m
TOP_OF_BHA = END_OF_BUILD + 2000.0
TOTAL_DEPTH = TOP_OF_BHA + 200.0


def example_71_well(element_length: float = 10.0) -> Well:
    """Example 7.1 from survey stations, buoyed weights as given, r = 0.08 m, block weight 0."""
    survey = minimum_curvature(
        [0.0, KOP, END_OF_BUILD, TOTAL_DEPTH], [0.0, 0.0, 60.0, 60.0], [0.0, 0.0, 0.0, 0.0]
    )
    string = DrillString((
        StringComponent("BHA", 200.0, outer_diameter=0.16, inner_diameter=0.07,
                        buoyed_weight=3000.0),
        StringComponent("drill pipe", TOTAL_DEPTH - 200.0, outer_diameter=0.16,
                        inner_diameter=0.108, buoyed_weight=300.0),
    ))
    return Well(
        survey=survey,
        string=string,
        sections=(HoleSection(0.0, TOTAL_DEPTH, 0.2159, "open", friction=0.15),),
        fluid=Fluid(density=1560.0),
        element_length=element_length,
        name="Example 7.1",
    )


@pytest.fixture(scope="session")
def example_71() -> Well:
    return example_71_well()


@pytest.fixture(scope="session")
def make_example_71() -> Callable[..., Well]:
    return example_71_well


def three_d_stations() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 3D well at 30 m stations: build, hold, turn across north (350 -> 10 deg), drop."""
    md = np.arange(0.0, 3630.0, 30.0)
    inclination = np.interp(md, [0, 600, 1200, 2100, 2700, 3600], [0, 0, 50, 50, 30, 30])
    azimuth = np.interp(md, [0, 1500, 2100, 3600], [350, 350, 370, 370]) % 360.0
    return md, inclination, azimuth


def three_d_well(element_length: float = 10.0) -> Well:
    md, inclination, azimuth = three_d_stations()
    string = DrillString((
        StringComponent("BHA", 150.0, outer_diameter=0.1651, inner_diameter=0.0714,
                        buoyed_weight=1500.0, tool_joint_diameter=0.16),
        StringComponent("drill pipe", 4000.0, outer_diameter=0.127, inner_diameter=0.1086,
                        buoyed_weight=250.0, tool_joint_diameter=0.1651),
    ))
    return Well(
        survey=minimum_curvature(md, inclination, azimuth),
        string=string,
        sections=(HoleSection(0.0, 1000.0, 0.2245, "cased", friction=0.2),
                  HoleSection(1000.0, float(md[-1]), 0.2159, "open", friction=0.3)),
        fluid=Fluid(density=1300.0),
        element_length=element_length,
        name="3D test well",
    )


@pytest.fixture(scope="session")
def three_d() -> Well:
    return three_d_well()


@pytest.fixture(scope="session")
def three_d_survey_stations() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return three_d_stations()
