"""Well-file tables for the temperature model and the friction model(s), with adapters.

``[temperature]`` picks a mud-temperature model and gives its inputs; each quantity is a string
with a unit (a plain number is refused: which unit it meant is not known)::

    [temperature]
    model = "apak"                      # geothermal | apak | apak-empirical | numerical
    surface_temperature = "59.5 degF"
    geothermal_gradient = "0.0127 degF/ft"
    inlet_temperature = "60 degF"
    flow_rate = "12600 gal/h"
    circulation_time = "44 h"
    pipe_inner_radius = "0.266 ft"
    ...

A hole section's ``friction`` is a plain number, a published fit by name
(``"kaarstad-glydril"``) or a table naming a family and its coefficients
(``{family = "linear", a = 0.23, b = 0.0013}``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, Literal

from numpy.typing import ArrayLike
from pydantic import BaseModel, BeforeValidator, ConfigDict, ValidationInfo, model_validator

from tdmon.config.common import _converter, check_friction
from tdmon.errors import ModelError
from tdmon.model.friction import FAMILIES, PUBLISHED_FRICTION_MODELS, FrictionModel
from tdmon.model.temperature import (
    CirculationParameters,
    Geotherm,
    WellboreTemperature,
    temperature_profile,
)

__all__ = ["FrictionModelConfig", "TemperatureConfig"]


def _reader(target: str, *, positive: bool) -> Callable[[Any, ValidationInfo], float]:
    """common's quantity reader (string with a unit, or from Python a number in ``target``;
    finite), plus an optional positivity check: radii, rates, times and properties must be
    above zero."""
    convert = _converter(target)

    def read(value: Any, info: ValidationInfo) -> float:
        number = convert(value, info)  # raises ValueError with the reason
        if positive and number <= 0.0:
            raise ValueError(f"must be positive, got {number:g} {target}")
        return number

    return read


def _field(target: str, positive: bool = True) -> BeforeValidator:
    return BeforeValidator(_reader(target, positive=positive))


Temperature = Annotated[float, _field("degC", positive=False)]
Gradient = Annotated[float, _field("degC/m", positive=False)]
FlowRate = Annotated[float, _field("m**3/s")]
Duration = Annotated[float, _field("s")]
Radius = Annotated[float, _field("m")]
Density = Annotated[float, _field("kg/m**3")]
SpecificHeat = Annotated[float, _field("J/(kg*K)")]
Conductivity = Annotated[float, _field("W/(m*K)")]
Viscosity = Annotated[float, _field("Pa*s")]
HeatTransferCoefficient = Annotated[float, _field("W/(m**2*K)")]

_CIRCULATION = ("inlet_temperature", "flow_rate", "circulation_time")
_ANALYTIC = ("pipe_outer_radius", "hole_radius", "fluid_density", "fluid_specific_heat",
             "formation_conductivity", "formation_specific_heat", "formation_density")
_FILM = ("pipe_inner_radius", "fluid_conductivity", "fluid_viscosity", "pipe_conductivity")


class TemperatureConfig(BaseModel):
    """The well file's ``[temperature]`` table (Table 10 of the thesis in SI).

    ``casing_radius`` defaults to ``hole_radius``; ``pipe_heat_transfer`` (U_p) and
    ``annulus_heat_transfer`` (U_a) are computed from the fluid and pipe properties unless both
    are given.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    model: Literal["geothermal", "apak", "apak-empirical", "numerical"] = "geothermal"
    surface_temperature: Temperature
    geothermal_gradient: Gradient
    inlet_temperature: Temperature | None = None
    flow_rate: FlowRate | None = None
    circulation_time: Duration | None = None
    pipe_inner_radius: Radius | None = None
    pipe_outer_radius: Radius | None = None
    hole_radius: Radius | None = None
    casing_radius: Radius | None = None
    fluid_density: Density | None = None
    fluid_specific_heat: SpecificHeat | None = None
    fluid_conductivity: Conductivity | None = None
    fluid_viscosity: Viscosity | None = None
    pipe_conductivity: Conductivity | None = None
    formation_conductivity: Conductivity | None = None
    formation_specific_heat: SpecificHeat | None = None
    formation_density: Density | None = None
    pipe_heat_transfer: HeatTransferCoefficient | None = None
    annulus_heat_transfer: HeatTransferCoefficient | None = None

    @model_validator(mode="after")
    def _inputs_of_the_model(self) -> TemperatureConfig:
        needed: tuple[str, ...] = ()
        if self.model != "geothermal":
            needed += _CIRCULATION
        if self.model in ("apak", "numerical"):
            needed += _ANALYTIC
            if self.pipe_heat_transfer is None or self.annulus_heat_transfer is None:
                needed += _FILM
        missing = [name for name in needed if getattr(self, name) is None]
        if missing:
            raise ValueError(f"model '{self.model}' needs {', '.join(missing)}")
        if self.model == "apak-empirical" and self.geothermal_gradient <= 0.0:
            raise ValueError("model 'apak-empirical' needs a positive geothermal_gradient")
        try:
            self.circulation()
        except ModelError as exc:  # e.g. pipe_inner_radius >= pipe_outer_radius
            raise ValueError(str(exc)) from None
        return self

    def geotherm(self) -> Geotherm:
        """The surface temperature [degC] and gradient [K/m] for the model layer."""
        return Geotherm(self.surface_temperature, self.geothermal_gradient)

    def circulation(self) -> CirculationParameters | None:
        """The circulation inputs for the model layer; None for the geothermal model."""
        if self.model == "geothermal":
            return None
        assert self.inlet_temperature is not None  # checked by the validator
        assert self.flow_rate is not None and self.circulation_time is not None
        return CirculationParameters(
            inlet_temperature=self.inlet_temperature,
            flow_rate=self.flow_rate,
            circulation_time=self.circulation_time,
            pipe_inner_radius=self.pipe_inner_radius,
            pipe_outer_radius=self.pipe_outer_radius,
            hole_radius=self.hole_radius,
            casing_radius=self.casing_radius if self.casing_radius is not None
            else self.hole_radius,
            fluid_density=self.fluid_density,
            fluid_specific_heat=self.fluid_specific_heat,
            fluid_conductivity=self.fluid_conductivity,
            fluid_viscosity=self.fluid_viscosity,
            pipe_conductivity=self.pipe_conductivity,
            formation_conductivity=self.formation_conductivity,
            formation_specific_heat=self.formation_specific_heat,
            formation_density=self.formation_density,
            pipe_heat_transfer=self.pipe_heat_transfer,
            annulus_heat_transfer=self.annulus_heat_transfer,
        )

    def profile(self, md: ArrayLike, survey_md: ArrayLike, survey_tvd: ArrayLike, *,
                total_md: float | None = None,
                inlet_temperature: float | None = None) -> WellboreTemperature:
        """Run the configured model (see :func:`tdmon.model.temperature.temperature_profile`).

        ``inlet_temperature`` [degC], e.g. a measured mud-in temperature, replaces the
        configured one.
        """
        return temperature_profile(self.model, md, survey_md, survey_tvd, self.geotherm(),
                                   self.circulation(), total_md=total_md,
                                   inlet_temperature=inlet_temperature)


class FrictionModelConfig(BaseModel):
    """A friction factor or a friction law mu(T), T in degC.

    Accepted forms: a number (constant mu), a published fit's name (see
    :data:`tdmon.model.friction.PUBLISHED_FRICTION_MODELS`), or a table with ``family`` and
    the family's coefficients (``{family = "linear", a = 0.23, b = 0.0013}``,
    ``{family = "polynomial", a0 = 0.25, a1 = 0.0009, a2 = -1e-6}``, ``{family = "constant",
    mu = 0.2}``) or ``{name = "kaarstad-glydril"}``.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    family: str
    coefficients: dict[str, float]
    name: str | None = None

    @model_validator(mode="before")
    @classmethod
    def _read(cls, raw: Any) -> Any:  # noqa: C901  (complex today; simplify when next touched)
        if isinstance(raw, bool):
            raise ValueError("expected a friction factor, a published fit's name or a table")
        if isinstance(raw, (int, float)):
            return {"family": "constant", "coefficients": {"mu": raw}}
        if isinstance(raw, str):
            return cls._published(raw.strip())
        if not isinstance(raw, dict):
            raise ValueError("expected a friction factor, a published fit's name or a table")
        if "coefficients" in raw:  # already in field form (e.g. model_dump round trip)
            return raw
        table = dict(raw)
        if "name" in table:
            if len(table) > 1:
                raise ValueError("a published fit's 'name' takes no other keys")
            return cls._published(str(table["name"]))
        if "family" not in table:
            raise ValueError(f"a friction table needs 'family' (one of {', '.join(FAMILIES)}) "
                             "or 'name'")
        family = table.pop("family")
        coefficients: dict[str, float] = {}
        for key, value in table.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"friction coefficient '{key}' must be a number, got {value!r}")
            coefficients[str(key)] = float(value)
        return {"family": family, "coefficients": coefficients}

    @staticmethod
    def _published(name: str) -> dict[str, Any]:
        try:
            return {"family": "constant", "coefficients": {"mu": float(name)}}
        except ValueError:
            pass
        model = PUBLISHED_FRICTION_MODELS.get(name)
        if model is None:
            raise ValueError(f"unknown published friction model '{name}' (known: "
                             f"{', '.join(PUBLISHED_FRICTION_MODELS)})")
        return {"family": model.family, "coefficients": dict(model.coefficients), "name": name}

    @model_validator(mode="after")
    def _valid_law(self) -> FrictionModelConfig:
        try:
            self.friction_model()
        except ModelError as exc:
            raise ValueError(str(exc)) from None
        if self.family == "constant":
            check_friction(self.coefficients["mu"])  # the one rule (config.common)
        return self

    def friction_model(self) -> FrictionModel:
        """The law as a :class:`~tdmon.model.friction.FrictionModel`."""
        return FrictionModel(self.family, self.coefficients)

    def constant_value(self) -> float | None:
        """The friction factor when it does not depend on temperature, else None."""
        return self.coefficients["mu"] if self.family == "constant" else None
