"""Quantities with units at the edges (tdmon/units.py): oilfield mixed fractions, units as
drillers write them, masses where a weight is meant, a bounded grammar for hostile texts, and
every unit tdmon prints read back.

Expected values are written out from the exact definitions (1 ft = 0.3048 m, 1 in = 0.0254 m,
1 lb = 0.45359237 kg, 1 US gal = 3.785411784 L, 1 bbl = 42 US gal, g = 9.80665 m/s2: NIST
SP 811, appendix B), not from tdmon's table; pint, a peer package, checks the table's names.
"""

from __future__ import annotations

import contextlib
import math
import re
from pathlib import Path

import pint
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tdmon import units
from tdmon.channels import CHANNEL_UNITS
from tdmon.config.common import _EXAMPLE_UNITS, unit_example
from tdmon.display import QUANTITIES, unit_system
from tdmon.units import UnitError, conversion, examples, parse_quantity, parse_unit, to_unit

ROOT = Path(__file__).resolve().parents[1]
INCH, FOOT, POUND, GALLON, G = 0.0254, 0.3048, 0.45359237, 3.785411784e-3, 9.80665
BARREL = 42 * GALLON


@pytest.mark.parametrize(
    ("text", "inches"),
    [("12 1/4 in", 12.25), ("5-1/2 in", 5.5), ("3/4 in", 0.75), ("8 1/2in", 8.5),
     ("-1 1/2 in", -1.5), ("12.25 in", 12.25), (".5 in", 0.5)],
)
def test_oilfield_sizes_read_as_mixed_fractions(text: str, inches: float) -> None:
    # "12 1/4 in" was read as 12 x (1/4 in) = 3 in before (issue 13)
    assert parse_quantity(text, "m") == pytest.approx(inches * INCH, rel=1e-12)


@pytest.mark.parametrize("text", ["12 1 in", "8 2.5 N", "1/0 in", "12 + 1/4 in", "5 - 1/2 in",
                                  "5 -1/2 in", "12.5 1/4 in", "0.5 1/2 m"])
def test_a_second_number_in_the_unit_is_refused(text: str) -> None:
    with pytest.raises(ValueError, match=r"unit|denominator"):
        parse_quantity(text, "m")


def test_reciprocal_and_factored_units_still_read() -> None:
    assert parse_quantity("120 1/min", "1/s") == pytest.approx(2.0)
    # a dogleg severity written per 30 m: 3 deg/30 m = 0.1 deg/m
    assert parse_quantity("3 deg/(30 m)", "deg/m") == pytest.approx(0.1)
    assert parse_quantity("3 deg/30m", "deg/m") == pytest.approx(0.1)  # number against name
    assert parse_quantity("2.5 degC/100m", "K/m") == pytest.approx(0.025)
    assert to_unit(60.0, "degF", "degC") == pytest.approx(15.555555555555555, rel=1e-15)


def test_a_payload_unit_with_a_number_is_refused_not_multiplied() -> None:
    # a payload {"value": 1, "unit": "8 N"} was taken as 8 N (issue 13)
    with pytest.raises(ValueError, match="starts with a number"):
        to_unit(1.0, "8 N", "N")
    assert to_unit(1.0, "kN", "N") == 1000.0


# -- units as drillers write them (issue 31) ---------------------------------------------------

@pytest.mark.parametrize(("text", "target", "expected"), [
    ("1030 kg/m3", "kg/m**3", 1030.0),
    ("1030 kg/m^3", "kg/m**3", 1030.0),
    ("10 m3", "m**3", 10.0),
    ("1.5 SG", "kg/m**3", 1500.0),
    ("1.5 sg", "kg/m**3", 1500.0),
    ("12.5 ppg", "kg/m**3", 12.5 * POUND / GALLON),
    ("1.2 g/cm3", "kg/m**3", 1200.0),
    ("40 t", "N", 40e3 * G),
    ("40 tonne", "N", 40e3 * G),
    ("500 klb", "N", 500e3 * POUND * G),
    ("500 klbf", "N", 500e3 * POUND * G),
    ("25 kkgf", "N", 25e3 * G),
    ("30 daN", "N", 300.0),
    ("3 kdaN", "N", 30e3),
    ("19.5 lb/ft", "N/m", 19.5 * POUND / FOOT * G),
    ("43 kg/m", "N/m", 43 * G),
    ("0.3 kN/m", "N/m", 300.0),
    ("20 kft.lbf", "N*m", 20e3 * FOOT * POUND * G),
    ("20 kft-lbf", "N*m", 20e3 * FOOT * POUND * G),
    ("20 ft-lbf", "N*m", 20 * FOOT * POUND * G),
    ("20 lbf*ft", "N*m", 20 * FOOT * POUND * G),
    ("14 kN.m", "N*m", 14e3),
    ("14 kNm", "N*m", 14e3),
    ("5 bbl", "m**3", 5 * BARREL),
    ("10 bpm", "m**3/s", 10 * BARREL / 60),
    ("300 gpm", "m**3/s", 300 * GALLON / 60),
    ("2000 L/min", "m**3/s", 2000e-3 / 60),
    ("212 degF", "degC", 100.0),
    ("300 K", "degC", 300 - 273.15),
    ("120 rpm", "rad/s", 4 * math.pi),
    ("3000 psi", "Pa", 3000 * POUND * G / INCH**2),
    ("9950 ft", "m", 9950 * FOOT),
    ("1.5 degF/100ft", "K/m", 1.5 * 5 / 9 / (100 * FOOT)),
    ("60 ft/h", "m/s", 60 * FOOT / 3600),
])
def test_drillers_spellings(text: str, target: str, expected: float) -> None:
    assert parse_quantity(text, target) == pytest.approx(expected, rel=1e-13)


def test_a_stroke_rate_is_read_but_is_no_flow() -> None:
    # spm counts pump strokes: without the pump's displacement it is no flow rate
    assert parse_unit("spm").dimension == units.STROKE_RATE
    with pytest.raises(UnitError, match=re.escape("a pump stroke rate, not a flow rate; e.g. 'L")):
        conversion("spm", "m**3/s")


# -- masses only where a weight is meant -------------------------------------------------------

MASSES = ("kg", "t", "tonne", "lb", "klb", "lbm", "g")
LENGTHS = ("m", "ft", "in", "km")
TARGETS = ("N", "N/m", "N*m", "Pa", "m", "kg/m**3", "m**3/s", "rad/s", "degC", "s", "m/s",
           "dimensionless")


@settings(max_examples=300, deadline=None)
@given(mass=st.sampled_from(MASSES), per=st.sampled_from((None, *LENGTHS)),
       target=st.sampled_from(TARGETS), value=st.floats(0.001, 1e6))
def test_mass_is_read_only_where_a_weight_is_meant(mass: str, per: str | None, target: str,
                                                   value: float) -> None:
    unit = mass if per is None else f"{mass}/{per}"
    weight_target = "N" if per is None else "N/m"
    if target != weight_target:
        with pytest.raises(UnitError, match="cannot be converted"):
            conversion(unit, target)
        return
    kilograms = to_unit(value, mass, "kg") / (1.0 if per is None else to_unit(1.0, per, "m"))
    assert to_unit(value, unit, target) == pytest.approx(kilograms * G, rel=1e-12)


def test_a_refused_mass_says_where_masses_are_read() -> None:
    with pytest.raises(UnitError) as caught:
        conversion("t", "N*m")
    assert str(caught.value) == (
        "unit 't' cannot be converted to 'N*m': a mass, not a torque (a mass is read as its "
        "weight only where a force or a weight per length is meant); e.g. 'kN*m', 'kft.lbf' "
        "or 'ft-lbf'")


# -- a bounded grammar --------------------------------------------------------------------------

@pytest.mark.parametrize(("unit", "reason"), [
    ("m*9**9**9", "a number (9) cannot be raised to a power"),
    ("9**9", "starts with a number"),
    ("kN*10**3", "a number (10) cannot be raised to a power"),
    ("m**9", "the power 9 is outside -4..4"),
    ("m^-99999999999", "outside -4..4"),
    ("m**2**2", "a power of a power"),
    ("m3**2", "two powers on 'm'"),
    ("m**0.5", "not a whole number"),
    ("((((m))))", "more than 3 parentheses"),
    ("*".join(["m"] * 13), "more than 24 parts"),
    ("m" * 65, "longer than 64 characters"),
    ("kN/(m", "a '(' is not closed"),
    ("kN)", "a ')' without its '('"),
    ("W/m K", "after a '/' is ambiguous"),
    ("deg/30 m", "after a '/' is ambiguous"),
    ("m;import os", "cannot read unit"),
    ("__import__", "unknown unit '__import__'"),
    ("m*0", "a factor of 0"),
    ("m*1e308", "cannot read unit"),
])
def test_hostile_units_are_refused_with_the_reason(unit: str, reason: str) -> None:
    with pytest.raises(UnitError, match=re.escape(reason)):
        conversion(unit, "m")


def test_pint_only_ever_sees_one_validated_name(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[str] = []
    looked_up = units._pint_name

    def recording(text: str) -> units._Name | None:
        seen.append(text)
        return looked_up(text)

    def never(*args: object, **kwargs: object) -> None:
        raise AssertionError("pint evaluated an expression")

    for memo in (units._conversion_or_reason, units.parse_unit, units._name):
        memo.cache_clear()
    monkeypatch.setattr(units, "_pint_name", recording)
    monkeypatch.setattr(pint.UnitRegistry, "parse_expression", never)
    for text in ("m*9**9**9", "furlong*parsec/fortnight", "__class__", "kN*(furlong)",
                 "a.b.c", "mile-1", "m/(s*minute)"):
        with contextlib.suppress(UnitError):
            conversion(text, "m")
    assert seen and all(re.fullmatch(r"[A-Za-zµ_]+", name) for name in seen), seen
    for memo in (units._conversion_or_reason, units.parse_unit, units._name):
        memo.cache_clear()


@settings(max_examples=500, deadline=None)
@given(st.text(alphabet="m9kNft*/^()-. 2lbs3%°µ_e+", max_size=80))
def test_any_text_is_a_unit_or_a_unit_error(text: str) -> None:
    try:
        scale, offset = conversion(text, "m", pint_names=False)
    except UnitError as exc:
        assert exc.reason and str(exc).startswith(exc.reason)
    else:
        assert math.isfinite(scale) and scale > 0 and offset == 0.0


def test_payload_units_never_ask_pint() -> None:
    with pytest.raises(UnitError, match="not one of the names tdmon reads in payloads"):
        conversion("furlong", "m", pint_names=False)
    assert conversion("kft", "m", pint_names=False) == pytest.approx((1000 * FOOT, 0.0))


# -- the table of names against pint -----------------------------------------------------------

# tdmon's names that pint lacks or means otherwise, and what they are in pint's words
OWN_NAMES = {
    "bbl": "oil_barrel",  # pint's bbl is the 31.5-gallon barrel
    "sg": "1000 kg/m**3", "SG": "1000 kg/m**3", "ppg": "pound/gallon",
    "gpm": "gallon/minute", "bpm": "oil_barrel/minute", "lpm": "L/min", "Lpm": "L/min",
    "Nm": "N*m", "kNm": "kN*m", "kdaN": "10 kN", "lbs": "lb", "lbm": "lb", "galUS": "gallon",
    "rev": "revolution", "delta_degC": "delta_degC", "delta_degF": "delta_degF",
}
NO_PINT = {"stroke", "spm"}
PREFIXED = ("kN", "MN", "daN", "kPa", "MPa", "GPa", "mm", "cm", "km", "kg", "mg", "ms", "mL",
            "kft", "klb", "klbf", "kkgf", "kJ", "kW", "mbar", "kgal", "kbbl")


@pytest.fixture(scope="module")
def ureg() -> pint.UnitRegistry:
    return pint.UnitRegistry()


@pytest.mark.parametrize("name", sorted(set(units.UNIT_NAMES) - NO_PINT) + list(PREFIXED))
def test_each_name_is_what_pint_says(ureg: pint.UnitRegistry, name: str) -> None:
    text = OWN_NAMES.get(name, name)
    if name.startswith("k") and name[1:] in OWN_NAMES:  # kbbl: a thousand oil barrels
        text = f"1000 * {OWN_NAMES[name[1:]]}"
    reference = ureg.parse_expression(text).to_base_units()
    ours = parse_unit(name)
    assert ours.scale == pytest.approx(float(reference.magnitude), rel=1e-12)
    assert dict(ours.dimension) == {k: float(v) for k, v in reference.dimensionality.items()}


# -- every unit tdmon prints is one it reads ---------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(system=st.sampled_from(["si", "field"]), quantity=st.sampled_from(sorted(QUANTITIES)),
       value=st.floats(-1e7, 1e7, allow_nan=False))
def test_every_printed_display_unit_reads_back(system: str, quantity: str,
                                               value: float) -> None:
    shown = unit_system(system)
    text = f"{shown.convert(quantity, value)!r} {shown.label(quantity)}"  # type: ignore[arg-type]
    back = parse_quantity(text, QUANTITIES[quantity])
    assert back == pytest.approx(value, rel=1e-12, abs=1e-9)


@settings(max_examples=200, deadline=None)
@given(channel=st.sampled_from(sorted(CHANNEL_UNITS)), value=st.floats(-1e9, 1e9))
def test_every_printed_channel_unit_reads_back(channel: str, value: float) -> None:
    internal, printed = CHANNEL_UNITS[channel]
    assert parse_quantity(f"{value!r} {printed}", internal) == value


@pytest.mark.parametrize("target", sorted({*_EXAMPLE_UNITS, "N/m", "kg/m", "m/s", "K/m"}))
def test_every_suggested_unit_reads(target: str) -> None:
    for unit in (unit_example(target), *examples(target)):
        scale, _ = conversion(unit, target)
        assert scale > 0


# -- the table of accepted spellings in docs/configuration.md ------------------------------------

def _documented() -> list[tuple[str, float, str]]:
    """(spelling, value in SI, SI unit) of each row of the units table."""
    text = (ROOT / "docs" / "configuration.md").read_text()
    section = text.split("## Units", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) >= 3 and cells[0].startswith("`"):
            value, si_unit = cells[2].split(" ", 1)
            for spelling in re.findall(r"`([^`]+)`", cells[0]):
                rows.append((spelling, float(value), si_unit.strip("`")))
    return rows


def test_the_documented_spellings_read_as_documented() -> None:
    rows = _documented()
    assert len(rows) > 60
    for spelling, value, si_unit in rows:
        unit = parse_unit(spelling)
        if unit.offset is not None:  # an absolute temperature: its size in degC
            assert unit.scale == pytest.approx(value, rel=1e-9), spelling
            continue
        if spelling in ("spm", "stroke"):
            continue
        assert to_unit(1.0, spelling, si_unit) == pytest.approx(value, rel=1e-5), spelling
