"""Quantities with units at the edges: oilfield mixed fractions and numbers inside units."""

from __future__ import annotations

import pytest

from tdmon.units import parse_quantity, to_unit

INCH = 0.0254


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
    assert to_unit(60.0, "degF", "degC") == pytest.approx(15.555555555555555)


def test_a_payload_unit_with_a_number_is_refused_not_multiplied() -> None:
    # a payload {"value": 1, "unit": "8 N"} was taken as 8 N (issue 13)
    with pytest.raises(ValueError, match="starts with a number"):
        to_unit(1.0, "8 N", "N")
    assert to_unit(1.0, "kN", "N") == 1000.0
