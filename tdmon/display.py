"""Display units: how tables, reports and Rerun views show quantities.

tdmon computes, records and publishes in SI (docs/architecture.md, "Units"); what a person
reads can be SI or oilfield ("field") units. A :class:`UnitSystem` gives, for each kind of
quantity, the unit shown and the conversion from the internal unit, so that an output site
writes ``units.force(hookload)`` and ``units.label("force")`` instead of ``/ 1e3`` and ``"kN"``.

==============  ===========  ===========  =====================
quantity        internal     ``si``       ``field``
==============  ===========  ===========  =====================
force           N            kN           klbf
torque          N m          kN m         kft lbf
depth           m            m            ft
density         kg/m^3       kg/m3        ppg
temperature     degC         degC         degF
pressure        Pa           bar          psi
flow            m^3/s        L/min        gpm (US gal/min)
rotation        rad/s        rpm          rpm
==============  ===========  ===========  =====================

Which system a command shows comes from :func:`resolve`: the command's ``--units`` option,
else the ``TDMON_UNITS`` environment variable, else the daemon file's ``[display] units``,
else ``si``. JSON, CSV and MCAP output stays SI whatever the choice (docs/configuration.md).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from functools import cache
from types import MappingProxyType
from typing import Final, Literal, TypeVar, cast, get_args

import numpy as np
from numpy.typing import NDArray

from tdmon.errors import TdmonError

__all__ = ["ENVIRONMENT_VARIABLE", "QUANTITIES", "SYSTEMS", "DisplayUnit", "UnitSystem",
           "current", "resolve", "unit_system", "using"]

SystemName = Literal["si", "field"]
SYSTEMS: Final[tuple[str, ...]] = get_args(SystemName)
ENVIRONMENT_VARIABLE: Final = "TDMON_UNITS"

Quantity = Literal["force", "torque", "depth", "density", "temperature", "pressure", "flow",
                   "rotation"]

QUANTITIES: Final[Mapping[str, str]] = MappingProxyType({
    "force": "N",
    "torque": "N*m",
    "depth": "m",
    "density": "kg/m**3",
    "temperature": "degC",
    "pressure": "Pa",
    "flow": "m**3/s",
    "rotation": "rad/s",
})
"""Each kind of quantity and its internal unit (as in tdmon.channels)."""

# (label shown, key used in column and entity names) per system and quantity; the label is
# also the unit converted to, so that every unit tdmon prints is one it reads
_TABLES: Final[Mapping[str, Mapping[str, tuple[str, str]]]] = {
    "si": {
        "force": ("kN", "kN"),
        "torque": ("kN m", "kNm"),
        "depth": ("m", "m"),
        "density": ("kg/m3", "kgm3"),
        "temperature": ("degC", "C"),
        "pressure": ("bar", "bar"),
        "flow": ("L/min", "Lpm"),
        "rotation": ("rpm", "rpm"),
    },
    "field": {
        "force": ("klbf", "klbf"),
        "torque": ("kft lbf", "kftlbf"),
        "depth": ("ft", "ft"),
        "density": ("ppg", "ppg"),
        "temperature": ("degF", "F"),
        "pressure": ("psi", "psi"),
        "flow": ("gpm", "gpm"),  # US gallons per minute
        "rotation": ("rpm", "rpm"),
    },
}

ArrayOrFloat = TypeVar("ArrayOrFloat", float, NDArray[np.float64])


@dataclass(frozen=True, slots=True)
class DisplayUnit:
    """One shown unit: ``shown = internal * scale + offset``.

    Attributes
    ----------
    label : what tables and axis labels print, e.g. ``"kN m"``
    key : the same without spaces or symbols, for column and entity names, e.g. ``"kNm"``
    scale, offset : conversion from the internal (SI) unit
    """

    label: str
    key: str
    scale: float
    offset: float = 0.0

    def __call__(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """``value`` [internal unit] in this unit."""
        return value * self.scale + self.offset

    def inverse(self, value: float) -> float:
        """``value`` in this unit back to the internal unit."""
        return (value - self.offset) / self.scale


@dataclass(frozen=True)
class UnitSystem:
    """The shown unit of every kind of quantity (see the module's table)."""

    name: SystemName
    units: Mapping[str, DisplayUnit]

    def unit(self, quantity: Quantity) -> DisplayUnit:
        return self.units[quantity]

    def label(self, quantity: Quantity) -> str:
        """The unit's label, e.g. ``label("torque") == "kft lbf"`` in field units."""
        return self.units[quantity].label

    def key(self, quantity: Quantity) -> str:
        """The unit for names, e.g. ``key("force") == "klbf"`` (``hookload_klbf``)."""
        return self.units[quantity].key

    def convert(self, quantity: Quantity, value: ArrayOrFloat) -> ArrayOrFloat:
        """``value`` [internal unit of ``quantity``] in the shown unit."""
        return self.units[quantity](value)

    def force(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Force [N] shown: kN or klbf."""
        return self.units["force"](value)

    def torque(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Torque [N m] shown: kN m or kft lbf."""
        return self.units["torque"](value)

    def depth(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Depth or length [m] shown: m or ft."""
        return self.units["depth"](value)

    def density(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Density [kg/m^3] shown: kg/m3 or ppg."""
        return self.units["density"](value)

    def temperature(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Temperature [degC] shown: degC or degF."""
        return self.units["temperature"](value)

    def pressure(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Pressure [Pa] shown: bar or psi."""
        return self.units["pressure"](value)

    def flow(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Flow rate [m^3/s] shown: L/min or gpm."""
        return self.units["flow"](value)

    def rotation(self, value: ArrayOrFloat) -> ArrayOrFloat:
        """Rotary speed [rad/s] shown: rpm."""
        return self.units["rotation"](value)

    def quantity_of(self, internal_unit: str) -> Quantity | None:
        """The kind of quantity whose internal unit is ``internal_unit`` (a unit text
        of tdmon.channels, e.g. ``"N*m"``), or None."""
        for quantity, unit in QUANTITIES.items():
            if unit == internal_unit:
                return cast(Quantity, quantity)
        return None

    @property
    def other(self) -> UnitSystem:
        """The other system (a table may show it in parentheses)."""
        return unit_system("field" if self.name == "si" else "si")


@cache
def unit_system(name: str) -> UnitSystem:
    """The system ``"si"`` or ``"field"``; conversions come from :mod:`tdmon.units`.

    Raises
    ------
    ValueError
        ``name`` is neither.
    """
    from tdmon.units import conversion

    if name not in _TABLES:
        raise ValueError(f"'{name}' is not a unit system (one of {', '.join(SYSTEMS)})")
    units = {}
    for quantity, (label, key) in _TABLES[name].items():
        scale, offset = conversion(QUANTITIES[quantity], label)
        # 1/(5/9) is 1.7999999999999998 degF/degC in floating point; 14 digits are exact
        units[quantity] = DisplayUnit(label, key, _round(scale), _round(offset))
    return UnitSystem(cast(SystemName, name), MappingProxyType(units))


def _round(value: float) -> float:
    return float(f"{value:.14g}")


def resolve(option: str | None = None, config: str | None = None,
            environ: Mapping[str, str] | None = None) -> UnitSystem:
    """The system a command shows: ``--units``, else ``TDMON_UNITS``, else the daemon file's
    ``[display] units``, else SI.

    Raises
    ------
    TdmonError
        ``TDMON_UNITS`` names no system (the option and the file are checked where read).
    """
    if option is not None:
        return unit_system(option)
    value = (os.environ if environ is None else environ).get(ENVIRONMENT_VARIABLE, "").strip()
    if value:
        if value.lower() not in SYSTEMS:
            raise TdmonError(f"{ENVIRONMENT_VARIABLE}='{value}' is not a unit system; "
                             f"set it to {' or '.join(SYSTEMS)}")
        return unit_system(value.lower())
    return unit_system(config or "si")


# The system of this process's outputs that are built deep inside the daemon (Rerun views of
# `tdmon run` and `tdmon replay --rrd`): the command sets it around its run, the sink reads it.
# A context variable, so that it is reset after the command and copied into asyncio tasks.
_CURRENT: ContextVar[UnitSystem | None] = ContextVar("tdmon_display_units", default=None)


def current() -> UnitSystem:
    """The system set by :func:`using` around the running command, else SI."""
    return _CURRENT.get() or unit_system("si")


@contextmanager
def using(system: UnitSystem) -> Iterator[UnitSystem]:
    """Make ``system`` the :func:`current` one inside the ``with`` block."""
    token = _CURRENT.set(system)
    try:
        yield system
    finally:
        _CURRENT.reset(token)
