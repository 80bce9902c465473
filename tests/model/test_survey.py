"""Minimum-curvature survey: hand values, a published example, north crossing, interpolation,
validation and a real survey (Volve F-4)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model.survey import (
    dogleg_angle,
    interpolate_survey,
    minimum_curvature,
    ratio_factor,
    tvd_and_inclination,
)

VOLVE_TRAJECTORY = Path(__file__).resolve().parents[2] / "data" / "volve-f4" / "trajectory.csv"

# Example 7.1 (Aadnoy, Mechanics of Drilling): KOP 1500 m, R = 500 m to 60 deg, 2000 m + 200 m
KOP = 1500.0
END_OF_BUILD = KOP + 500.0 * math.radians(60.0)
TOP_OF_BHA = END_OF_BUILD + 2000.0
TOTAL_DEPTH = TOP_OF_BHA + 200.0


def test_single_arc_from_vertical_matches_circle_geometry() -> None:
    # 100 m arc from vertical to 10 deg at azimuth 45 deg: radius R = 100 m / beta, so by
    # plane geometry TVD = R sin(beta) and the horizontal displacement is R (1 - cos beta).
    survey = minimum_curvature([0.0, 100.0], [0.0, 10.0], [45.0, 45.0])
    beta = math.radians(10.0)
    radius = 100.0 / beta
    horizontal = radius * (1.0 - math.cos(beta))
    assert survey.tvd[1] == pytest.approx(radius * math.sin(beta), rel=1e-12)  # 99.4931 m
    assert survey.north[1] == pytest.approx(horizontal * math.cos(math.radians(45)), rel=1e-12)
    assert survey.east[1] == pytest.approx(horizontal * math.sin(math.radians(45)), rel=1e-12)
    assert survey.tvd[1] == pytest.approx(99.4931, abs=1e-4)
    assert survey.dogleg[1] == pytest.approx(beta)
    assert survey.dls[1] == pytest.approx(beta / 100.0)
    assert survey.dogleg[0] == 0.0 and survey.dls[0] == 0.0


def test_hand_computed_3d_interval() -> None:
    # I 20 -> 30 deg, A 40 -> 60 deg over 30 m, by hand with the formulas of Sawaryn and
    # Thorogood (2005): cos(beta) = cos(dI) - sin I1 sin I2 (1 - cos dA)
    i1, i2, a1, a2 = map(math.radians, (20.0, 30.0, 40.0, 60.0))
    beta = math.acos(math.cos(i2 - i1) - math.sin(i1) * math.sin(i2) * (1 - math.cos(a2 - a1)))
    rf = 2.0 / beta * math.tan(beta / 2.0)
    north = 15.0 * (math.sin(i1) * math.cos(a1) + math.sin(i2) * math.cos(a2)) * rf
    east = 15.0 * (math.sin(i1) * math.sin(a1) + math.sin(i2) * math.sin(a2)) * rf
    tvd = 15.0 * (math.cos(i1) + math.cos(i2)) * rf
    survey = minimum_curvature([1000.0, 1030.0], [20.0, 30.0], [40.0, 60.0], tvd0=900.0,
                               north0=10.0, east0=-5.0)
    assert survey.dogleg[1] == pytest.approx(beta, rel=1e-9)
    assert survey.tvd[1] - 900.0 == pytest.approx(tvd, rel=1e-12)
    assert survey.north[1] - 10.0 == pytest.approx(north, rel=1e-12)
    assert survey.east[1] + 5.0 == pytest.approx(east, rel=1e-12)


def test_published_example_71_depths() -> None:
    # Aadnoy, Mechanics of Drilling, Example 7.1 (thesis Table 5): MD/TVD/HD of the top of the
    # sail 2024/1933/250 m, top of BHA 4024/2933/1982 m, bottom 4224/3033/2155 m (rounded).
    survey = minimum_curvature([0.0, KOP, END_OF_BUILD, TOP_OF_BHA, TOTAL_DEPTH],
                               [0, 0, 60, 60, 60], [0, 0, 0, 0, 0])
    assert survey.md[2:] == pytest.approx([2024, 4024, 4224], abs=0.5)
    assert survey.tvd[2:] == pytest.approx([1933, 2933, 3033], abs=0.5)
    assert survey.north[2:] == pytest.approx([250, 1982, 2155], abs=0.5)


def test_azimuth_wraps_across_north() -> None:
    # Horizontal, 350 -> 10 deg over 100 m: a 20 deg turn symmetric about north, not 340 deg
    crossing = minimum_curvature([0.0, 100.0], [90.0, 90.0], [350.0, 10.0])
    beta = math.radians(20.0)
    assert crossing.dogleg[1] == pytest.approx(beta)
    assert crossing.east[1] == pytest.approx(0.0, abs=1e-12)
    assert crossing.north[1] == pytest.approx(2 * 100.0 / beta * math.sin(beta / 2))  # chord
    for azimuths in ([-10.0, 10.0], [350.0, 370.0], [710.0, 10.0]):
        same = minimum_curvature([0.0, 100.0], [90.0, 90.0], azimuths)
        assert same.north[1] == pytest.approx(crossing.north[1], rel=1e-12)
        assert same.east[1] == pytest.approx(0.0, abs=1e-9)
    assert crossing.azimuth.min() >= 0.0 and crossing.azimuth.max() < 2 * math.pi


def test_dogleg_and_ratio_factor_arrays_match_scalars() -> None:
    inc1 = np.radians([0.0, 10.0, 45.0, 90.0])
    inc2 = np.radians([5.0, 10.0, 50.0, 80.0])
    azi1 = np.radians([0.0, 350.0, 90.0, 180.0])
    azi2 = np.radians([0.0, 10.0, 95.0, 170.0])
    doglegs = dogleg_angle(inc1, azi1, inc2, azi2)
    for k in range(4):
        assert doglegs[k] == pytest.approx(float(dogleg_angle(inc1[k], azi1[k], inc2[k], azi2[k])))
    assert float(ratio_factor(0.0)) == 1.0
    assert float(ratio_factor(1e-5)) == pytest.approx(1.0 + 1e-10 / 12, rel=1e-14)
    assert float(ratio_factor(math.pi / 2)) == pytest.approx(4 / math.pi)  # (2/beta) tan(beta/2)


def test_interpolation_reproduces_stations(
    three_d_survey_stations: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    md, inc, azi = three_d_survey_stations
    survey = minimum_curvature(md, inc, azi)
    again = interpolate_survey(survey, survey.md)
    for name in ("inclination", "tvd", "north", "east"):
        assert np.allclose(getattr(again, name), getattr(survey, name), rtol=0, atol=1e-9), name
    # azimuth compared as directions (0 and 2 pi are the same)
    assert np.allclose(np.cos(again.azimuth - survey.azimuth), 1.0, atol=1e-12)


def test_interpolated_points_lie_on_the_arc() -> None:
    survey = minimum_curvature([0.0, 30.0, 60.0], [40.0, 47.0, 44.0], [350.0, 6.0, 15.0])
    fine_md = np.linspace(0.0, 60.0, 61)
    fine = interpolate_survey(survey, fine_md)
    # The arc has constant curvature: every 1 m step turns by the same dogleg, and running
    # minimum curvature over the interpolated stations lands on the same positions.
    turn = fine.dogleg[1:]
    assert np.allclose(turn[:30], survey.dogleg[1] / 30, rtol=1e-9)
    assert np.allclose(turn[30:], survey.dogleg[2] / 30, rtol=1e-9)
    rebuilt = minimum_curvature(fine_md, np.degrees(fine.inclination), np.degrees(fine.azimuth))
    for name in ("tvd", "north", "east"):
        assert np.allclose(getattr(rebuilt, name), getattr(fine, name), rtol=0, atol=1e-9), name
    # each point is at the chord distance 2 R sin(f beta / 2) from the first station
    radius = 30.0 / survey.dogleg[1]
    f = fine_md[1:30] / 30.0
    chord = np.sqrt(fine.tvd[1:30] ** 2 + fine.north[1:30] ** 2 + fine.east[1:30] ** 2)
    assert np.allclose(chord, 2 * radius * np.sin(f * survey.dogleg[1] / 2), rtol=1e-12)


def test_tvd_and_inclination_are_interpolate_surveys_to_the_last_bit() -> None:
    # the loads along the string take these two alone; they must not move a recorded number
    rng = np.random.default_rng(17)
    for _ in range(40):
        n = int(rng.integers(2, 12))
        md = np.cumsum(rng.uniform(5.0, 400.0, n)) - 5.0
        survey = minimum_curvature(md, rng.uniform(0.0, 100.0, n) * (rng.random(n) > 0.2),
                                   rng.uniform(0.0, 360.0, n))
        targets = np.sort(rng.uniform(md[0], md[-1], int(rng.integers(1, 500))))
        targets = np.unique(np.concatenate([targets, md[rng.random(n) > 0.5]]))
        full = interpolate_survey(survey, targets)
        tvd, inclination = tvd_and_inclination(survey, targets)
        assert tvd.tobytes() == full.tvd.tobytes()
        assert inclination.tobytes() == full.inclination.tobytes()


def test_interpolation_outside_survey_is_an_error() -> None:
    survey = minimum_curvature([0.0, 100.0], [0.0, 10.0], [0.0, 0.0])
    with pytest.raises(ModelError, match="outside the survey"):
        interpolate_survey(survey, [50.0, 150.0])
    with pytest.raises(ModelError, match="outside the survey"):
        tvd_and_inclination(survey, [50.0, 150.0])


@pytest.mark.parametrize("depths", [[10.0, 50.0, 50.0], [10.0, 60.0, 50.0], [80.0, 20.0]])
def test_interpolation_depths_must_increase(depths: list[float]) -> None:
    survey = minimum_curvature([0.0, 100.0], [0.0, 10.0], [0.0, 0.0])
    with pytest.raises(ModelError, match="increase strictly"):
        interpolate_survey(survey, depths)
    with pytest.raises(ModelError, match="increase strictly"):
        tvd_and_inclination(survey, depths)
    assert tvd_and_inclination(survey, [50.0])[0].shape == (1,)  # one depth needs no order


@pytest.mark.parametrize(
    ("md", "inc", "azi", "reason"),
    [
        ([0.0, 100.0, 100.0], [0, 1, 2], [0, 0, 0], "increase strictly"),
        ([0.0, 100.0, 90.0], [0, 1, 2], [0, 0, 0], "increase strictly"),
        ([0.0, 100.0], [0, 181], [0, 0], "0-180"),
        ([0.0, 100.0], [-1, 10], [0, 0], "0-180"),
        ([0.0, np.nan], [0, 10], [0, 0], "not finite"),
        ([0.0, 100.0], [0, 10], [0, np.inf], "not finite"),
        ([0.0], [0], [0], "at least 2"),
        ([0.0, 100.0], [0, 10, 20], [0, 0, 0], "same length"),
    ],
)
def test_invalid_surveys_are_rejected(md: list[float], inc: list[float], azi: list[float],
                                      reason: str) -> None:
    with pytest.raises(ModelError, match=reason):
        minimum_curvature(md, inc, azi)


def test_volve_f4_trajectory_matches_its_own_positions() -> None:
    # 87 MWD stations of Volve 15/9-F-4 with the operator's TVD/NS/EW columns. Found: agreement
    # to ~1e-11 m (the operator's values are minimum curvature too), DLS to 2e-6 deg/30 m.
    data = np.genfromtxt(VOLVE_TRAJECTORY, delimiter=",", names=True, dtype=None,
                         encoding="utf-8")
    survey = minimum_curvature(data["md_m"], data["incl_deg"], data["azi_deg"])
    assert np.max(np.abs(survey.tvd - data["tvd_m"])) < 1e-6
    assert np.max(np.abs(survey.north - data["ns_m"])) < 1e-6
    assert np.max(np.abs(survey.east - data["ew_m"])) < 1e-6
    dls_deg_30m = np.degrees(survey.dls) * 30.0
    assert np.max(np.abs(dls_deg_30m - data["dls_deg_per_30m"])) < 1e-4
