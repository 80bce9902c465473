"""Tests of tdmon.model.temperature (and the [temperature] config adapter).

Reference case: the thesis's Tables 10-12 (US units), converted to SI with tdmon.units.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pydantic import ValidationError

from tdmon.config.thermal import TemperatureConfig
from tdmon.errors import ModelError
from tdmon.model.temperature import (
    CirculationParameters,
    Geotherm,
    apak_empirical_temperature,
    apak_temperature,
    dimensionless_temperature,
    dittus_boelter,
    geothermal_temperature,
    heat_transfer,
    numerical_temperature,
    temperature_profile,
)
from tdmon.units import parse_quantity, to_unit

FT = 0.3048
H_FT = 9950.0
H = H_FT * FT  # 3032.76 m, the TVD of Example 7.1


def degf(celsius: np.ndarray | float) -> np.ndarray:
    return np.asarray(celsius) * 1.8 + 32.0


# Table 10 of the thesis, in the units printed there
TABLE_10 = {
    "inlet_temperature": "60 degF",
    "flow_rate": "12600 gal/h",
    "circulation_time": "44 h",
    "pipe_inner_radius": "0.266 ft",
    "pipe_outer_radius": "0.276 ft",
    "hole_radius": "0.349 ft",
    "casing_radius": "0.427 ft",
    "fluid_density": "13 lb/gal",
    "fluid_specific_heat": "0.4 BTU/(lb degF)",
    "fluid_conductivity": "1 BTU/(ft h degF)",
    "fluid_viscosity": "46 lb/(ft h)",
    "pipe_conductivity": "1 BTU/(ft h degF)",
    "formation_conductivity": "1.3 BTU/(ft h degF)",
    "formation_specific_heat": "0.2 BTU/(lb degF)",
    "formation_density": "165 lb/ft**3",
}
TABLE_11_U = {
    "pipe_heat_transfer": "42.94 BTU/(h ft**2 degF)",
    "annulus_heat_transfer": "44.61 BTU/(h ft**2 degF)",
}
_SI_UNITS = {
    "inlet_temperature": "degC", "flow_rate": "m**3/s", "circulation_time": "s",
    "pipe_inner_radius": "m", "pipe_outer_radius": "m", "hole_radius": "m",
    "casing_radius": "m", "fluid_density": "kg/m**3", "fluid_specific_heat": "J/(kg*K)",
    "fluid_conductivity": "W/(m*K)", "fluid_viscosity": "Pa*s", "pipe_conductivity": "W/(m*K)",
    "formation_conductivity": "W/(m*K)", "formation_specific_heat": "J/(kg*K)",
    "formation_density": "kg/m**3", "pipe_heat_transfer": "W/(m**2*K)",
    "annulus_heat_transfer": "W/(m**2*K)",
}


def si(table: dict[str, str]) -> dict[str, float]:
    return {key: parse_quantity(value, _SI_UNITS[key]) for key, value in table.items()}


GEOTHERM = Geotherm(to_unit(59.5, "degF", "degC"), parse_quantity("0.0127 degF/ft", "degC/m"))
TABLE_11 = CirculationParameters(**si(TABLE_10 | TABLE_11_U))
FROM_SCRATCH = CirculationParameters(**si(TABLE_10))


def example_7_1_tvd(md: np.ndarray) -> np.ndarray:
    """Example 7.1 (Aadnoy): vertical to 1500 m, build R = 500 m to 60 deg, hold."""
    kop, radius, angle = 1500.0, 500.0, math.radians(60.0)
    end_of_build = kop + radius * angle
    build = kop + radius * np.sin((md - kop) / radius)
    hold = kop + radius * math.sin(angle) + (md - end_of_build) * math.cos(angle)
    return np.where(md <= kop, md, np.where(md <= end_of_build, build, hold))


# --------------------------------------------------------------------------- geotherm

def test_geothermal_hand_value_and_table_12() -> None:
    # hand: 15 + 0.03 * 2000 = 75 degC
    assert geothermal_temperature(2000.0, 15.0, 0.03) == pytest.approx(75.0, abs=1e-12)
    # Table 12: 15 degC at surface, 86 degC at 3033 m; docs/reference-values.md: 15.3 and 85.5
    t = geothermal_temperature([0.0, H], GEOTHERM.surface_temperature, GEOTHERM.gradient)
    assert t == pytest.approx([15.28, 85.48], abs=0.01)


def test_geothermal_arrays_versus_scalars() -> None:
    depths = np.linspace(0.0, 4000.0, 7).reshape(7, 1)
    array = geothermal_temperature(depths, 10.0, 0.025)
    assert array.shape == (7, 1)
    for depth, value in zip(depths.ravel(), array.ravel(), strict=True):
        assert geothermal_temperature(float(depth), 10.0, 0.025) == pytest.approx(value)


def test_geothermal_rejects_negative_depth() -> None:
    with pytest.raises(ModelError, match="negative"):
        geothermal_temperature([-1.0, 10.0], 10.0, 0.02)


# --------------------------------------------------------------------------- building blocks

def test_dimensionless_temperature_hand_values() -> None:
    # Table 11: t_D 14.2 -> T_D 1.81; by hand
    # (0.4063 + 0.5 ln 14.2)(1 + 0.6/14.2) = 1.73292 * 1.04225 = 1.8061
    assert dimensionless_temperature(14.2) == pytest.approx(1.8061, abs=1e-4)
    # short times: 1.1281 sqrt(1)(1 - 0.3) = 0.78967
    assert dimensionless_temperature(1.0) == pytest.approx(0.78967, abs=1e-5)
    with pytest.raises(ModelError):
        dimensionless_temperature(0.0)


def test_dittus_boelter_hand_value() -> None:
    # 0.023 * 10000^0.8 * 10^0.4 * 0.6 / 0.1 = 0.023 * 1584.89 * 2.51189 * 6 = 549.38
    assert dittus_boelter(1e4, 10.0, 0.6, 0.1) == pytest.approx(549.38, rel=1e-4)


def test_heat_transfer_table_11_time_groups() -> None:
    ht = heat_transfer(TABLE_11)
    # Table 11: t_D = 14.2, T_D = 1.81 (alpha = 0.0394 ft^2/h, r_bit = 0.349 ft, 44 h)
    assert ht.dimensionless_time == pytest.approx(14.23, abs=0.01)
    assert ht.dimensionless_temperature == pytest.approx(1.807, abs=0.001)
    # given U values pass through unchanged
    assert ht.pipe / 5.678263 == pytest.approx(42.94, rel=1e-4)
    assert ht.h_pipe is None


def test_heat_transfer_from_scratch() -> None:
    ht = heat_transfer(FROM_SCRATCH)
    assert ht.prandtl is not None and ht.reynolds_pipe is not None
    assert ht.reynolds_annulus is not None and ht.h_annulus is not None
    # docs/reference-values.md: Pr = mu c / k = 46 * 0.4 / 1 = 18.4 (the thesis prints 44)
    assert ht.prandtl == pytest.approx(18.4, rel=1e-6)
    # hand: v = q / (pi r_pi^2) = 0.013249 / 0.020651 = 0.6416 m/s;
    # Re = 1557.7 * 0.6416 * 0.16215 / 0.019015 = 8522
    assert ht.reynolds_pipe == pytest.approx(8522, rel=1e-3)
    assert ht.reynolds_annulus == pytest.approx(3627, rel=1e-3)
    # U in BTU/(h ft^2 F): these are tdmon's numbers, documented in docs/temperature.md
    assert ht.pipe / 5.678263 == pytest.approx(55.84, rel=1e-3)
    assert ht.annulus / 5.678263 == pytest.approx(355.6, rel=1e-3)
    assert ht.annulus == ht.h_annulus  # U_a = h_a


# --------------------------------------------------------------------------- Kabir / Apak

def test_apak_reproduces_table_11() -> None:
    result = apak_temperature([0.0, H], H, GEOTHERM, TABLE_11)
    # Table 11 / docs/reference-values.md §2: annulus 67.8 F at surface, 135.88 F at 9950 ft; the
    # Table 11 inputs are rounded to 4 digits, hence 0.3 F
    assert degf(result.annulus) == pytest.approx([67.8, 135.88], abs=0.3)
    k = result.coefficients
    assert k is not None and k.C1 is not None and k.C2 is not None
    # docs/reference-values.md: A = 0.0011366/ft, B = 6.647e-5/ft, theta1 = 3.099e-4 (from B rounded
    # to 6.64e-5), theta2 = -2.435e-4, C1 = -1.833 F, C2 = 13.51 F; tolerance 0.5 % covers the
    # rounding of the printed inputs
    per_ft = {"A": k.A * FT, "B": k.B * FT, "theta1": k.theta1 * FT, "theta2": k.theta2 * FT}
    assert per_ft["A"] == pytest.approx(0.0011366, rel=1e-3)
    assert per_ft["B"] == pytest.approx(6.647e-5, rel=1e-3)
    assert per_ft["theta1"] == pytest.approx(3.099e-4, rel=5e-3)
    assert per_ft["theta2"] == pytest.approx(-2.435e-4, rel=5e-3)
    c1_f, c2_f = k.C1 * 1.8, k.C2 * 1.8  # [K] -> [F]
    assert c1_f == pytest.approx(-1.833, rel=5e-3)
    assert c2_f == pytest.approx(13.51, rel=5e-3)


def test_apak_boundary_conditions_and_energy_balance() -> None:
    x = np.linspace(0.0, H, 20001)
    result = apak_temperature(x, H, GEOTHERM, TABLE_11)
    k = result.coefficients
    assert k is not None
    assert result.pipe[0] == pytest.approx(TABLE_11.inlet_temperature, abs=1e-10)
    assert result.pipe[-1] == pytest.approx(result.annulus[-1], abs=1e-10)
    # independent check: the profiles satisfy dTp/dx = A (Ta - Tp) and
    # dTa/dx = A (Ta - Tp) - B (Tf - Ta) (finite differences, O(dx^2) ~ 1e-9 K/m)
    dtp = np.gradient(result.pipe, x)[1:-1]
    dta = np.gradient(result.annulus, x)[1:-1]
    exchange = (k.A * (result.annulus - result.pipe))[1:-1]
    assert dtp == pytest.approx(exchange, abs=1e-7)
    assert dta == pytest.approx(exchange - k.B * (result.formation - result.annulus)[1:-1],
                                abs=1e-7)


def test_apak_arrays_versus_scalars() -> None:
    x = np.array([0.0, 500.0, 1500.0, H])
    whole = apak_temperature(x, H, GEOTHERM, TABLE_11)
    for i, depth in enumerate(x):
        single = apak_temperature(depth, H, GEOTHERM, TABLE_11)
        assert float(single.annulus) == pytest.approx(whole.annulus[i], abs=1e-12)
        assert float(single.pipe) == pytest.approx(whole.pipe[i], abs=1e-12)


def test_apak_no_overflow_for_large_theta_h() -> None:
    # 0.5 l/s through a 30 km well: theta1 H ~ 800, e^(theta1 H) overflows a float
    slow = CirculationParameters(**(si(TABLE_10 | TABLE_11_U) | {"flow_rate": 0.0005}))
    depth = 30000.0
    result = apak_temperature(np.linspace(0.0, depth, 301), depth, GEOTHERM, slow)
    k = result.coefficients
    assert k is not None and k.theta1 * depth > 710.0
    with pytest.raises(OverflowError):
        math.exp(k.theta1 * depth)  # what the unscaled C1, C2 formulas would need
    assert np.all(np.isfinite(result.pipe)) and np.all(np.isfinite(result.annulus))
    assert result.pipe[0] == pytest.approx(slow.inlet_temperature, abs=1e-9)
    # far from both ends the exponentials have died out and the particular solution remains:
    # T_a = T_f and T_p = T_f - G/A (hand: eq. 52-53 without the C terms)
    middle = 150
    assert result.annulus[middle] == pytest.approx(result.formation[middle], abs=1e-9)
    assert result.pipe[middle] == pytest.approx(result.formation[middle] - GEOTHERM.gradient / k.A,
                                                abs=1e-9)
    assert result.pipe[-1] == pytest.approx(result.annulus[-1], abs=1e-9)


def test_measured_inlet_temperature_replaces_configured_one() -> None:
    result = apak_temperature([0.0, H], H, GEOTHERM, TABLE_11, inlet_temperature=25.0)
    assert result.pipe[0] == pytest.approx(25.0)
    assert result.inlet_temperature == 25.0
    base = apak_temperature([0.0, H], H, GEOTHERM, TABLE_11)
    assert result.annulus[-1] > base.annulus[-1]  # warmer mud in, warmer mud out


def test_apak_from_scratch_u_values() -> None:
    result = apak_temperature([0.0, H], H, GEOTHERM, FROM_SCRATCH)
    # documented in docs/temperature.md: 66.4 F at surface, 142.5 F at TD
    assert degf(result.annulus) == pytest.approx([66.38, 142.53], abs=0.05)


# --------------------------------------------------------------------------- numerical along MD

@pytest.mark.parametrize("circulation", [TABLE_11, FROM_SCRATCH], ids=["table-11", "scratch"])
def test_numerical_equals_analytic_on_vertical_well(circulation: CirculationParameters) -> None:
    md = np.linspace(0.0, H, 97)
    analytic = apak_temperature(md, H, GEOTHERM, circulation)
    numeric = numerical_temperature(md, [0.0, H], [0.0, H], GEOTHERM, circulation)
    # independent solution (scipy solve_bvp, tol 1e-8): the requirement is 0.1 degC
    assert numeric.annulus == pytest.approx(analytic.annulus, abs=0.1)
    assert numeric.pipe == pytest.approx(analytic.pipe, abs=0.1)
    assert np.max(np.abs(numeric.annulus - analytic.annulus)) < 1e-5


def test_numerical_handles_stiff_wells() -> None:
    # theta1 H ~ 800 (see the overflow test): boundary layers of ~40 m at both ends of 30 km
    slow = CirculationParameters(**(si(TABLE_10 | TABLE_11_U) | {"flow_rate": 0.0005}))
    depth = 30000.0
    x = np.linspace(0.0, depth, 301)
    numeric = numerical_temperature(x, [0.0, depth], [0.0, depth], GEOTHERM, slow)
    analytic = apak_temperature(x, depth, GEOTHERM, slow)
    assert numeric.annulus == pytest.approx(analytic.annulus, abs=1e-3)
    assert numeric.pipe == pytest.approx(analytic.pipe, abs=1e-3)


def test_to_dict_is_json_ready() -> None:
    result = apak_temperature([0.0, H], H, GEOTHERM, FROM_SCRATCH)
    data = result.to_dict()
    text = json.dumps(data, allow_nan=False)
    assert '"annulus_C"' in text and '"md_m"' in text
    coefficients = data["coefficients"]
    assert isinstance(coefficients, dict)
    assert coefficients["Pr"] == pytest.approx(18.4)
    geothermal = temperature_profile("geothermal", [0.0], [0.0, H], [0.0, H], GEOTHERM)
    assert geothermal.to_dict()["coefficients"] is None


def test_numerical_on_deviated_well_differs_from_analytic_in_tvd() -> None:
    survey_md = np.linspace(0.0, 4224.0, 4225)
    survey_tvd = example_7_1_tvd(survey_md)
    assert survey_tvd[-1] == pytest.approx(3033.2, abs=0.1)  # Table 5: 3033 m
    md = np.array([0.0, 1500.0, 4224.0])
    analytic = temperature_profile("apak", md, survey_md, survey_tvd, GEOTHERM, TABLE_11)
    numeric = temperature_profile("numerical", md, survey_md, survey_tvd, GEOTHERM, TABLE_11)
    # the thesis's way (x = TVD) gives its 57.7 degC at TD
    assert analytic.annulus[-1] == pytest.approx(57.7, abs=0.05)
    # along MD the mud flows 4224 m through the formation, 1191 m more than the TVD, most of
    # it in the deep, hot hold section: it arrives warmer (docs/temperature.md)
    assert numeric.annulus[-1] == pytest.approx(69.3, abs=0.1)
    assert numeric.annulus[0] == pytest.approx(analytic.annulus[0], abs=0.1)
    assert numeric.tvd == pytest.approx(analytic.tvd)
    assert numeric.formation[-1] == pytest.approx(analytic.formation[-1])


def test_numerical_arrays_versus_scalars() -> None:
    md = np.array([0.0, 700.0, H])
    whole = numerical_temperature(md, [0.0, H], [0.0, H], GEOTHERM, TABLE_11)
    single = numerical_temperature(700.0, [0.0, H], [0.0, H], GEOTHERM, TABLE_11)
    assert float(single.annulus) == pytest.approx(whole.annulus[1], abs=1e-9)


def test_numerical_total_md_above_survey_end() -> None:
    md = np.linspace(0.0, 2000.0, 5)
    numeric = numerical_temperature(md, [0.0, H], [0.0, H], GEOTHERM, TABLE_11, total_md=2000.0)
    analytic = apak_temperature(md, 2000.0, GEOTHERM, TABLE_11)
    assert numeric.annulus == pytest.approx(analytic.annulus, abs=1e-4)


# --------------------------------------------------------------------------- empirical

def test_apak_empirical_hand_value() -> None:
    result = apak_empirical_temperature(
        [0.0, H], GEOTHERM, inlet_temperature=TABLE_11.inlet_temperature,
        flow_rate=TABLE_11.flow_rate, circulation_time=TABLE_11.circulation_time)
    # by hand, field units, q = 12600 gal/h = 210 gal/min (tdmon's assumption):
    # Tp(H) = 60 - 0.3207*44 + 0.0465*9950 + 1193.65*0.0127 - 0.0166*210 - 1.0401*59.5
    tp = 60 - 0.3207 * 44 + 0.0465 * 9950 + 1193.65 * 0.0127 - 0.0166 * 210 - 1.0401 * 59.5
    ta = tp - 0.00945 * 44 + 0.000006 * 9950 + 47.869 * 0.0127 - 0.00387 * 210 - 0.05112 * 59.5
    tmax = (0.7238 * 44**-0.0488 * 9950**0.8153 * 0.0127**0.7279 * 210**-0.0879
            * 60**0.0857 * 59.5**0.3622)
    assert degf(result.pipe[-1]) == pytest.approx(tp, abs=1e-6)
    assert degf(result.annulus[-1]) == pytest.approx(ta, abs=1e-6)
    assert result.maximum_temperature is not None
    assert degf(result.maximum_temperature) == pytest.approx(tmax, abs=1e-6)
    assert tmax == pytest.approx(177.7, abs=0.1)
    # the correlation is not a profile: it does not return the inlet temperature at surface
    assert abs(float(degf(result.pipe[0])) - 60.0) > 50.0


def test_apak_empirical_arrays_versus_scalars() -> None:
    kwargs = {"inlet_temperature": 20.0, "flow_rate": 0.02, "circulation_time": 36000.0}
    whole = apak_empirical_temperature([100.0, 2000.0], GEOTHERM, **kwargs)
    single = apak_empirical_temperature(2000.0, GEOTHERM, **kwargs)
    assert float(single.annulus) == pytest.approx(whole.annulus[1])


# --------------------------------------------------------------------------- composer

def test_profile_geothermal_needs_no_circulation() -> None:
    result = temperature_profile("geothermal", [0.0, 1000.0], [0.0, 2000.0], [0.0, 1000.0],
                                 Geotherm(10.0, 0.03))
    assert result.annulus == pytest.approx([10.0, 25.0])  # TVD 500 m at MD 1000 m
    assert result.pipe == pytest.approx(result.formation)
    assert result.coefficients is None


def test_profile_unknown_model_and_missing_circulation() -> None:
    with pytest.raises(ModelError, match="unknown temperature model"):
        temperature_profile("holmes", [0.0], [0.0, H], [0.0, H], GEOTHERM, TABLE_11)
    with pytest.raises(ModelError, match="needs the circulation inputs"):
        temperature_profile("apak", [0.0], [0.0, H], [0.0, H], GEOTHERM)


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"flow_rate": -0.01}, "flow_rate must be positive"),
        ({"flow_rate": 0.0}, "flow_rate must be positive"),
        ({"circulation_time": 0.0}, "circulation_time must be positive"),
        ({"circulation_time": -5.0}, "circulation_time must be positive"),
        ({"hole_radius": 0.0}, "hole_radius must be positive"),
        ({"pipe_outer_radius": -0.1}, "pipe_outer_radius must be positive"),
        ({"pipe_inner_radius": 0.09}, "must be smaller than pipe_outer_radius"),
        ({"hole_radius": 0.08}, "no annulus"),
        ({"formation_density": float("nan")}, "formation_density must be positive"),
        ({"inlet_temperature": float("inf")}, "inlet_temperature must be a finite"),
    ],
)
def test_bad_inputs_raise_model_error(change: dict[str, float], message: str) -> None:
    with pytest.raises(ModelError, match=message):
        CirculationParameters(**(si(TABLE_10) | change))


def test_missing_input_names_the_input() -> None:
    bare = CirculationParameters(inlet_temperature=20.0, flow_rate=0.02, circulation_time=3600.0)
    with pytest.raises(ModelError, match="'formation_conductivity'"):
        apak_temperature([0.0], 1000.0, GEOTHERM, bare)


def test_depth_below_bit_and_zero_depth_are_errors() -> None:
    with pytest.raises(ModelError, match="below total_depth"):
        apak_temperature([0.0, H + 10.0], H, GEOTHERM, TABLE_11)
    with pytest.raises(ModelError, match="total_depth must be positive"):
        apak_temperature([0.0], 0.0, GEOTHERM, TABLE_11)
    with pytest.raises(ModelError, match="non-finite"):
        apak_temperature([0.0, float("nan")], H, GEOTHERM, TABLE_11)


def test_numerical_bad_surveys() -> None:
    with pytest.raises(ModelError, match="start at MD 0"):
        numerical_temperature([100.0], [10.0, H], [10.0, H], GEOTHERM, TABLE_11)
    with pytest.raises(ModelError, match="increase strictly"):
        numerical_temperature([100.0], [0.0, 50.0, 50.0], [0.0, 50.0, 50.0], GEOTHERM, TABLE_11)
    with pytest.raises(ModelError, match="below the last survey station"):
        numerical_temperature([100.0], [0.0, H], [0.0, H], GEOTHERM, TABLE_11, total_md=H + 1)


def test_empirical_bad_inputs() -> None:
    with pytest.raises(ModelError, match="flow_rate must be positive"):
        apak_empirical_temperature([0.0], GEOTHERM, inlet_temperature=20.0, flow_rate=-1.0,
                                   circulation_time=3600.0)
    with pytest.raises(ModelError, match="circulation_time must be positive"):
        apak_empirical_temperature([0.0], GEOTHERM, inlet_temperature=20.0, flow_rate=0.02,
                                   circulation_time=0.0)


# --------------------------------------------------------------------------- config adapter

def _table_11_config(**changes: object) -> TemperatureConfig:
    data: dict[str, object] = {"model": "apak", "surface_temperature": "59.5 degF",
                               "geothermal_gradient": "0.0127 degF/ft"}
    data |= TABLE_10 | TABLE_11_U
    data |= changes
    return TemperatureConfig.model_validate(data)


def test_config_units_and_profile() -> None:
    config = _table_11_config()
    assert config.circulation() == TABLE_11
    assert config.geotherm() == GEOTHERM
    result = config.profile([0.0, H], [0.0, H], [0.0, H])
    assert degf(result.annulus) == pytest.approx([67.8, 135.88], abs=0.3)
    measured = config.profile([0.0, H], [0.0, H], [0.0, H], inlet_temperature=30.0)
    assert measured.pipe[0] == pytest.approx(30.0)


def test_config_defaults_casing_radius_to_hole_radius() -> None:
    data = {k: v for k, v in TABLE_10.items() if k != "casing_radius"}
    config = TemperatureConfig.model_validate(
        {"model": "numerical", "surface_temperature": 15, "geothermal_gradient": 0.025} | data)
    circulation = config.circulation()
    assert circulation is not None and circulation.casing_radius == circulation.hole_radius


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"flow_rate": "-210 gal/min"}, "must be positive"),
        ({"circulation_time": 0}, "must be positive"),
        ({"flow_rate": "210 furlongs"}, "cannot be converted"),
        ({"hole_radius": "0.3 kg"}, "cannot be converted"),
        ({"pipe_inner_radius": "0.3 ft"}, "smaller than pipe_outer_radius"),
        ({"colour": "red"}, "Extra inputs"),
        ({"model": "holmes"}, "Input should be"),
        ({"inlet_temperature": None}, "needs inlet_temperature"),
    ],
)
def test_config_errors_are_value_errors_with_reason(changes: dict[str, object],
                                                    message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        _table_11_config(**changes)


def test_config_geothermal_needs_only_the_geotherm() -> None:
    config = TemperatureConfig.model_validate(
        {"surface_temperature": "4 degC", "geothermal_gradient": "30 degC/km"})
    assert config.model == "geothermal"
    assert config.circulation() is None
    assert config.geothermal_gradient == pytest.approx(0.03)
    result = config.profile([1000.0], [0.0, 2000.0], [0.0, 2000.0])
    assert result.annulus == pytest.approx([34.0])
