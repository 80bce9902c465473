"""Unit handling at the edges: one pint registry, strings with units to SI floats.

Inside tdmon every quantity is SI (N, N m, m, s, Pa, m^3/s, kg/m^3, rad) except temperatures,
which are degC because the friction correlations are written in degC. A quantity is a string
with its unit, such as ``"0.3 kN/m"``, ``"9950 ft"``, ``"13 ppg"``, ``"60 degF"`` or an oilfield
size such as ``"12 1/4 in"``. :func:`parse_quantity` also takes a plain number as already SI
(command-line flags, Python callers); files refuse a plain number for a dimensional key
(`tdmon.config.common`), since ``block_weight = 655`` meant in kN would be read as 655 N.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import math
import os
import re
import tempfile
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import pint

_EXTRA_UNITS = ("ppg = pound / gallon", "sg = 1000 * kilogram / meter ** 3",
                "gpm = gallon / minute")


def _cache_folder() -> Path:
    import platformdirs

    return platformdirs.user_cache_path("tdmon", appauthor=False)


@lru_cache(maxsize=1)
def registry() -> pint.UnitRegistry:
    """The one pint registry, built on the first conversion `conversion` has not stored.

    Parsing pint's definition files takes about 0.4 s, so the parsed definitions are kept in
    the user's cache folder (``~/.cache/tdmon/pint`` on Linux; pint rebuilds them when its
    files change). A cache folder that cannot be written only costs the parse.
    """
    import pint

    folder = _cache_folder() / "pint"
    ureg: pint.UnitRegistry
    try:
        folder.mkdir(parents=True, exist_ok=True)
        ureg = pint.UnitRegistry(cache_folder=folder)
    except OSError:
        ureg = pint.UnitRegistry()
    for definition in _EXTRA_UNITS:
        ureg.define(definition)
    return ureg


# Conversions pint has computed, kept on disk: a command that reads a well file converts a
# dozen units, and importing pint with its registry costs it 0.1-0.2 s (0.4 s without pint's
# own cache). The file is keyed by the pint installation and tdmon's extra units; a different
# pint, an unreadable or a corrupt file is ignored, and one that cannot be written is not kept.
_STORE_NAME = "conversions.json"


def _store_key() -> str:
    spec = importlib.util.find_spec("pint")
    origin = spec.origin if spec is not None and spec.origin else ""
    try:
        stamp = os.stat(origin).st_mtime_ns if origin else 0
    except OSError:
        stamp = 0
    return f"{origin}:{stamp}:{';'.join(_EXTRA_UNITS)}"


@lru_cache(maxsize=1)
def _stored_conversions() -> dict[str, list[float]]:
    try:
        document = json.loads((_cache_folder() / _STORE_NAME).read_text())
        if document.get("key") == _store_key():
            return {str(k): [float(v[0]), float(v[1])] for k, v in document["conversions"].items()}
    except (OSError, ValueError, TypeError, KeyError, AttributeError, IndexError):
        pass
    return {}


def _store(key: str, value: tuple[float, float]) -> None:
    stored = _stored_conversions()
    stored[key] = [value[0], value[1]]
    folder = _cache_folder()
    written = None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", dir=folder, suffix=".tmp", delete=False) as file:
            written = file.name
            json.dump({"key": _store_key(), "conversions": stored}, file)
        os.replace(written, folder / _STORE_NAME)  # atomic: readers see the old or the new
    except OSError:
        if written is not None:
            with contextlib.suppress(OSError):
                os.unlink(written)


_ABSOLUTE_TEMPERATURES = {"degC", "degF", "degR", "K", "kelvin", "celsius", "fahrenheit",
                          "degree_Celsius", "degree_Fahrenheit"}
_OFFSET_IN_COMPOUND = re.compile(r"\b(degC|degF|celsius|fahrenheit)\b")


# Oilfield sizes are written as mixed fractions ("12 1/4 in", "5-1/2 in", "3/4 in"). Read as a
# plain number, "12 1/4 in" would be 12 times the unit "1/4 in", i.e. 3 in.
_MIXED_FRACTION = re.compile(
    r"\s*(?P<sign>[-+]?)(?:(?P<whole>\d+)(?:\s+|-))?(?P<num>\d+)/(?P<den>\d+)\s*(?P<unit>.*?)\s*")
# A unit that starts with a number ("8 N"), an operator ("+ 1/4 in") or a fraction of numbers
# ("1/4 in", after "12.5"): pint would multiply the value by it. "1/min" is a unit.
_LEADING_NUMBER = re.compile(r"\s*(?:[-+*/]|[\d.](?!\s*/\s*[^\d\s])|\d+\s*/\s*\d)")
_DECIMAL = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*")


def _split(text: str) -> tuple[float, str]:
    fraction = _MIXED_FRACTION.fullmatch(text)
    if fraction is not None:
        denominator = int(fraction["den"])
        if denominator == 0:
            raise ValueError(f"'{text}': a fraction with denominator 0")
        number = int(fraction["whole"] or 0) + int(fraction["num"]) / denominator
        return (-number if fraction["sign"] == "-" else number), fraction["unit"]
    match = _DECIMAL.fullmatch(text)
    if match is None:
        raise ValueError(f"'{text}' is not a number followed by a unit (e.g. '9950 ft')")
    number, unit = float(match.group(1)), match.group(2)
    if _LEADING_NUMBER.match(unit):
        raise ValueError(f"'{text}': the unit '{unit}' starts with a number or an operator; "
                         "write one number and a unit (e.g. '12.25 in' or '12 1/4 in')")
    return number, unit


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
    if _LEADING_NUMBER.match(unit):
        # pint reads "8 N" as a quantity and would multiply every value by 8
        raise ValueError(f"unit '{unit}' starts with a number; give the number as the value")
    if unit not in _ABSOLUTE_TEMPERATURES:
        unit = _OFFSET_IN_COMPOUND.sub(lambda m: "delta_" + m.group(1), unit)
    if target not in _ABSOLUTE_TEMPERATURES:
        target = _OFFSET_IN_COMPOUND.sub(lambda m: "delta_" + m.group(1), target)
    key = f"{unit}\x1f{target}"
    stored = _stored_conversions().get(key)
    if stored is not None:
        return stored[0], stored[1]
    value = _pint_conversion(unit, target)
    _store(key, value)
    return value


def _pint_conversion(unit: str, target: str) -> tuple[float, float]:
    import pint

    ureg = registry()
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


# Sample times: Unix seconds from 1970 up to the year 2200 (a stamp beyond is a unit mistake,
# e.g. milliseconds, never a real time).
T_MIN = 0.0
T_MAX = 7_258_118_400.0


def parse_time(t: object) -> float | str:
    """Unix seconds from a number or an ISO 8601 string, or the rejection reason."""
    if isinstance(t, bool):
        return "'t' must be Unix seconds or ISO 8601, got bool"
    if isinstance(t, int | float):
        try:
            seconds = float(t)
        except OverflowError:
            return "'t' is too large"
    elif isinstance(t, str):
        try:
            stamp = datetime.fromisoformat(t)
        except ValueError:
            return f"'t' is not ISO 8601: '{clip(t)}'"
        if stamp.tzinfo is None:
            stamp = stamp.replace(tzinfo=UTC)
        try:
            seconds = stamp.timestamp()
        except (OverflowError, OSError, ValueError):
            return f"'t' out of range: '{clip(t)}'"
    else:
        return f"'t' must be Unix seconds or ISO 8601, got {type(t).__name__}"
    if not math.isfinite(seconds):
        return f"'t' is not finite ({seconds})"
    if not T_MIN <= seconds < T_MAX:
        return f"'t' out of range ({seconds:g} s)"
    return seconds


def clip(text: str, limit: int = 60) -> str:
    """``text`` cut to ``limit`` characters with "..." (for quoting user input in errors)."""
    return text if len(text) <= limit else text[: limit - 3] + "..."
