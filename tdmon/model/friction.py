"""Friction factor as a function of mud temperature, mu(T), T in degC.

Pure functions for the families of the thesis [1] (eq. 5, 8-11), published coefficient sets as
module constants (Kaarstad et al. [2], the thesis's own fit), a small frozen
:class:`FrictionModel` that a lab fit's output feeds as is, and :func:`local_friction`, which
gives each string element the friction of its hole section at its annulus temperature.

References
----------
.. [1] Thesis "Torque and Drag Friction Model: Implemented Friction Factor Dependency of
   Temperature" (University of Stavanger), sections 2, 3.3, 3.4, 4.3.
.. [2] Kaarstad, E., Aadnoy, B.S., Fjelde, T. (2009). A study of temperature dependent
   friction in wellbore fluids. SPE/IADC 119768.
.. [3] Samuel, R. (2010). Friction factors: what are they for torque, drag, vibration, bottom
   hole assembly and transient surge/swab analyses? IADC/SPE 128059 (Table 24 in [1]).
"""

from __future__ import annotations

import inspect
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

__all__ = [
    "EVERY_COEFFICIENT",
    "FAMILIES",
    "KAARSTAD_2009",
    "PUBLISHED_FRICTION_MODELS",
    "THESIS_GLYDRIL_FIT",
    "TYPICAL_FRICTION_RANGES",
    "FrictionFamily",
    "FrictionModel",
    "constant",
    "evaluate_law",
    "exponential",
    "linear",
    "local_friction",
    "polynomial",
    "power",
    "saturation_growth",
]

Array = NDArray[np.float64]


def _temperature(temperature: ArrayLike) -> Array:
    values = np.asarray(temperature, dtype=np.float64)
    # the array methods, not np.all/np.any: these checks run for every friction case the
    # calibration evaluates, and the functions' dispatch costs more than the check
    if not np.isfinite(values).all():
        raise ModelError("temperature contains non-finite values")
    return values


def _finite(mu: Array, family: str, temperature: Array) -> Array:
    finite = np.isfinite(mu)
    if not finite.all():
        where = np.atleast_1d(temperature)[np.atleast_1d(~finite)][0]
        raise ModelError(f"friction model '{family}' is not defined at {where} degC")
    return mu


def constant(temperature: ArrayLike, mu: float) -> Array:
    """Temperature-independent friction factor.

    Parameters
    ----------
    temperature : array_like
        Mud temperature [degC] (only its shape is used).
    mu : float
        Friction factor [-].

    Returns
    -------
    ndarray
        ``mu`` with the shape of ``temperature`` [-].
    """
    t = _temperature(temperature)
    return _finite(np.full(t.shape, float(mu)), "constant", t)


def linear(temperature: ArrayLike, a: float, b: float) -> Array:
    """Linear friction law mu = a + b T.

    Parameters
    ----------
    temperature : array_like
        Mud temperature T [degC].
    a : float
        Friction factor at 0 degC [-].
    b : float
        Slope [1/K].

    Returns
    -------
    ndarray
        Friction factor [-].

    Notes
    -----
    Eq. 5 in [1] (alpha + beta T_a); Kaarstad et al. [2] fit this form (eq. 12-16 in [1]).
    """
    t = _temperature(temperature)
    return _finite(a + b * t, "linear", t)


def power(temperature: ArrayLike, a: float, b: float) -> Array:
    """Power law mu = a T^b, for T > 0 degC.

    Parameters
    ----------
    temperature : array_like
        Mud temperature T [degC], positive.
    a : float
        Friction factor at 1 degC [-].
    b : float
        Exponent [-].

    Returns
    -------
    ndarray
        Friction factor [-].

    Notes
    -----
    Eq. 8 in [1]. Not defined at or below 0 degC (ModelError).
    """
    t = _temperature(temperature)
    if np.any(t <= 0.0):
        raise ModelError("the power friction model mu = a T^b needs temperatures above 0 degC")
    return _finite(a * t**b, "power", t)


def exponential(temperature: ArrayLike, a: float, b: float) -> Array:
    """Exponential law mu = a e^(b T).

    Parameters
    ----------
    temperature : array_like
        Mud temperature T [degC].
    a : float
        Friction factor at 0 degC [-].
    b : float
        Rate [1/K].

    Returns
    -------
    ndarray
        Friction factor [-].

    Notes
    -----
    Eq. 9 in [1].
    """
    t = _temperature(temperature)
    with np.errstate(over="ignore"):
        return _finite(a * np.exp(b * t), "exponential", t)


def saturation_growth(temperature: ArrayLike, a: float, b: float) -> Array:
    """Saturation-growth law mu = a T / (b + T).

    Parameters
    ----------
    temperature : array_like
        Mud temperature T [degC].
    a : float
        Friction factor approached at high temperature [-].
    b : float
        Temperature at which mu = a/2 [degC].

    Returns
    -------
    ndarray
        Friction factor [-].

    Notes
    -----
    Eq. 10 in [1]. Singular at T = -b (ModelError).
    """
    t = _temperature(temperature)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _finite(a * t / (b + t), "saturation-growth", t)


def polynomial(temperature: ArrayLike, **coefficients: float) -> Array:
    """Polynomial law mu = a0 + a1 T + ... + am T^m.

    Parameters
    ----------
    temperature : array_like
        Mud temperature T [degC].
    **coefficients : float
        ``a0``, ``a1``, ... ``am``: coefficient of T^k [1/K^k]; missing powers are zero.

    Returns
    -------
    ndarray
        Friction factor [-].

    Notes
    -----
    Eq. 11 in [1].
    """
    t = _temperature(temperature)
    powers: dict[int, float] = {}
    for name, value in coefficients.items():
        match = re.fullmatch(r"a(\d+)", name)
        if match is None:
            raise ModelError(f"polynomial coefficient '{name}' is not of the form a0, a1, ...")
        powers[int(match.group(1))] = float(value)
    if not powers:
        raise ModelError("the polynomial friction model needs at least a0")
    ordered = [powers.get(k, 0.0) for k in range(max(powers) + 1)]
    values = np.asarray(np.polynomial.polynomial.polyval(t, ordered), dtype=np.float64)
    return _finite(values, "polynomial", t)


#: the ``scaled`` of a family whose every coefficient multiplies mu (its friction is linear
#: in the coefficients, as a polynomial's, whose names a0, a1, ... vary with the degree)
EVERY_COEFFICIENT: Final = "every"


@dataclass(frozen=True)
class FrictionFamily:
    """A mu(T) family: its function and the coefficients that the friction is proportional to.

    Calling it calls the function: ``FAMILIES["linear"](T, a=0.23, b=0.0013)``.

    Parameters
    ----------
    function : ``(temperature, **coefficients) -> mu``
    scaled : the coefficients to multiply by ``s`` so that the law becomes ``s mu(T)`` (the
        mu(T) calibration's scale mode, :mod:`tdmon.calib.mu_calibration`), e.g. ``("a",)``
        for ``a T^b``, or :data:`EVERY_COEFFICIENT`. Required: a family that does not say is
        an error, never every coefficient by default (that would scale the exponent of a
        power law).

    Raises
    ------
    ModelError
        ``scaled`` is empty or names a coefficient the function does not take.
    """

    function: Callable[..., Array]
    scaled: tuple[str, ...] | Literal["every"]

    def __post_init__(self) -> None:
        if self.scaled == EVERY_COEFFICIENT:
            return
        taken = tuple(inspect.signature(self.function).parameters)[1:]
        if not self.scaled or not set(self.scaled) <= set(taken):
            raise ModelError(f"friction family {self.function.__name__}: scaled coefficients "
                             f"{self.scaled!r} must be some of {', '.join(taken)}")

    def __call__(self, temperature: ArrayLike, **coefficients: float) -> Array:
        return self.function(temperature, **coefficients)

    def scale(self, coefficients: Mapping[str, float], factor: float) -> dict[str, float]:
        """The coefficients of ``factor`` times the law (the others as they are)."""
        if self.scaled == EVERY_COEFFICIENT:
            return {name: value * factor for name, value in coefficients.items()}
        return {name: value * factor if name in self.scaled else value
                for name, value in coefficients.items()}


FAMILIES: Mapping[str, FrictionFamily] = MappingProxyType({
    "constant": FrictionFamily(constant, scaled=("mu",)),
    "linear": FrictionFamily(linear, scaled=EVERY_COEFFICIENT),
    "power": FrictionFamily(power, scaled=("a",)),
    "exponential": FrictionFamily(exponential, scaled=("a",)),
    "saturation-growth": FrictionFamily(saturation_growth, scaled=("a",)),
    "polynomial": FrictionFamily(polynomial, scaled=EVERY_COEFFICIENT),
})
"""mu(T) families by name; each takes ``(temperature, **coefficients)`` and says which of its
coefficients the scale mode multiplies."""

#: The coefficient names of each family but the polynomial's (whose names are a0, a1, ...),
#: read once from the functions' signatures: a FrictionModel is built for every calibration
#: step, and ``inspect.signature`` costs more than the rest of its checks together.
_PARAMETERS: Mapping[str, tuple[str, ...]] = MappingProxyType({
    name: tuple(inspect.signature(family.function).parameters)[1:]
    for name, family in FAMILIES.items() if name != "polynomial"})
_PARAMETER_SETS: Mapping[str, frozenset[str]] = MappingProxyType({
    name: frozenset(parameters) for name, parameters in _PARAMETERS.items()})


@dataclass(frozen=True)
class FrictionModel:
    """A friction law mu(T): a family name and its coefficients.

    Parameters
    ----------
    family : str
        One of :data:`FAMILIES` ("constant", "linear", "power", "exponential",
        "saturation-growth", "polynomial").
    coefficients : Mapping[str, float]
        Keyword arguments of the family's function, e.g. ``{"a": 0.23, "b": 0.0013}`` for
        "linear", ``{"mu": 0.2}`` for "constant", ``{"a0": ..., "a1": ...}`` for "polynomial".

    Examples
    --------
    >>> FrictionModel("linear", {"a": 0.23, "b": 0.0013})(50.0)
    array(0.295)
    """

    family: str
    coefficients: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ModelError(f"unknown friction family '{self.family}' "
                             f"(expected one of {', '.join(FAMILIES)})")
        values: dict[str, float] = {}
        for name, value in self.coefficients.items():
            number = float(value)
            if not math.isfinite(number):
                raise ModelError(f"friction coefficient '{name}' must be finite, got {value}")
            values[name] = number
        if self.family != "polynomial":
            parameters = _PARAMETERS[self.family]
            if set(values) != set(parameters):
                raise ModelError(f"friction family '{self.family}' takes coefficients "
                                 f"{', '.join(parameters)}, got {', '.join(values) or 'none'}")
        else:
            polynomial(0.0, **values)  # checks the names a0, a1, ...
        object.__setattr__(self, "coefficients", MappingProxyType(values))

    @classmethod
    def constant(cls, mu: float) -> FrictionModel:
        """A temperature-independent friction factor ``mu`` [-]."""
        return cls("constant", {"mu": mu})

    def __call__(self, temperature_C: ArrayLike) -> Array:
        """Friction factor [-] at mud temperature ``temperature_C`` [degC]."""
        return FAMILIES[self.family].function(temperature_C, **self.coefficients)

    def describe(self) -> str:
        """A one-line formula, e.g. ``mu = 0.23 + 0.0013 T``."""
        c = self.coefficients
        if self.family == "constant":
            return f"mu = {c['mu']:g}"
        if self.family == "linear":
            return f"mu = {c['a']:g} + {c['b']:g} T"
        if self.family == "power":
            return f"mu = {c['a']:g} T^{c['b']:g}"
        if self.family == "exponential":
            return f"mu = {c['a']:g} exp({c['b']:g} T)"
        if self.family == "saturation-growth":
            return f"mu = {c['a']:g} T / ({c['b']:g} + T)"
        terms = sorted(c.items(), key=lambda item: int(item[0][1:]))
        return "mu = " + " + ".join(f"{v:g} T^{k[1:]}" for k, v in terms)


def evaluate_law(family: str, coefficients: dict[str, float],
                 temperature_C: ArrayLike) -> Array:
    """``FrictionModel(family, coefficients)(temperature_C)`` without building the model.

    The same numbers and errors: the family's function takes the coefficients straight away
    when they are what the model would check them into (finite floats, the family's names);
    anything else goes through :class:`FrictionModel`, which raises as it does. The mu(T)
    calibration evaluates its law about 16 times a window; building and checking the model
    each time made one evaluation at 400 temperatures 8.2 instead of 6.6 us.

    Parameters
    ----------
    family : str
        One of :data:`FAMILIES`.
    coefficients : dict[str, float]
        Keyword arguments of the family's function.
    temperature_C : array_like
        Mud temperature [degC].

    Returns
    -------
    ndarray
        Friction factor [-].
    """
    names = _PARAMETER_SETS.get(family)  # None for the polynomial and unknown families
    if names is None or coefficients.keys() != names:
        return FrictionModel(family, coefficients)(temperature_C)
    for value in coefficients.values():
        if type(value) is not float or not math.isfinite(value):
            return FrictionModel(family, coefficients)(temperature_C)
    return FAMILIES[family].function(temperature_C, **coefficients)


def _linear(a: float, b: float) -> FrictionModel:
    return FrictionModel("linear", {"a": a, "b": b})


KAARSTAD_2009: Mapping[str, FrictionModel] = MappingProxyType({
    "water": _linear(0.42, 0.0021),
    "oil-based-1.53sg": _linear(0.12, 0.0001),
    "oil-based-1.58sg": _linear(0.14, 0.00005),
    "glydril": _linear(0.23, 0.0013),
    "aphrons": _linear(0.42, 0.00227),
})
"""Linear mu(T) fits of Kaarstad et al. [2] (T in degC), eq. 12-16 in [1].

Keys: water (eq. 12), oil-based mud 1.53 sg (eq. 13), oil-based mud 1.58 sg (eq. 14), Glydril
water-based mud (eq. 15), Aphrons (eq. 16; the thesis prints it without the T).
"""

THESIS_GLYDRIL_FIT: FrictionModel = _linear(0.25231, 0.00085)
"""The thesis's own linear fit to the five Glydril tribometer averages, eq. 21 in [1].

tdmon's lab fit of the printed averages gives 0.25195 + 0.000855 T (see docs/lab-fit.md).
"""

PUBLISHED_FRICTION_MODELS: Mapping[str, FrictionModel] = MappingProxyType({
    **{f"kaarstad-{name}": model for name, model in KAARSTAD_2009.items()},
    "thesis-glydril": THESIS_GLYDRIL_FIT,
})
"""Published fits by the names a well file may use (``friction = "kaarstad-glydril"``)."""

TYPICAL_FRICTION_RANGES: Mapping[str, Mapping[str, tuple[float, float]]] = MappingProxyType({
    "oil-based": MappingProxyType({"cased": (0.16, 0.20), "open": (0.17, 0.25)}),
    "water-based": MappingProxyType({"cased": (0.25, 0.35), "open": (0.25, 0.40)}),
    "brine": MappingProxyType({"cased": (0.30, 0.40), "open": (0.30, 0.40)}),
    "polymer-based": MappingProxyType({"cased": (0.15, 0.22), "open": (0.20, 0.30)}),
    "synthetic-based": MappingProxyType({"cased": (0.12, 0.18), "open": (0.15, 0.25)}),
    "foam": MappingProxyType({"cased": (0.30, 0.40), "open": (0.35, 0.55)}),
    "air": MappingProxyType({"cased": (0.35, 0.55), "open": (0.40, 0.60)}),
})
"""Typical friction-factor ranges (low, high) by fluid and hole type, Table 24 in [1] after [3]."""


def local_friction(section_models: Sequence[FrictionModel | float],
                   element_section_index: ArrayLike,
                   element_annulus_temperature_C: ArrayLike) -> Array:
    """Friction factor of each string element from its hole section's mu(T).

    Parameters
    ----------
    section_models : sequence of FrictionModel or float
        One friction law per hole section (cased, open, ...); a float is a constant mu.
    element_section_index : array_like of int
        Index into ``section_models`` of the section each element lies in.
    element_annulus_temperature_C : array_like
        Annulus mud temperature at each element's depth [degC].

    Returns
    -------
    ndarray
        mu per element [-], the ``mu`` array the torque-and-drag kernels accept.

    Notes
    -----
    The local friction factor of Case 2 and 3 in [1]: each element gets mu(T_a) at its depth.
    """
    index = np.asarray(element_section_index)
    temperature = _temperature(element_annulus_temperature_C)
    if index.shape != temperature.shape:
        raise ModelError(f"element_section_index has shape {index.shape} but the temperatures "
                         f"have shape {temperature.shape}")
    if index.size and not np.issubdtype(index.dtype, np.integer):
        raise ModelError("element_section_index must hold integers")
    if index.size and (index.min() < 0 or index.max() >= len(section_models)):
        raise ModelError(f"element_section_index refers to section {int(index.max())} but only "
                         f"{len(section_models)} section models are given")
    mu = np.empty(temperature.shape, dtype=np.float64)
    for number, model in enumerate(section_models):
        mask = index == number
        if not np.any(mask):
            continue
        law = model if isinstance(model, FrictionModel) else FrictionModel.constant(model)
        mu[mask] = law(temperature[mask])
    return mu
