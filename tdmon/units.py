"""Unit handling at the edges: one pint registry, strings with units to SI floats.

Inside tdmon every quantity is SI (N, N m, m, s, Pa, m^3/s, kg/m^3, rad) except temperatures,
which are degC because the friction correlations are written in degC. A configured quantity is
either a plain number, already in the internal unit, or a string such as ``"0.3 kN/m"``,
``"9950 ft"``, ``"13 ppg"`` or ``"60 degF"``.
"""

from __future__ import annotations

import re
from functools import lru_cache

import pint

ureg: pint.UnitRegistry = pint.UnitRegistry()
ureg.define("ppg = pound / gallon")
ureg.define("sg = 1000 * kilogram / meter ** 3")

_ABSOLUTE_TEMPERATURES = {"degC", "degF", "degR", "K", "kelvin", "celsius", "fahrenheit",
                          "degree_Celsius", "degree_Fahrenheit"}
_OFFSET_IN_COMPOUND = re.compile(r"\b(degC|degF|celsius|fahrenheit)\b")


def _split(text: str) -> tuple[float, str]:
    match = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*", text)
    if match is None:
        raise ValueError(f"'{text}' is not a number followed by a unit (e.g. '9950 ft')")
    return float(match.group(1)), match.group(2)


@lru_cache(maxsize=512)
def conversion(unit: str, target: str) -> tuple[float, float]:
    """Return (scale, offset) so that ``value_in_target = value * scale + offset``.

    A temperature unit alone (``degF``) is an absolute temperature; inside a compound unit
    (``BTU/(ft degF h)``, ``degF/ft``) it is a temperature difference.

    Raises
    ------
    ValueError
        The unit is unknown or has the wrong dimension for ``target``.
    """
    if unit not in _ABSOLUTE_TEMPERATURES:
        unit = _OFFSET_IN_COMPOUND.sub(lambda m: "delta_" + m.group(1), unit)
    if target not in _ABSOLUTE_TEMPERATURES:
        target = _OFFSET_IN_COMPOUND.sub(lambda m: "delta_" + m.group(1), target)
    try:
        if unit in _ABSOLUTE_TEMPERATURES:
            zero = ureg.Quantity(0.0, unit).to(target).magnitude
            return ureg.Quantity(1.0, unit).to(target).magnitude - zero, zero
        # an expression may carry a factor, e.g. "deg/(30 m)"
        return float(ureg.parse_expression(unit).to(target).magnitude), 0.0
    except pint.errors.DimensionalityError as exc:
        raise ValueError(f"unit '{unit}' cannot be converted to '{target}'") from exc
    except (pint.errors.UndefinedUnitError, AttributeError) as exc:
        # pint's UndefinedUnitError subclasses AttributeError: translate it here
        raise ValueError(f"unknown unit '{unit}'") from exc
    except Exception as exc:  # pint raises assorted parse errors for garbage strings
        raise ValueError(f"cannot read unit '{unit}': {exc}") from exc


def to_unit(value: float, unit: str, target: str) -> float:
    """Convert ``value`` given in ``unit`` to ``target`` (e.g. ``to_unit(60, "degF", "degC")``)."""
    scale, offset = conversion(unit, target)
    return value * scale + offset


def parse_quantity(value: float | int | str, target: str) -> float:
    """Read a configured quantity: a number already in ``target`` or a string with a unit.

    >>> parse_quantity("9950 ft", "m")
    3032.76
    """
    if isinstance(value, bool):
        raise ValueError("expected a number or a string with a unit, got a boolean")
    if isinstance(value, (int, float)):
        return float(value)
    number, unit = _split(value)
    if not unit:
        return number
    return to_unit(number, unit, target)
