"""Tests of tdmon.model.friction (and the friction-model config adapter)."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from tdmon.config.thermal import FrictionModelConfig
from tdmon.errors import ModelError
from tdmon.model.friction import (
    FAMILIES,
    KAARSTAD_2009,
    PUBLISHED_FRICTION_MODELS,
    THESIS_GLYDRIL_FIT,
    TYPICAL_FRICTION_RANGES,
    FrictionModel,
    constant,
    evaluate_law,
    exponential,
    linear,
    local_friction,
    polynomial,
    power,
    saturation_growth,
)
from tdmon.model.temperature import (
    CirculationParameters,
    Geotherm,
    apak_temperature,
    geothermal_temperature,
)
from tdmon.units import parse_quantity, to_unit

# --------------------------------------------------------------------------- families, by hand


def test_family_hand_values() -> None:
    assert linear(50.0, 0.23, 0.0013) == pytest.approx(0.295)          # 0.23 + 0.065
    assert power(16.0, 0.1, 0.5) == pytest.approx(0.4)                  # 0.1 * 4
    assert exponential(10.0, 0.2, np.log(2) / 10) == pytest.approx(0.4)  # doubles in 10 K
    assert saturation_growth(30.0, 0.4, 10.0) == pytest.approx(0.3)     # 0.4 * 30 / 40
    assert polynomial(10.0, a0=0.2, a1=0.01, a2=-0.0001) == pytest.approx(0.29)  # .2+.1-.01
    assert polynomial(10.0, a0=0.2, a2=0.001) == pytest.approx(0.3)     # missing a1 is zero
    assert constant(80.0, 0.21) == pytest.approx(0.21)


@pytest.mark.parametrize(
    ("family", "coefficients"),
    [
        ("linear", {"a": 0.23, "b": 0.0013}),
        ("power", {"a": 0.17, "b": 0.14}),
        ("exponential", {"a": 0.25, "b": 0.003}),
        ("saturation-growth", {"a": 0.34, "b": 7.0}),
        ("polynomial", {"a0": 0.25, "a1": 0.001, "a2": -1e-6}),
        ("constant", {"mu": 0.3}),
    ],
)
def test_arrays_versus_scalars(family: str, coefficients: dict[str, float]) -> None:
    temperature = np.array([[10.0, 35.0], [60.0, 90.0]])
    function = FAMILIES[family]
    array = function(temperature, **coefficients)
    assert array.shape == (2, 2)
    for t, mu in zip(temperature.ravel(), array.ravel(), strict=True):
        assert function(float(t), **coefficients) == pytest.approx(mu)
    model = FrictionModel(family, coefficients)
    assert model(temperature) == pytest.approx(array)


def test_undefined_values_raise_instead_of_nan() -> None:
    with pytest.raises(ModelError, match="above 0 degC"):
        power([10.0, 0.0], 0.2, 0.1)
    with pytest.raises(ModelError, match=r"not defined at -7\.0 degC"):
        saturation_growth([20.0, -7.0], 0.3, 7.0)
    with pytest.raises(ModelError, match="not defined"):
        exponential(1000.0, 0.2, 1.0)  # overflows to inf
    with pytest.raises(ModelError, match="non-finite"):
        linear([20.0, float("nan")], 0.2, 0.001)


# --------------------------------------------------------------------------- FrictionModel

def test_friction_model_validation() -> None:
    with pytest.raises(ModelError, match="unknown friction family"):
        FrictionModel("cubic-spline", {})
    with pytest.raises(ModelError, match="takes coefficients a, b"):
        FrictionModel("linear", {"a": 0.2})
    with pytest.raises(ModelError, match="takes coefficients a, b"):
        FrictionModel("linear", {"a": 0.2, "b": 0.001, "c": 1.0})
    with pytest.raises(ModelError, match="a0, a1"):
        FrictionModel("polynomial", {"x2": 1.0})
    with pytest.raises(ModelError, match="must be finite"):
        FrictionModel("linear", {"a": float("inf"), "b": 0.0})


def test_friction_model_is_frozen_and_describes_itself() -> None:
    source = {"a": 0.23, "b": 0.0013}
    model = FrictionModel("linear", source)
    source["a"] = 99.0  # the model keeps its own copy
    assert model(0.0) == pytest.approx(0.23)
    with pytest.raises(TypeError):
        model.coefficients["a"] = 1.0  # type: ignore[index]
    assert model.describe() == "mu = 0.23 + 0.0013 T"
    assert FrictionModel.constant(0.2).describe() == "mu = 0.2"
    assert FrictionModel.constant(0.2)([1.0, 2.0]) == pytest.approx([0.2, 0.2])


# --------------------------------------------------------------------------- published constants

def test_kaarstad_constants_eq_12_to_16() -> None:
    expected = {  # eq. 12-16 of the thesis, mu at 0 degC and slope per K
        "water": (0.42, 0.0021),
        "oil-based-1.53sg": (0.12, 0.0001),
        "oil-based-1.58sg": (0.14, 0.00005),
        "glydril": (0.23, 0.0013),
        "aphrons": (0.42, 0.00227),
    }
    assert set(KAARSTAD_2009) == set(expected)
    for name, (a, b) in expected.items():
        model = KAARSTAD_2009[name]
        assert model.family == "linear"
        assert model(100.0) == pytest.approx(a + 100.0 * b)
        assert PUBLISHED_FRICTION_MODELS[f"kaarstad-{name}"] is model
    assert THESIS_GLYDRIL_FIT(40.0) == pytest.approx(0.25231 + 0.034)  # eq. 21
    assert PUBLISHED_FRICTION_MODELS["thesis-glydril"] is THESIS_GLYDRIL_FIT


def test_typical_ranges_table_24() -> None:
    assert TYPICAL_FRICTION_RANGES["water-based"]["cased"] == (0.25, 0.35)
    assert TYPICAL_FRICTION_RANGES["water-based"]["open"] == (0.25, 0.40)
    assert TYPICAL_FRICTION_RANGES["oil-based"]["cased"] == (0.16, 0.20)
    assert TYPICAL_FRICTION_RANGES["oil-based"]["open"] == (0.17, 0.25)
    assert len(TYPICAL_FRICTION_RANGES) == 7
    for ranges in TYPICAL_FRICTION_RANGES.values():
        for low, high in ranges.values():
            assert 0.0 < low < high < 1.0


# --------------------------------------------------------------------------- Table 12

def _table_10_circulation() -> tuple[Geotherm, CirculationParameters, float]:
    q = parse_quantity
    geotherm = Geotherm(to_unit(59.5, "degF", "degC"), q("0.0127 degF/ft", "degC/m"))
    circulation = CirculationParameters(
        inlet_temperature=to_unit(60.0, "degF", "degC"),
        flow_rate=q("12600 gal/h", "m**3/s"),
        circulation_time=q("44 h", "s"),
        pipe_outer_radius=q("0.276 ft", "m"),
        hole_radius=q("0.349 ft", "m"),
        casing_radius=q("0.427 ft", "m"),
        fluid_density=q("13 lb/gal", "kg/m**3"),
        fluid_specific_heat=q("0.4 BTU/(lb degF)", "J/(kg*K)"),
        formation_conductivity=q("1.3 BTU/(ft h degF)", "W/(m*K)"),
        formation_specific_heat=q("0.2 BTU/(lb degF)", "J/(kg*K)"),
        formation_density=q("165 lb/ft**3", "kg/m**3"),
        pipe_heat_transfer=q("42.94 BTU/(h ft**2 degF)", "W/(m**2*K)"),
        annulus_heat_transfer=q("44.61 BTU/(h ft**2 degF)", "W/(m**2*K)"),
    )
    return geotherm, circulation, q("9950 ft", "m")


def test_table_12_friction_factors() -> None:
    geotherm, circulation, depth = _table_10_circulation()
    glydril = KAARSTAD_2009["glydril"]
    apak = glydril(apak_temperature([0.0, depth], depth, geotherm, circulation).annulus)
    geo = glydril(geothermal_temperature([0.0, depth], geotherm.surface_temperature,
                                         geotherm.gradient))
    # Table 12 prints three decimals: 0.256 -> 0.305 and 0.250 -> 0.341
    assert apak == pytest.approx([0.256, 0.305], abs=0.002)
    assert geo == pytest.approx([0.250, 0.341], abs=0.002)
    # percentage increase surface -> TD: +19.1 % and +36.4 %
    assert 100 * (apak[1] / apak[0] - 1) == pytest.approx(19.1, abs=0.3)
    assert 100 * (geo[1] / geo[0] - 1) == pytest.approx(36.4, abs=0.3)


# --------------------------------------------------------------------------- local friction

def test_local_friction_per_section() -> None:
    cased = KAARSTAD_2009["glydril"]
    temperature = np.array([20.0, 40.0, 60.0, 80.0])
    section = np.array([0, 0, 1, 1])
    mu = local_friction([cased, 0.35], section, temperature)
    assert mu == pytest.approx([0.256, 0.282, 0.35, 0.35])


def test_local_friction_arrays_versus_scalars() -> None:
    models = [KAARSTAD_2009["glydril"], FrictionModel("exponential", {"a": 0.2, "b": 0.01})]
    temperature = np.linspace(15.0, 85.0, 9)
    section = (np.arange(9) >= 4).astype(int)
    whole = local_friction(models, section, temperature)
    for i in range(9):
        assert local_friction(models, section[i:i + 1], temperature[i:i + 1])[0] == \
            pytest.approx(whole[i])


def test_local_friction_bad_input() -> None:
    model = KAARSTAD_2009["glydril"]
    with pytest.raises(ModelError, match="shape"):
        local_friction([model], [0, 0], [20.0])
    with pytest.raises(ModelError, match="only 1 section"):
        local_friction([model], [0, 1], [20.0, 30.0])
    with pytest.raises(ModelError, match="integers"):
        local_friction([model], [0.5], [20.0])


# --------------------------------------------------------------------------- config adapter

class _Section(BaseModel):
    friction: FrictionModelConfig


@pytest.mark.parametrize(
    ("raw", "family", "mu_at_50", "constant_value"),
    [
        (0.25, "constant", 0.25, 0.25),
        ("kaarstad-glydril", "linear", 0.295, None),
        ({"name": "thesis-glydril"}, "linear", 0.29481, None),
        ({"family": "linear", "a": 0.23, "b": 0.0013}, "linear", 0.295, None),
        ({"family": "polynomial", "a0": 0.2, "a2": 4e-5}, "polynomial", 0.3, None),
        ({"family": "constant", "mu": 0.3}, "constant", 0.3, 0.3),
    ],
)
def test_friction_config_forms(raw: object, family: str, mu_at_50: float,
                               constant_value: float | None) -> None:
    config = _Section.model_validate({"friction": raw}).friction
    assert config.family == family
    assert config.friction_model()(50.0) == pytest.approx(mu_at_50)
    assert config.constant_value() == constant_value


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ("kaarstad-bentonite", "unknown published friction model"),
        ({"family": "linear", "a": 0.2, "c": 1.0}, "takes coefficients a, b"),
        ({"family": "linear", "a": "x", "b": 0.1}, "must be a number"),
        ({"a": 0.2, "b": 0.1}, "needs 'family'"),
        ({"name": "kaarstad-glydril", "a": 0.2}, "takes no other keys"),
        (-0.1, "is outside 0-1"),
        (True, "expected a friction factor"),
    ],
)
def test_friction_config_errors(raw: object, message: str) -> None:
    with pytest.raises(ValidationError, match=message):
        _Section.model_validate({"friction": raw})


def _outcome(call: object) -> object:
    """The value's bits, or the error's class and message."""
    try:
        return np.asarray(call()).tobytes()  # type: ignore[operator]
    except Exception as exc:  # the errors themselves are compared
        return type(exc), str(exc)


@pytest.mark.parametrize(("family", "coefficients"), [
    ("constant", {"mu": 0.2}),
    ("linear", {"a": 0.23, "b": 0.0013}),
    ("linear", {"b": 0.0013, "a": 0.23}),
    ("power", {"a": 0.1, "b": 0.3}),
    ("exponential", {"a": 0.2, "b": 0.004}),
    ("exponential", {"a": 0.2, "b": 900.0}),
    ("saturation-growth", {"a": 0.4, "b": 30.0}),
    ("saturation-growth", {"a": 0.4, "b": -50.0}),
    ("polynomial", {"a0": 0.2, "a2": 1e-5}),
    ("polynomial", {"b0": 0.2}),
    ("linear", {"a": float("nan"), "b": 0.0013}),
    ("linear", {"a": 0.23, "b": float("inf")}),
    ("linear", {"a": 0.23}),
    ("linear", {"a": 0.23, "b": 0.001, "c": 0.0}),
    ("linear", {"a": np.float64(0.23), "b": 0.0013}),
    ("linear", {"a": 1, "b": True}),
    ("linear", {"a": "0.5", "b": 0.0013}),
    ("cubic", {"a": 0.23, "b": 0.0013}),
])
@pytest.mark.parametrize("temperature", [
    50.0, [10.0, 50.0, 90.0], np.linspace(-60.0, 120.0, 37), [20.0, float("nan")], -50.0, [],
])
def test_evaluate_law_is_the_model_called(family: str, coefficients: dict[str, float],
                                          temperature: object) -> None:
    # the quick path's bits and errors are the model's, for good and bad laws and temperatures
    expected = _outcome(lambda: FrictionModel(family, coefficients)(temperature))
    assert _outcome(lambda: evaluate_law(family, coefficients, temperature)) == expected
