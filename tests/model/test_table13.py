"""Table 13 of the thesis: hook load and torque with the local Glydril friction factor, Apak
versus geothermal mud temperature (Case 2, Example 7.1 geometry), through the shipped well files
and ``tdmon model loads`` exactly as a user runs them.

Provenance of the expected values: docs/reference-values.md sections 2 and 3
(the thesis's Table 13 for the
relative changes; an element-wise integration with the local mu at each element's TVD for the
absolute values, which Table 13 prints about ten times too small).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

from tdmon.cli import main
from tdmon.config.well import load_well_with_friction
from tdmon.model.well import hole_grid

ROOT = Path(__file__).resolve().parents[2]
APAK = ROOT / "config" / "wells" / "thesis-case2-apak.toml"
GEOTHERMAL = ROOT / "config" / "wells" / "thesis-case2-geothermal.toml"
METHODS = ("aadnoy", "soft-string")

# Table 13, Apak relative to geothermal [%]: pick-up, slack-off, rotating torque
THESIS_CHANGE = {"pick_up": -2.6, "slack_off": 3.5, "torque": -6.1}
# docs/reference-values.md section 3, element-wise [%]
ELEMENT_WISE_CHANGE = {
    "aadnoy": {"pick_up": -2.6, "slack_off": 2.9, "torque": -6.0},
    "soft-string": {"pick_up": -2.6, "slack_off": 2.9, "torque": -6.2},
}
# docs/reference-values.md section 3, element-wise absolute values at TD, bit off bottom, (Apak,
# geothermal): pick-up and slack-off [kN], rotating torque [kN m]
ELEMENT_WISE = {
    "aadnoy": {"pick_up": (1874, 1924), "slack_off": (790, 768), "torque": (43.3, 46.0)},
    "soft-string": {"pick_up": (1819, 1868), "slack_off": (790, 768), "torque": (39.7, 42.4)},
}
# tdmon's "aadnoy" rotating torque: the published build-section formula (Table 22) over the
# whole build arc, which adds mu r 2 w R (1 - cos a) to the element-wise integral (see
# test_aadnoy_torque_differs_by_the_closed_form_build_term)
AADNOY_TORQUE = (46.82, 49.65)

# Tolerances. docs/reference-values.md prints forces to 1 kN and torques to 0.1 kN m, so the
# rounding alone is 0.5 kN and 0.05 kN m. The model's own discretisation adds less than that:
# element lengths from 1 m to 100 m change the Table 13 loads by < 0.3 kN and < 0.01 kN m (measured
# when these tests were written). Hence 1 kN and 0.1 kN m: twice the rounding, no more.
FORCE_TOLERANCE_KN = 1.0
TORQUE_TOLERANCE_KNM = 0.1


def _loads(well: Path, method: str) -> dict[str, float]:
    """``tdmon model loads --well W --method M --json`` in-process: loads in kN and kN m."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        assert main(["model", "loads", "--well", str(well), "--method", method,
                     "--json"]) == 0
    document = json.loads(buffer.getvalue())
    assert document["mu"] is None  # the well file's local friction, not a --mu override
    return {
        "static": document["hookload_N"]["static"] / 1e3,
        "pick_up": document["hookload_N"]["pick_up"] / 1e3,
        "slack_off": document["hookload_N"]["slack_off"] / 1e3,
        "torque": document["torque_Nm"]["rotating"] / 1e3,
    }


@pytest.fixture(scope="module")
def table_13() -> dict[str, dict[str, tuple[float, float]]]:
    """(Apak, geothermal) loads per method, run once per file and method."""
    results: dict[str, dict[str, tuple[float, float]]] = {}
    for method in METHODS:
        apak, geothermal = _loads(APAK, method), _loads(GEOTHERMAL, method)
        results[method] = {key: (apak[key], geothermal[key]) for key in apak}
    return results


def _change(pair: tuple[float, float]) -> float:
    apak, geothermal = pair
    return 100.0 * (apak / geothermal - 1.0)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("quantity", ["pick_up", "slack_off", "torque"])
def test_relative_changes_match_table_13(table_13, method, quantity):
    change = _change(table_13[method][quantity])
    # the thesis's Table 13, within 1 percentage point (the tolerance)
    assert change == pytest.approx(THESIS_CHANGE[quantity], abs=1.0)
    # the element-wise figures of docs/reference-values.md section 3; aadnoy's torque is 0.3 points
    # off because of the closed-form build term (see below), everything else within 0.1 point
    assert change == pytest.approx(ELEMENT_WISE_CHANGE[method][quantity], abs=0.5)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("quantity", ["pick_up", "slack_off"])
def test_absolute_hook_loads(table_13, method, quantity):
    assert table_13[method][quantity] == pytest.approx(ELEMENT_WISE[method][quantity],
                                                       abs=FORCE_TOLERANCE_KN)


def test_absolute_torque_soft_string(table_13):
    assert table_13["soft-string"]["torque"] == pytest.approx(
        ELEMENT_WISE["soft-string"]["torque"], abs=TORQUE_TOLERANCE_KNM)


def test_absolute_torque_aadnoy(table_13):
    assert table_13["aadnoy"]["torque"] == pytest.approx(AADNOY_TORQUE,
                                                         abs=TORQUE_TOLERANCE_KNM)


def test_the_temperature_model_is_the_only_difference(table_13):
    """Same weight (static hook load) in both files: only the friction differs; the cooler
    Apak mud lowers pick-up and torque and raises slack-off."""
    for method in METHODS:
        static_apak, static_geothermal = table_13[method]["static"]
        assert static_apak == pytest.approx(static_geothermal, rel=1e-12)
        assert static_apak == pytest.approx(1179.9, abs=0.1)  # docs/reference-values.md section 1
        pick_up, slack_off, torque = (table_13[method][key]
                                      for key in ("pick_up", "slack_off", "torque"))
        assert pick_up[0] < pick_up[1] and slack_off[0] > slack_off[1] and torque[0] < torque[1]


# ----------------------------------------------------------------- the aadnoy torque, explained

_DRILL_PIPE_WEIGHT = 300.0   # [N/m], buoyed, Example 7.1
_BHA_WEIGHT = 3000.0         # [N/m]
_BHA_LENGTH = 200.0          # [m]
_RADIUS = 0.08               # [m], torque radius of the example
_BUILD_RADIUS = 500.0        # [m]
_BUILD = (1500.0, 1500.0 + 500.0 * math.pi / 3.0)  # MD of kick-off and end of build [m]


def _element_wise_torque(well_file: Path) -> float:
    """Rotating off-bottom torque [kN m] integrated element by element with the thesis-style
    normal force N = |F| d(alpha) + w dL sin(alpha), each element at its own local mu.

    An independent, deliberately plain implementation (planar well, no kernels): it is how
    the reference values' element-wise figures were obtained.
    """
    well, mu = load_well_with_friction(well_file)
    grid = hole_grid(well)
    top_of_bha = well.hole_bottom - _BHA_LENGTH
    force = torque = 0.0
    for j in range(grid.n_elements - 1, -1, -1):
        length = grid.md[j + 1] - grid.md[j]
        bha = max(0.0, grid.md[j + 1] - max(grid.md[j], top_of_bha))
        weight = _BHA_WEIGHT * bha + _DRILL_PIPE_WEIGHT * (length - bha)  # w dL [N]
        inclination = 0.5 * (grid.inclination[j] + grid.inclination[j + 1])
        upper = force + weight * math.cos(inclination)
        turn = abs(grid.inclination[j + 1] - grid.inclination[j])
        normal = 0.5 * (force + upper) * turn + weight * math.sin(inclination)
        torque += mu[j] * _RADIUS * normal
        force = upper
    return torque / 1e3


def _build_term(well_file: Path) -> float:
    """mu_build r 2 w R (1 - cos 60 deg) [kN m], mu_build the build's length-weighted mu."""
    well, mu = load_well_with_friction(well_file)
    grid = hole_grid(well)
    middle = grid.element_mid_md
    inside = (middle > _BUILD[0]) & (middle < _BUILD[1])
    lengths = np.diff(grid.md)[inside]
    mu_build = float(mu[inside] @ lengths / lengths.sum())
    return mu_build * _RADIUS * 2.0 * _DRILL_PIPE_WEIGHT * _BUILD_RADIUS * (
        1.0 - math.cos(math.pi / 3.0)) / 1e3


@pytest.mark.parametrize(("well_file", "index"), [(APAK, 0), (GEOTHERMAL, 1)])
def test_element_wise_torque_reproduces_reference(well_file, index):
    assert _element_wise_torque(well_file) == pytest.approx(
        ELEMENT_WISE["aadnoy"]["torque"][index], abs=TORQUE_TOLERANCE_KNM)


@pytest.mark.parametrize(("well_file", "index"), [(APAK, 0), (GEOTHERMAL, 1)])
def test_aadnoy_torque_differs_by_the_closed_form_build_term(table_13, well_file, index):
    """Aadnoy's build torque T4 = T3 + mu r ((F3 + w R sin a) a + 2 w R (1 - cos a)) exceeds
    the integral of N = F/R + w sin(alpha) over the arc, (F3 + w R sin a) a, by exactly
    mu r 2 w R (1 - cos a): 3.5 kN m here (1.8 kN m at mu 0.15, where docs/reference-values.md
    section 1 lists
    23.45 and 21.64 kN m). The rest of the two calculations agree."""
    gap = table_13["aadnoy"]["torque"][index] - _element_wise_torque(well_file)
    assert gap == pytest.approx(_build_term(well_file), abs=0.02)
