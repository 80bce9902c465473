"""Unit handling at the edges: unit texts read by a bounded grammar, strings with units to SI.

Inside tdmon every quantity is SI (N, N m, m, s, Pa, m^3/s, kg/m^3, rad) except temperatures,
which are degC because the friction correlations are written in degC. A quantity is a string
with its unit, such as ``"0.3 kN/m"``, ``"9950 ft"``, ``"13 ppg"``, ``"60 degF"`` or an oilfield
size such as ``"12 1/4 in"``. :func:`parse_quantity` also takes a plain number as already SI
(command-line flags, Python callers); files refuse a plain number for a dimensional key
(`tdmon.config.common`), since ``block_weight = 655`` meant in kN would be read as 655 N.

A unit text comes from files, command lines and rig payloads alike, so it is read by a small
grammar of known names, never evaluated as an expression (``"m*9**9**9"`` once hung the
daemon): names with an optional prefix, products (``*``, ``.``, ``-`` between names, a space),
quotients (``/``), parentheses, positive numbers (``deg/(30 m)``) and integer powers within
+-:data:`MAX_POWER` (``m3``, ``m^3``, ``m**3``, ``s-1``), at most :data:`MAX_UNIT_CHARS`
characters and :data:`MAX_UNIT_TOKENS` tokens. Every step costs a bounded time.

The names drillers write (:data:`UNIT_NAMES`, docs/configuration.md, "Units") are defined here
with their SI factors; any other single name is looked up in pint's definitions (pint sees the
validated name alone). Where a force is meant (a target in N or N/m), a mass or a mass per
length is its weight under standard gravity (:data:`GRAVITY`): ``"40 t"`` of block weight,
``"19.5 lb/ft"`` of pipe weight.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from datetime import UTC, datetime
from functools import lru_cache
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Final, NamedTuple, cast

if TYPE_CHECKING:
    import pint

__all__ = ["GRAVITY", "MAX_POWER", "MAX_UNIT_CHARS", "MAX_UNIT_TOKENS", "T_MAX", "T_MIN",
           "UNIT_NAMES", "Unit", "UnitError", "clip", "conversion", "examples", "parse_quantity",
           "parse_time", "parse_unit", "registry", "split_quantity", "to_unit"]

GRAVITY: Final = 9.80665
"""Standard gravity [m/s^2] (3rd CGPM, 1901; NIST SP 811, B.8): the weight of a mass where a
force is meant, ``1 t`` = 9806.65 N, ``1 lb/ft`` = 14.593 N/m."""

MAX_UNIT_CHARS: Final = 64
"""The longest unit text read (``BTU/(h ft**2 degF)`` is 18)."""
MAX_UNIT_TOKENS: Final = 24
"""The most names, numbers and operators in one unit text."""
MAX_POWER: Final = 4
"""The largest power of a name or a parenthesis (``m^3``, ``s^-2``)."""
_MAX_DEPTH: Final = 3  # parentheses inside parentheses
_MAX_QUANTITY_CHARS: Final = 120  # a number, a space and a unit


class UnitError(ValueError):
    """A unit text that cannot be read, or that does not measure what ``target`` measures.

    ``reason`` says why; ``str()`` adds units that would work when the target is known.
    """

    def __init__(self, reason: str, target: str | None = None) -> None:
        self.reason = reason
        self.target = target
        hint = _hint(target) if target is not None else ""
        super().__init__(f"{reason}; e.g. {hint}" if hint else reason)


# -- dimensions ------------------------------------------------------------------------------

Dimension = tuple[tuple[str, float], ...]
"""Exponents of pint's base dimensions, sorted by name, zeros left out."""


def _dimension(**exponents: float) -> Dimension:
    return tuple(sorted((f"[{name}]", float(power)) for name, power in exponents.items()
                        if power))


def _product(a: Dimension, b: Dimension, power: float = 1.0) -> Dimension:
    merged = dict(a)
    for name, exponent in b:
        merged[name] = merged.get(name, 0.0) + exponent * power
    return tuple(sorted((name, value) for name, value in merged.items() if value))


NONE: Final = _dimension()
LENGTH: Final = _dimension(length=1)
MASS: Final = _dimension(mass=1)
TIME: Final = _dimension(time=1)
TEMPERATURE: Final = _dimension(temperature=1)
VOLUME: Final = _dimension(length=3)
RATE: Final = _dimension(time=-1)
SPEED: Final = _dimension(length=1, time=-1)
FORCE: Final = _dimension(mass=1, length=1, time=-2)
TORQUE: Final = _dimension(mass=1, length=2, time=-2)
PRESSURE: Final = _dimension(mass=1, length=-1, time=-2)
FORCE_PER_LENGTH: Final = _dimension(mass=1, time=-2)
MASS_PER_LENGTH: Final = _dimension(mass=1, length=-1)
DENSITY: Final = _dimension(mass=1, length=-3)
FLOW: Final = _dimension(length=3, time=-1)
POWER: Final = _dimension(mass=1, length=2, time=-3)
VISCOSITY: Final = _dimension(mass=1, length=-1, time=-1)
STROKE_RATE: Final = _dimension(stroke=1, time=-1)
_STROKE: Final = _dimension(stroke=1)

# What a dimension is called in messages, and units of it that work (the first is the example
# a message gives; docs/configuration.md lists the same).
_KINDS: Final[Mapping[Dimension, tuple[str, tuple[str, ...]]]] = MappingProxyType({
    NONE: ("a plain number", ("%",)),
    LENGTH: ("a length", ("m", "ft", "in")),
    MASS: ("a mass", ("kg", "t", "lb")),
    TIME: ("a duration", ("s", "min", "h")),
    TEMPERATURE: ("a temperature", ("degC", "degF")),
    VOLUME: ("a volume", ("m3", "bbl", "L")),
    RATE: ("a rotary speed or a rate", ("rpm", "1/s")),
    SPEED: ("a speed", ("m/s", "ft/min", "m/h")),
    FORCE: ("a force", ("kN", "klbf", "t")),
    TORQUE: ("a torque", ("kN*m", "kft.lbf", "ft-lbf")),
    PRESSURE: ("a pressure", ("bar", "psi", "MPa")),
    FORCE_PER_LENGTH: ("a weight per length", ("kN/m", "lb/ft", "kg/m")),
    MASS_PER_LENGTH: ("a mass per length", ("kg/m", "lb/ft")),
    DENSITY: ("a density", ("kg/m3", "ppg", "sg")),
    FLOW: ("a flow rate", ("L/min", "gpm", "bpm")),
    STROKE_RATE: ("a pump stroke rate", ("spm",)),
    _product(TEMPERATURE, LENGTH, -1): ("a temperature gradient", ("degC/100m", "degF/ft")),
})


def _kind(dimension: Dimension) -> str:
    known = _KINDS.get(dimension)
    return known[0] if known is not None else "another quantity"


def examples(target: str) -> tuple[str, ...]:
    """Units that convert to ``target`` as people write them (``examples("N")`` is
    ``("kN", "klbf", "t")``); empty for a target of no listed kind."""
    try:
        unit = parse_unit(target)
    except UnitError:
        return ()
    known = _KINDS.get(unit.dimension)
    return known[1] if known is not None else ()


def _hint(target: str) -> str:
    spelled = [f"'{example}'" for example in examples(target)]
    if not spelled:
        return ""
    return spelled[0] if len(spelled) == 1 else f"{', '.join(spelled[:-1])} or {spelled[-1]}"


# -- names -----------------------------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class _Name:
    """One unit name: ``value [SI] = value [name] * scale``."""

    scale: float
    dimension: Dimension


_INCH = 0.0254  # [m], exact (international yard and pound agreement, 1959)
_FOOT = 0.3048  # [m], exact
_POUND = 0.45359237  # [kg], exact
_GALLON = 3.785411784e-3  # [m^3], US gallon: 231 in^3, exact
_POUND_FORCE = _POUND * GRAVITY  # [N]
_DEGREE = math.pi / 180.0  # [rad]
_REVOLUTION = 2.0 * math.pi  # [rad]

_NAME_TABLE: dict[str, tuple[float, Dimension]] = {
    # length
    "m": (1.0, LENGTH), "meter": (1.0, LENGTH), "metre": (1.0, LENGTH),
    "ft": (_FOOT, LENGTH), "foot": (_FOOT, LENGTH), "feet": (_FOOT, LENGTH),
    "in": (_INCH, LENGTH), "inch": (_INCH, LENGTH),
    # mass: t and tonne are the metric ton, lb the avoirdupois pound
    "g": (1e-3, MASS), "t": (1e3, MASS), "tonne": (1e3, MASS),
    "lb": (_POUND, MASS), "lbm": (_POUND, MASS), "lbs": (_POUND, MASS),
    # time
    "s": (1.0, TIME), "sec": (1.0, TIME), "second": (1.0, TIME), "min": (60.0, TIME),
    "minute": (60.0, TIME), "h": (3600.0, TIME), "hr": (3600.0, TIME), "hour": (3600.0, TIME),
    "d": (86400.0, TIME), "day": (86400.0, TIME),
    # force: kgf and tf are a kilogram and a tonne under standard gravity, kip 1000 lbf
    "N": (1.0, FORCE), "lbf": (_POUND_FORCE, FORCE), "kip": (1e3 * _POUND_FORCE, FORCE),
    "kgf": (GRAVITY, FORCE), "tf": (1e3 * GRAVITY, FORCE), "kdaN": (1e4, FORCE),
    # torque written as one word
    "Nm": (1.0, TORQUE), "kNm": (1e3, TORQUE),
    # pressure
    "Pa": (1.0, PRESSURE), "bar": (1e5, PRESSURE),
    "psi": (_POUND_FORCE / _INCH**2, PRESSURE), "ksi": (1e3 * _POUND_FORCE / _INCH**2, PRESSURE),
    # volume: bbl is the oil barrel, 42 US gallons (not pint's 31.5-gallon barrel)
    "L": (1e-3, VOLUME), "l": (1e-3, VOLUME), "cc": (1e-6, VOLUME),
    "gal": (_GALLON, VOLUME), "gallon": (_GALLON, VOLUME), "galUS": (_GALLON, VOLUME),
    "bbl": (42.0 * _GALLON, VOLUME),
    # flow rates and pump strokes (a stroke count has a dimension of its own: no key takes it)
    "gpm": (_GALLON / 60.0, FLOW), "bpm": (42.0 * _GALLON / 60.0, FLOW),
    "lpm": (1e-3 / 60.0, FLOW), "Lpm": (1e-3 / 60.0, FLOW),
    "stroke": (1.0, _STROKE), "spm": (1.0 / 60.0, STROKE_RATE),
    # density: sg is relative to water at 1000 kg/m3, ppg pounds per US gallon
    "sg": (1e3, DENSITY), "SG": (1e3, DENSITY), "ppg": (_POUND / _GALLON, DENSITY),
    # angles and rotation (radians are a plain number, as in pint)
    "rad": (1.0, NONE), "deg": (_DEGREE, NONE), "degree": (_DEGREE, NONE),
    "rev": (_REVOLUTION, NONE), "revolution": (_REVOLUTION, NONE),
    "rpm": (_REVOLUTION / 60.0, RATE), "rps": (_REVOLUTION, RATE), "Hz": (1.0, RATE),
    # energy, power, viscosity (thermal and fluid properties)
    "J": (1.0, TORQUE), "W": (1.0, POWER), "BTU": (1055.056, TORQUE), "Btu": (1055.056, TORQUE),
    "cP": (1e-3, VISCOSITY),
    # plain numbers
    "dimensionless": (1.0, NONE), "%": (0.01, NONE), "percent": (0.01, NONE),
    # temperature differences (inside a compound unit degC and degF are these)
    "K": (1.0, TEMPERATURE), "kelvin": (1.0, TEMPERATURE),
    "delta_degC": (1.0, TEMPERATURE), "delta_degF": (5.0 / 9.0, TEMPERATURE),
    "degR": (5.0 / 9.0, TEMPERATURE),
}

# Absolute temperatures when alone: degC = value * scale + offset. Written from degC, tdmon's
# temperature unit, so that degF -> degC is 5/9 and -160/9 rounded once each
_ABSOLUTE: Final[Mapping[str, tuple[float, float]]] = MappingProxyType({
    "degC": (1.0, 0.0), "celsius": (1.0, 0.0), "degree_Celsius": (1.0, 0.0),
    "degF": (5.0 / 9.0, -160.0 / 9.0), "fahrenheit": (5.0 / 9.0, -160.0 / 9.0),
    "degree_Fahrenheit": (5.0 / 9.0, -160.0 / 9.0),
    "K": (1.0, -273.15), "kelvin": (1.0, -273.15), "degR": (5.0 / 9.0, -273.15),
})

# SI prefixes, longest first ("da" before "d"), and the names that take them; oilfield names
# take "k" (kft, klb, klbf, kkgf)
_PREFIXES: Final = (("da", 1e1), ("G", 1e9), ("M", 1e6), ("k", 1e3), ("h", 1e2), ("d", 1e-1),
                    ("c", 1e-2), ("m", 1e-3), ("µ", 1e-6), ("u", 1e-6), ("n", 1e-9))
_SI_PREFIXED: Final = frozenset({"m", "g", "s", "N", "Pa", "L", "l", "J", "W", "Hz", "bar",
                                 "rad"})
_KILO_PREFIXED: Final = frozenset({"ft", "lb", "lbf", "kgf", "gal", "bbl"})

UNIT_NAMES: Final[Mapping[str, tuple[float, Dimension]]] = MappingProxyType(_NAME_TABLE)
"""The names defined here: name -> (SI factor, dimension). Prefixed forms (kN, MPa, mm, kft,
klb, klbf, kkgf, daN) and pint's other names are read too; ``degC``/``degF`` alone are
absolute temperatures."""


@lru_cache(maxsize=256)
def _name(text: str, pint_names: bool = True) -> _Name | None:
    """The unit ``text`` names (one name, validated by the tokenizer), or None; pint's
    definitions are looked up only with ``pint_names``."""
    entry = _NAME_TABLE.get(text)
    if entry is not None:
        return _Name(*entry)
    if text in _ABSOLUTE:  # degC, degF inside a compound: a temperature difference
        return _Name(_ABSOLUTE[text][0], TEMPERATURE)
    for prefix, factor in _PREFIXES:
        if text.startswith(prefix) and len(text) > len(prefix):
            base = text[len(prefix):]
            if base in _SI_PREFIXED or (prefix == "k" and base in _KILO_PREFIXED):
                scale, dimension = _NAME_TABLE[base]
                return _Name(factor * scale, dimension)
    return _pint_name(text) if pint_names else None


def _pint_name(text: str) -> _Name | None:
    """A name outside the table from pint's definitions (multiplicative units only)."""
    import pint
    from pint.util import UnitsContainer

    ureg = registry()
    try:
        units = UnitsContainer({ureg.get_name(text): 1})
        one, zero = ureg.Quantity(1.0, units), ureg.Quantity(0.0, units)
        scale = float(one.to_base_units().magnitude)
        offset = float(zero.to_base_units().magnitude)
        dimension = one.dimensionality
    except (pint.errors.PintError, AttributeError, KeyError, ValueError, TypeError):
        # pint's UndefinedUnitError subclasses AttributeError
        return None
    if offset != 0.0 or not math.isfinite(scale):
        return None  # an offset unit other than the temperatures above, e.g. degRe
    exponents = ((str(name), float(cast(float, power))) for name, power in dimension.items())
    return _Name(scale, tuple(sorted((name, power) for name, power in exponents if power)))


def _cache_folder() -> Path:
    import platformdirs

    return platformdirs.user_cache_path("tdmon", appauthor=False)


@lru_cache(maxsize=1)
def registry() -> pint.UnitRegistry:
    """pint's registry, built the first time a name outside :data:`UNIT_NAMES` is read.

    Parsing pint's definition files takes about 0.4 s, so pint keeps them parsed in the user's
    cache folder (``~/.cache/tdmon/pint`` on Linux; pint rebuilds them when its files change),
    a fixed set of files. A cache folder that cannot be written only costs the parse.
    """
    import pint

    folder = _cache_folder() / "pint"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return pint.UnitRegistry(cache_folder=folder)
    except OSError:
        return pint.UnitRegistry()


# -- the grammar -----------------------------------------------------------------------------

# A name: letters (a digit inside a name such as cmH2O is part of it), "%"; digits right after
# a name are its power (m3, s-1); "-" or "." between names multiplies (ft-lbf, kft.lbf)
_TOKEN = re.compile(r"""
    (?P<space>\s+)
  | (?P<name>%|[A-Za-zµ_]+(?:\d+[A-Za-zµ_]+)*)(?P<attached>(?:-(?=\d)|\+)?\d+)?
  | (?P<number>\d+(?:\.\d+)?)
  | (?P<power>\*\*|\^)\s*(?P<exponent>[-+]?\d+(?:\.\d*)?)?
  | (?P<times>[*·]|[.-](?=[A-Za-zµ_(%]))
  | (?P<divide>/)
  | (?P<open>\()
  | (?P<close>\))
""", re.VERBOSE)
_INTEGER = re.compile(r"[-+]?\d+")
_SYMBOLS: Final = (("°C", "degC"), ("°F", "degF"), ("°", "deg"), ("²", "^2"), ("³", "^3"))


@dataclass(frozen=True, slots=True)
class Unit:
    """A unit read by :func:`parse_unit`: ``value [SI] = value * scale``, or for an absolute
    temperature (``offset`` not None) ``value [degC] = value * scale + offset``."""

    scale: float
    dimension: Dimension
    offset: float | None = None


class _Token(NamedTuple):
    kind: str  # name, number, power, times, divide, open, close
    text: str
    power: str | None  # a name's power written right after it (m3), a power token's exponent
    start: int
    end: int


def _tokens(text: str) -> Iterator[_Token]:
    position = 0
    while position < len(text):
        match = _TOKEN.match(text, position)
        if match is None:
            raise UnitError(f"cannot read unit '{text}' at '{clip(text[position:], 12)}'")
        position = match.end()
        if match["space"] is not None:
            continue
        if match["name"] is not None:
            yield _Token("name", match["name"], match["attached"], match.start(), match.end())
        elif match["power"] is not None:
            yield _Token("power", match[0], match["exponent"], match.start(), match.end())
        else:
            kind = match.lastgroup
            assert kind is not None
            yield _Token(kind, match[0], None, match.start(), match.end())


class _Reader:
    """Recursive descent over at most MAX_UNIT_TOKENS tokens, left to right as in pint
    (``a/b*c`` is ``a*c/b``):
    ``product := factor (("*" | "/" | nothing) factor)*``,
    ``factor := (name [power] | number [name] | "(" product ")") ["^" integer]``.

    A number written against a name is one factor (``deg/30m`` is per 30 m), and a product by
    juxtaposition after a quotient (``W/m K``) is refused as ambiguous.
    """

    def __init__(self, text: str, tokens: list[_Token], pint_names: bool) -> None:
        self.text = text
        self.tokens = tokens
        self.pint_names = pint_names
        self.position = 0

    def fail(self, why: str) -> UnitError:
        return UnitError(f"cannot read unit '{self.text}': {why}")

    def peek(self) -> _Token | None:
        return self.tokens[self.position] if self.position < len(self.tokens) else None

    def product(self, depth: int) -> tuple[float, Dimension]:
        scale, dimension = self.factor(depth)
        after_quotient = False
        while (token := self.peek()) is not None and token.kind != "close":
            if token.kind in ("times", "divide"):
                self.position += 1
            elif after_quotient:
                raise self.fail(f"'{token.text}' after a '/' is ambiguous; write the "
                                "denominator in parentheses, e.g. 'W/(m K)'")
            other_scale, other_dimension = self.factor(depth)
            if token.kind == "divide":
                scale, dimension = scale / other_scale, _product(dimension, other_dimension, -1)
            else:
                scale, dimension = scale * other_scale, _product(dimension, other_dimension)
            after_quotient = token.kind == "divide" or (after_quotient and token.kind != "times")
        return scale, dimension

    def factor(self, depth: int) -> tuple[float, Dimension]:
        token = self.peek()
        if token is None:
            raise self.fail("it ends where a unit is expected")
        self.position += 1
        power = 1
        if token.kind == "name":
            scale, dimension = self.name(token)
            if token.power is not None:
                power = self.checked_power(token.power)
        elif token.kind == "number":
            scale = self.number(token)
            following = self.peek()
            if following is not None and following.kind == "name" and following.start == token.end:
                return self.number_and_name(scale, following)
            dimension = NONE
        elif token.kind == "open":
            scale, dimension = self.parenthesis(depth)
        else:
            raise self.fail(f"'{token.text}' where a unit is expected")
        power = self.power_after(token, power)
        if power != 1:
            scale, dimension = scale**power, _product(NONE, dimension, power)
        return scale, dimension

    def number(self, token: _Token) -> float:
        """A number's value as a factor (never 0, never raised to a power)."""
        scale = float(token.text)
        if not scale > 0:
            raise self.fail("a factor of 0")
        following = self.peek()
        if following is not None and following.kind == "power":
            raise self.fail(f"a number ({token.text}) cannot be raised to a power")
        return scale

    def parenthesis(self, depth: int) -> tuple[float, Dimension]:
        """What stands between a '(' (just read) and its ')'."""
        if depth >= _MAX_DEPTH:
            raise self.fail(f"more than {_MAX_DEPTH} parentheses inside each other")
        scale, dimension = self.product(depth + 1)
        closing = self.peek()
        if closing is None or closing.kind != "close":
            raise self.fail("a '(' is not closed")
        self.position += 1
        return scale, dimension

    def power_after(self, token: _Token, power: int) -> int:
        """The power of a factor: ``power`` (written against a name), or the one a ``^`` or
        ``**`` after it gives (never both, never a power of a power)."""
        following = self.peek()
        if following is None or following.kind != "power":
            return power
        if token.power is not None:
            raise self.fail(f"two powers on '{token.text}'")
        if following.power is None:
            raise self.fail("a power must be a whole number")
        power = self.checked_power(following.power)
        self.position += 1
        again = self.peek()
        if again is not None and again.kind == "power":
            raise self.fail("a power of a power")
        return power

    def number_and_name(self, number: float, token: _Token) -> tuple[float, Dimension]:
        """``30m``: the number times the name (and its own power), one factor."""
        self.position += 1
        scale, dimension = self.name(token)
        if token.power is not None:
            power = self.checked_power(token.power)
            scale, dimension = scale**power, _product(NONE, dimension, power)
        following = self.peek()
        if following is not None and following.kind == "power":
            raise self.fail(f"write the power of '{token.text}' in parentheses")
        return number * scale, dimension

    def name(self, token: _Token) -> tuple[float, Dimension]:
        name = _name(token.text, self.pint_names)
        if name is None:
            where = "" if token.text == self.text else f" in '{self.text}'"
            among = "" if self.pint_names else " (not one of the names tdmon reads in payloads)"
            raise UnitError(f"unknown unit '{token.text}'{where}{among}")
        return name.scale, name.dimension

    def checked_power(self, text: str) -> int:
        if not _INTEGER.fullmatch(text):
            raise self.fail(f"the power '{text}' is not a whole number")
        power = int(text)
        if not -MAX_POWER <= power <= MAX_POWER:
            raise self.fail(f"the power {power} is outside -{MAX_POWER}..{MAX_POWER}")
        return power


@lru_cache(maxsize=512)
def parse_unit(text: str, pint_names: bool = True) -> Unit:
    """Read one unit text (``"kN*m"``, ``"kg/m3"``, ``"ft-lbf"``, ``"degF"``) by the grammar
    of the module's docstring.

    A temperature name alone (``degC``, ``degF``, ``K``) is an absolute temperature; inside a
    compound unit (``degF/ft``, ``BTU/(h ft**2 degF)``) it is a temperature difference. A name
    outside :data:`UNIT_NAMES` and its prefixed forms is looked up in pint's definitions only
    with ``pint_names`` (importing pint takes 0.3-2 s once; the daemon's payloads do without).

    Raises
    ------
    UnitError
        Too long, an unknown name, a power out of range, or not a unit at all.
    """
    if len(text) > MAX_UNIT_CHARS:
        raise UnitError(f"unit '{clip(text)}' is longer than {MAX_UNIT_CHARS} characters")
    stripped = text.strip()
    for symbol, spelled in _SYMBOLS:
        stripped = stripped.replace(symbol, spelled)
    if stripped in _ABSOLUTE:
        scale, offset = _ABSOLUTE[stripped]
        return Unit(scale, TEMPERATURE, offset)
    if not stripped:
        raise UnitError("empty unit")
    tokens: list[_Token] = []
    for token in _tokens(stripped):
        tokens.append(token)
        if len(tokens) > MAX_UNIT_TOKENS:
            raise UnitError(f"unit '{clip(text)}' has more than {MAX_UNIT_TOKENS} parts")
    reader = _Reader(stripped, tokens, pint_names)
    scale, dimension = reader.product(0)
    if reader.position != len(tokens):
        raise reader.fail("a ')' without its '('")
    if not (math.isfinite(scale) and scale > 0):
        raise reader.fail("its size is out of range")
    return Unit(scale, dimension)


# -- conversion ------------------------------------------------------------------------------

# A unit that starts with a number ("8 N"), an operator ("+ 1/4 in") or a fraction of numbers
# ("1/4 in", after "12.5"): pint would multiply the value by it. "1/min" is a unit.
_LEADING_NUMBER = re.compile(r"\s*(?:[-+*/]|[\d.](?!\s*/\s*[^\d\s])|\d+\s*/\s*\d)")


@lru_cache(maxsize=512)
def _conversion_or_reason(unit: str, target: str, pint_names: bool
                          ) -> tuple[float, float] | UnitError:
    """:func:`conversion`, with a refusal returned (so that it is remembered too)."""
    if _LEADING_NUMBER.match(unit):
        return UnitError(f"unit '{clip(unit)}' starts with a number; give the number as the "
                         "value", target)
    try:
        source, wanted = parse_unit(unit, pint_names), parse_unit(target)
    except UnitError as exc:
        return UnitError(exc.reason, target)
    if (source.offset is None) != (wanted.offset is None) and source.dimension == TEMPERATURE:
        alone = "a temperature" if source.offset is not None else "a temperature difference"
        return UnitError(f"unit '{unit}' is {alone}; '{target}' is not", target)
    scale = source.scale
    if source.dimension != wanted.dimension:
        # a weight meant: a mass [kg] or a mass per length [kg/m] times standard gravity
        if (source.dimension, wanted.dimension) in ((MASS, FORCE),
                                                    (MASS_PER_LENGTH, FORCE_PER_LENGTH)):
            scale *= GRAVITY
        else:
            weight = (" (a mass is read as its weight only where a force or a weight per "
                      "length is meant)" if source.dimension in (MASS, MASS_PER_LENGTH) else "")
            return UnitError(f"unit '{unit}' cannot be converted to '{target}': "
                             f"{_kind(source.dimension)}, not {_kind(wanted.dimension)}{weight}",
                             target)
    if source.offset is not None and wanted.offset is not None:
        return scale / wanted.scale, (source.offset - wanted.offset) / wanted.scale
    return scale / wanted.scale, 0.0


def conversion(unit: str, target: str, *, pint_names: bool = True) -> tuple[float, float]:
    """Return (scale, offset) so that ``value_in_target = value * scale + offset``.

    A temperature unit alone (``degF``) is an absolute temperature; inside a compound unit
    (``BTU/(ft degF h)``, ``degF/ft``) it is a temperature difference. A mass where a force is
    meant (``t`` to ``N``, ``lb/ft`` to ``N/m``) is its weight under :data:`GRAVITY`. Results,
    refusals included, are remembered for the last 512 pairs.

    ``pint_names=False`` reads only tdmon's own names (:data:`UNIT_NAMES`, prefixed forms):
    the daemon's payloads, so that no payload makes the daemon import pint.

    Raises
    ------
    UnitError
        The unit cannot be read or has the wrong dimension for ``target`` (a ValueError; the
        message ends with units that would work).
    """
    result = _conversion_or_reason(unit, target, pint_names)
    if isinstance(result, UnitError):
        raise UnitError(result.reason, result.target)
    return result


def to_unit(value: float, unit: str, target: str) -> float:
    """Convert ``value`` given in ``unit`` to ``target`` (e.g. ``to_unit(60, "degF", "degC")``)."""
    scale, offset = conversion(unit, target)
    return value * scale + offset


# Oilfield sizes are written as mixed fractions ("12 1/4 in", "5-1/2 in", "3/4 in"). Read as a
# plain number, "12 1/4 in" would be 12 times the unit "1/4 in", i.e. 3 in.
_MIXED_FRACTION = re.compile(
    r"\s*(?P<sign>[-+]?)(?:(?P<whole>\d+)(?:\s+|-))?(?P<num>\d+)/(?P<den>\d+)\s*(?P<unit>.*?)\s*")
_DECIMAL = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*")


def split_quantity(text: str) -> tuple[float, str]:
    """The number and the unit text of a quantity (``"12 1/4 in"`` -> ``(12.25, "in")``).

    Raises
    ------
    ValueError
        Not one number followed by a unit (a second number, an operator, too long).
    """
    if len(text) > _MAX_QUANTITY_CHARS:
        raise UnitError(f"'{clip(text)}' is longer than {_MAX_QUANTITY_CHARS} characters; "
                        "write one number and a unit (e.g. '9950 ft')")
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


def parse_quantity(value: float | int | str, target: str) -> float:
    """Read a configured quantity: a number already in ``target`` or a string with a unit.

    >>> parse_quantity("9950 ft", "m")
    3032.76
    """
    if isinstance(value, bool):
        raise ValueError("expected a number or a string with a unit, got a boolean")
    if isinstance(value, (int, float)):
        return float(value)
    number, unit = split_quantity(value)
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
