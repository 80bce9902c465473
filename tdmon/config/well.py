"""The well file: survey, hole sections, drill string, fluid, limits and temperature, as TOML.

A dimensional quantity is a string with a unit ("0.3 kN/m", "9950 ft", "13 ppg", "655 kN"): a
plain number is refused, since the unit it was meant in cannot be known. Dimensionless keys
(friction factors, safety factors) are plain numbers. ``load_well(path)`` validates the file
and ``WellConfig.to_model()`` turns it into the model layer's :class:`tdmon.model.well.Well`.
Every problem is a :class:`tdmon.errors.ConfigError` naming the file, the key and the reason.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Annotated, Any, Final, Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import (
    AfterValidator,
    BeforeValidator,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from tdmon.config.common import (
    CrossFieldError,
    Density,
    Diameter,
    Dimensionless,
    Force,
    Length,
    Moment,
    Pressure,
    StrictModel,
    WeightPerLength,
    load_model,
    quantity,
)
from tdmon.config.limits import (
    MAX_ELEMENTS,
    MAX_MEASURED_DEPTH,
    MAX_SURVEY_FILE_BYTES,
    MAX_SURVEY_STATIONS,
)
from tdmon.config.thermal import FrictionModelConfig, TemperatureConfig
from tdmon.errors import ConfigError, ModelError
from tdmon.model.friction import local_friction
from tdmon.model.hookload_sensor import HookloadSensor, SensorLocation
from tdmon.model.hydraulics import WellHydraulics, nozzle_area
from tdmon.model.rheology import Rheology, from_fann, from_pv_yp
from tdmon.model.string import STEEL_DENSITY, DrillString, StringComponent, weight_per_length
from tdmon.model.survey import Survey, minimum_curvature
from tdmon.model.temperature import WellboreTemperature
from tdmon.model.well import (
    Fluid,
    HoleSection,
    LimitSettings,
    Well,
    hole_grid,
    section_friction,
)

_LENGTH = quantity("m")


class WellInfo(StrictModel):
    name: str = ""
    element_length: Length = Field(default=10.0, gt=0)
    block_weight: Force = Field(default=0.0, ge=0)


def _check_station_count(count: int) -> None:
    if count < 2:
        raise ValueError(f"{count} station{'' if count == 1 else 's'}: a survey needs at least "
                         "two (the surface and the bottom of the hole)")
    if count > MAX_SURVEY_STATIONS:
        raise ValueError(f"{count} stations, more than the {MAX_SURVEY_STATIONS} a survey may "
                         "hold (closer than any element length of the model)")


def _depth_reason(value: float) -> str:
    return (f"{value:g} m is deeper than {MAX_MEASURED_DEPTH:g} m, the deepest measured depth "
            "accepted (the longest wells reach about 15 km)")


def _check_depth(value: float) -> float:
    if value > MAX_MEASURED_DEPTH:
        raise ValueError(_depth_reason(value))
    return value


#: A measured depth or length along the hole, at most :data:`MAX_MEASURED_DEPTH`
Depth = Annotated[Length, AfterValidator(_check_depth)]


class SurveyConfig(StrictModel):
    """Survey stations, inline (``stations = [[md, inclination, azimuth], ...]``) or from a
    CSV file (path relative to the well file).

    The angles' unit is ``angle_unit`` ("deg" or "rad") or, for a CSV file, the suffix of the
    angle columns (``incl_deg``, ``azi_rad``). Without either, degrees are assumed, unless the
    stations look like radians (see :func:`looks_like_radians`): then the file is refused.
    """

    stations: list[tuple[float, float, float]] | None = None
    file: Path | None = None
    angle_unit: Literal["deg", "rad"] | None = None
    md_unit: str = "m"
    md_column: str = "md_m"
    inclination_column: str = "incl_deg"
    azimuth_column: str = "azi_deg"

    @field_validator("stations")
    @classmethod
    def _finite(
        cls, stations: list[tuple[float, float, float]] | None
    ) -> list[tuple[float, float, float]] | None:
        if stations is not None:
            _check_station_count(len(stations))
        for index, station in enumerate(stations or []):
            if not all(math.isfinite(value) for value in station):
                raise ValueError(f"station {index} {list(station)} holds a NaN or infinite value")
        return stations

    @model_validator(mode="after")
    def _one_source(self) -> SurveyConfig:
        if (self.stations is None) == (self.file is None):
            raise ValueError("give either 'stations' or 'file', not both or neither")
        return self


class HoleSectionConfig(StrictModel):
    name: str = ""
    kind: Literal["cased", "open"]
    top: Depth = Field(ge=0)
    bottom: Depth
    diameter: Diameter = Field(gt=0)
    friction: FrictionModelConfig | None = None

    @model_validator(mode="after")
    def _ordered(self) -> HoleSectionConfig:
        if self.bottom <= self.top:
            raise ValueError(f"bottom ({self.bottom:g} m) must be below top ({self.top:g} m)")
        return self


#: ``length = "rest"``: the top component reaches the surface with the bit at the bottom of the
#: hole (its length is the hole's depth less the other components)
REST: Final = "rest"


def _length_or_rest(value: Any, info: ValidationInfo) -> float | str:
    if isinstance(value, str) and value.strip().lower() == REST:
        return REST
    return cast(float, _LENGTH.func(value, info))  # type: ignore[call-arg]


class StringComponentConfig(StrictModel):
    name: str = ""
    length: Annotated[float | str, BeforeValidator(_length_or_rest)]
    # both may be left out when the weight is buoyed (buoyed_weight, or [fluid]
    # buoyancy_factor with a weight in air) and the torque radius known (tool_joint_od)
    od: Diameter | None = Field(default=None, gt=0)
    id: Diameter | None = Field(default=None, ge=0)
    weight: WeightPerLength | None = Field(default=None, gt=0)
    buoyed_weight: WeightPerLength | None = Field(default=None, gt=0)
    tool_joint_od: Diameter | None = Field(default=None, gt=0)
    yield_strength: Pressure | None = Field(default=None, gt=0)
    makeup_torque: Moment | None = Field(default=None, gt=0)
    youngs_modulus: Pressure = Field(default=2.06e11, gt=0)

    @model_validator(mode="after")
    def _consistent(self) -> StringComponentConfig:
        if isinstance(self.length, float) and not self.length > 0:
            raise CrossFieldError("length", f"must be > 0 m or \"{REST}\", got {self.length:g}")
        if isinstance(self.length, float):
            try:
                _check_depth(self.length)
            except ValueError as exc:
                raise CrossFieldError("length", str(exc)) from None
        if (self.od is None) != (self.id is None):
            raise CrossFieldError("od" if self.od is None else "id",
                                  "missing key (give both od and id, or neither with a buoyed "
                                  "weight)")
        if self.od is not None and self.id is not None and self.id >= self.od:
            raise ValueError(f"id ({self.id:g} m) must be smaller than od ({self.od:g} m)")
        if self.weight is not None and self.buoyed_weight is not None:
            raise ValueError("give 'weight' (in air) or 'buoyed_weight', not both")
        return self


class StringDefaultsConfig(StrictModel):
    """``[string_defaults]``: values every ``[[string]]`` component takes unless it gives its
    own: ``tool_joint_od`` (the torque radius is half of it)."""

    tool_joint_od: Diameter | None = Field(default=None, gt=0)


class FluidConfig(StrictModel):
    """``[fluid]``: ``density`` buoys weights in air (eq 35, eq 36 with ``inside_density``);
    ``buoyancy_factor`` replaces eq 35 for every weight in air. ``density`` may be left out when
    every weight is buoyed; with ``buoyancy_factor`` alone it is ``(1 - factor) x 7850 kg/m3``
    (eq 35 read backwards)."""

    density: Density | None = Field(default=None, gt=0)
    inside_density: Density | None = Field(default=None, gt=0)
    buoyancy_factor: Dimensionless | None = Field(default=None, gt=0, le=1)


Area = Annotated[float, quantity("m^2")]
Viscosity = Annotated[float, quantity("Pa*s")]


class HydraulicsConfig(StrictModel):
    """``[hydraulics]``: the mud's rheology, the bit's nozzles, a float valve and the open
    hole's pressure window (docs/hydraulics.md; :class:`tdmon.model.hydraulics.WellHydraulics`).

    The rheology is the Fann 600 and 300 rpm dial readings (``fann_600``, ``fann_300``) or the
    plastic viscosity and yield point (``plastic_viscosity``, ``yield_point``), read into
    ``rheology_model`` (``bingham`` or ``power_law``). Without either pair the rheology is not
    known and no viscous drag, surge or swab is modelled. The bit's flow area is ``nozzles``
    (their diameters) or ``nozzle_area`` (the total flow area), not both."""

    rheology_model: Literal["bingham", "power_law"] = "bingham"
    fann_600: Dimensionless | None = Field(default=None, gt=0)
    fann_300: Dimensionless | None = Field(default=None, gt=0)
    plastic_viscosity: Viscosity | None = Field(default=None, gt=0)
    yield_point: Pressure | None = Field(default=None, ge=0)
    nozzles: list[Diameter] | None = Field(default=None, min_length=1)
    nozzle_area: Area | None = Field(default=None, gt=0)
    discharge_coefficient: Dimensionless = Field(default=0.95, gt=0, le=1)
    float_valve: bool = False
    pump_open_area: Area = Field(default=0.0, ge=0)
    pore_density: Density | None = Field(default=None, gt=0)
    fracture_density: Density | None = Field(default=None, gt=0)

    @field_validator("nozzles")
    @classmethod
    def _positive(cls, nozzles: list[float] | None) -> list[float] | None:
        if nozzles is not None and not all(d > 0.0 for d in nozzles):
            raise ValueError(f"every nozzle diameter must be > 0 m, got {nozzles}")
        return nozzles

    @model_validator(mode="after")
    def _pairs(self) -> HydraulicsConfig:
        for first, second in (("fann_600", "fann_300"), ("plastic_viscosity", "yield_point")):
            if (getattr(self, first) is None) != (getattr(self, second) is None):
                missing = first if getattr(self, first) is None else second
                raise CrossFieldError(missing, f"missing key (give both {first} and {second})")
        if self.fann_600 is not None and self.plastic_viscosity is not None:
            raise ValueError("give the Fann readings or plastic_viscosity and yield_point, "
                             "not both")
        if self.nozzles is not None and self.nozzle_area is not None:
            raise ValueError("give 'nozzles' or 'nozzle_area', not both")
        if (self.pore_density is not None and self.fracture_density is not None
                and not self.pore_density < self.fracture_density):
            raise ValueError(f"pore_density ({self.pore_density:g} kg/m3) must be below "
                             f"fracture_density ({self.fracture_density:g} kg/m3)")
        return self

    def rheology(self) -> Rheology | None:
        """The mud's rheology, or None when the file gives none."""
        if self.fann_600 is not None and self.fann_300 is not None:
            return from_fann(self.fann_600, self.fann_300, self.rheology_model)
        if self.plastic_viscosity is not None and self.yield_point is not None:
            return from_pv_yp(self.plastic_viscosity, self.yield_point, self.rheology_model)
        return None

    def to_model(self) -> WellHydraulics:
        area = nozzle_area(self.nozzles) if self.nozzles is not None else self.nozzle_area
        return WellHydraulics(rheology=self.rheology(), nozzle_area=area,
                              float_valve=self.float_valve,
                              discharge_coefficient=self.discharge_coefficient,
                              pump_open_area=self.pump_open_area,
                              pore_density=self.pore_density,
                              fracture_density=self.fracture_density)


class LimitsConfig(StrictModel):
    safety_factor: Dimensionless = Field(default=1.0, ge=1.0)
    helical_factor: Dimensionless = Field(default=math.sqrt(2.0), gt=1.0)


class HookloadSensorConfig(StrictModel):
    """``[hookload_sensor]``: how the rig's hook-load channel reads the load on the hook
    (docs/configuration.md, "The hook-load sensor"; :mod:`tdmon.model.hookload_sensor`).

    ``location``: ``deadline`` (a dead-line anchor load cell times the lines: hoisting reads
    low and lowering high by the sheave friction), ``hook`` (a load pin at the hook) or
    ``top_drive`` (a load cell in the top drive). ``lines``: lines strung between crown and
    block. ``efficiency``: efficiency per turning sheave (API RP 9B's design factor 1.04 gives
    0.9615); ``above_sensor``: travelling equipment above a pin or load cell, which it does not
    weigh. Left out: a sensor that reads the load on the hook."""

    location: Literal["deadline", "hook", "top_drive"] = "hook"
    lines: int = Field(default=10, ge=1, le=24)
    efficiency: float = Field(default=1.0, ge=0.8, le=1.0)
    above_sensor: Force = Field(default=0.0, ge=0)

    @model_validator(mode="after")
    def _consistent(self) -> HookloadSensorConfig:
        if self.location == "deadline" and self.above_sensor != 0.0:
            raise ValueError("a deadline sensor weighs all the travelling equipment: "
                             "above_sensor applies to 'hook' and 'top_drive' only")
        return self

    def to_model(self) -> HookloadSensor:
        return HookloadSensor(SensorLocation(self.location), self.lines, self.efficiency,
                              self.above_sensor)


class WellConfig(StrictModel):
    """The whole well file."""

    well: WellInfo = WellInfo()
    survey: SurveyConfig
    hole: list[HoleSectionConfig] = Field(min_length=1)
    string: list[StringComponentConfig] = Field(min_length=1)
    string_defaults: StringDefaultsConfig = StringDefaultsConfig()
    fluid: FluidConfig = FluidConfig()
    hydraulics: HydraulicsConfig = HydraulicsConfig()
    limits: LimitsConfig = LimitsConfig()
    temperature: TemperatureConfig | None = None
    hookload_sensor: HookloadSensorConfig = HookloadSensorConfig()

    @field_validator("hole")
    @classmethod
    def _sections_in_order(cls, hole: list[HoleSectionConfig]) -> list[HoleSectionConfig]:
        for upper, lower in itertools.pairwise(hole):
            if lower.top < upper.bottom - 1e-6:
                raise ValueError(
                    f"sections overlap: '{lower.name or lower.kind}' starts at {lower.top:g} m, "
                    f"above the bottom of the one before ({upper.bottom:g} m)"
                )
        return hole

    @model_validator(mode="after")
    def _elements_bounded(self) -> WellConfig:
        elements = self.hole[-1].bottom / self.well.element_length
        if elements > MAX_ELEMENTS:
            raise CrossFieldError(
                "well.element_length",
                f"{self.well.element_length:g} m makes {elements:.3g} elements down to "
                f"{self.hole[-1].bottom:g} m, more than the {MAX_ELEMENTS} the model marches "
                "for every hook load")
        return self

    @model_validator(mode="after")
    def _string_complete(self) -> WellConfig:
        last = len(self.string) - 1
        for index, item in enumerate(self.string):
            key = f"string[{index}]"
            if item.length == REST and index != last:
                raise CrossFieldError(f"{key}.length", f"only the top (last) component can be "
                                      f"\"{REST}\": it is the one cut to length")
            buoyed = item.buoyed_weight is not None or self.fluid.buoyancy_factor is not None
            if not buoyed and self.fluid.density is None:
                raise CrossFieldError("fluid.density", f"missing key ({key} has a weight in air "
                                      "to buoy; or give [fluid] buoyancy_factor)")
            if item.od is None:
                if item.weight is None and item.buoyed_weight is None:
                    raise CrossFieldError(f"{key}.od", "missing key (no weight given: it comes "
                                          "from od and id)")
                if item.weight is not None and self.fluid.buoyancy_factor is None:
                    raise CrossFieldError(f"{key}.od", "missing key (a weight in air is buoyed "
                                          "with od and id; or give buoyed_weight, or [fluid] "
                                          "buoyancy_factor)")
                if item.tool_joint_od is None and self.string_defaults.tool_joint_od is None:
                    raise CrossFieldError(f"{key}.tool_joint_od", "missing key (without od the "
                                          "torque radius comes from it; or give it once in "
                                          "[string_defaults])")
        return self

    @model_validator(mode="after")
    def _resolve_paths(self, info: ValidationInfo) -> WellConfig:
        base = (info.context or {}).get("base_dir")
        if base is not None and self.survey.file is not None and not self.survey.file.is_absolute():
            object.__setattr__(self.survey, "file", Path(base) / self.survey.file)
        return self

    # -- adapters to the model layer ------------------------------------------------------

    def to_model(self, source: str | Path = "<well>") -> Well:
        """The model layer's :class:`Well`; ``source`` names the file in error messages."""
        survey = self._survey(str(source))
        sections = tuple(
            HoleSection(
                top=section.top,
                bottom=section.bottom,
                diameter=section.diameter,
                kind=section.kind,
                friction=section.friction.constant_value() if section.friction else None,
            )
            for section in self.hole
        )
        components = self._components(str(source), sections[-1].bottom)
        if sections[-1].bottom > survey.md[-1] + 1e-6:
            raise ConfigError(
                str(source),
                f"hole[{len(sections) - 1}].bottom",
                f"{sections[-1].bottom:g} m is below the last survey station "
                f"({survey.md[-1]:g} m)",
            )
        return Well(
            survey=survey,
            string=DrillString(components),
            sections=sections,
            fluid=Fluid(density=self._fluid_density(), inside_density=self.fluid.inside_density),
            block_weight=self.well.block_weight,
            element_length=self.well.element_length,
            limits=LimitSettings(
                safety_factor=self.limits.safety_factor,
                helical_factor=self.limits.helical_factor,
            ),
            name=self.well.name,
            hookload_sensor=self.hookload_sensor.to_model(),
            hydraulics=self._hydraulics(str(source)),
        )

    def _hydraulics(self, source: str) -> WellHydraulics:
        try:
            return self.hydraulics.to_model()
        except ModelError as exc:  # Fann readings no fluid of the model fits
            raise ConfigError(source, "hydraulics", str(exc)) from exc

    def _components(self, source: str, hole_bottom: float) -> tuple[StringComponent, ...]:
        """The model's components: "rest" resolved, the string defaults and the buoyancy
        factor applied."""
        fixed = sum(item.length for item in self.string if isinstance(item.length, float))
        factor = self.fluid.buoyancy_factor
        components = []
        for index, item in enumerate(self.string):
            length = item.length
            if not isinstance(length, float):
                length = hole_bottom - fixed
                if not length > 0.0:
                    raise ConfigError(source, f"string[{index}].length",
                                      f"\"{REST}\" leaves {length:g} m: the other components "
                                      f"({fixed:g} m) reach the bottom of the hole "
                                      f"({hole_bottom:g} m)")
            buoyed = item.buoyed_weight
            if buoyed is None and factor is not None:
                in_air = (item.weight if item.weight is not None
                          else float(weight_per_length(item.od or 0.0, item.id or 0.0)))
                buoyed = factor * in_air
            try:
                components.append(StringComponent(
                    name=item.name, length=length,
                    outer_diameter=math.nan if item.od is None else item.od,
                    inner_diameter=math.nan if item.id is None else item.id,
                    weight_in_air=item.weight if buoyed is None else None,
                    buoyed_weight=buoyed,
                    tool_joint_diameter=item.tool_joint_od or self.string_defaults.tool_joint_od,
                    yield_strength=item.yield_strength, makeup_torque=item.makeup_torque,
                    youngs_modulus=item.youngs_modulus))
            except ModelError as exc:
                raise ConfigError(source, f"string[{index}]", str(exc)) from exc
        return tuple(components)

    def _fluid_density(self) -> float:
        """[kg/m3]: given, else from the buoyancy factor (eq 35), else NaN (every weight is
        buoyed; only the limits' pressure terms would need it)."""
        if self.fluid.density is not None:
            return self.fluid.density
        if self.fluid.buoyancy_factor is not None:
            return (1.0 - self.fluid.buoyancy_factor) * STEEL_DENSITY
        return math.nan

    def element_friction(self, well: Well, source: str | Path = "<well>") -> NDArray[np.float64]:
        """The friction factor of every element of ``hole_grid(well)`` from the sections'
        friction (a number or a law mu(T)); a law mu(T) is evaluated at the annulus temperature
        of the ``[temperature]`` model at the element's depth (the thesis's local friction
        factor, Case 2 and 3), with the mud circulating at the bottom of the hole."""
        grid = hole_grid(well)
        if all(section.friction is None or section.friction.constant_value() is not None
               for section in self.hole):
            try:
                return section_friction(well, grid)
            except ModelError as exc:
                raise ConfigError(str(source), "hole", str(exc)) from exc
        missing = [i for i, section in enumerate(self.hole) if section.friction is None]
        if missing:
            raise ConfigError(str(source), f"hole[{missing[0]}].friction", "missing key")
        if self.temperature is None:
            raise ConfigError(str(source), "temperature",
                              "a section's friction depends on temperature but the well file "
                              "has no [temperature] table")
        profile = self.annulus_temperature(well, grid.element_mid_md, source)
        laws = [section.friction.friction_model() for section in self.hole if section.friction]
        try:
            return local_friction(laws, grid.element_section, profile.annulus)
        except ModelError as exc:
            raise ConfigError(str(source), "hole", str(exc)) from exc

    def annulus_temperature(
        self, well: Well, md: NDArray[np.float64], source: str | Path = "<well>"
    ) -> WellboreTemperature:
        """The ``[temperature]`` model at ``md``, circulating at the bottom of the hole."""
        if self.temperature is None:
            raise ConfigError(str(source), "temperature", "missing table")
        # the hole grid, not the survey stations, as the path: the temperature models
        # interpolate TVD linearly between the points they are given
        grid = hole_grid(well)
        try:
            return self.temperature.profile(md, grid.md, grid.tvd,
                                            total_md=well.sections[-1].bottom)
        except ModelError as exc:
            raise ConfigError(str(source), "temperature", str(exc)) from exc

    def _survey(self, source: str) -> Survey:
        config = self.survey
        if config.stations is not None:
            table = np.asarray(config.stations, dtype=float)
            key = "survey.stations"
        else:
            assert config.file is not None
            table = _read_survey_csv(source, config)
            key = f"survey.file ({config.file})"
        scale = 1.0 if config.md_unit == "m" else _md_scale(source, config.md_unit)
        deepest = float(np.max(table[:, 0])) * scale if len(table) else 0.0
        if deepest > MAX_MEASURED_DEPTH:
            raise ConfigError(source, key, _depth_reason(deepest))
        unit = _angle_unit(source, config)
        if unit is None and looks_like_radians(table[:, 1], table[:, 2]):
            raise ConfigError(
                source, key,
                f"the angles look like radians (inclination at most "
                f"{np.max(table[:, 1]):.3g}, azimuth at most {np.max(np.abs(table[:, 2])):.3g}); "
                "say which unit they are in: angle_unit = \"rad\" or \"deg\" in [survey]")
        if unit == "rad":
            table = np.column_stack([table[:, 0], np.degrees(table[:, 1:3])])
        try:
            return minimum_curvature(table[:, 0] * scale, table[:, 1], table[:, 2])
        except ModelError as exc:
            raise ConfigError(source, key, str(exc)) from exc


#: The largest inclination of a survey in radians (pi: 0-180 deg), with a rounding margin.
_RADIAN_INCLINATION_MAX = math.pi + 1e-6
#: The largest |azimuth| of a survey in radians (2 pi), with a rounding margin.
_RADIAN_AZIMUTH_MAX = 2.0 * math.pi + 1e-6


def looks_like_radians(inclination: ArrayLike, azimuth: ArrayLike) -> bool:
    """Whether survey angles given without a unit are likely radians rather than degrees.

    True when some inclination is above zero (a vertical well reads the same in both), every
    inclination is at most pi and every |azimuth| at most 2 pi. In degrees that is a well that
    never leaves 3.2 deg of vertical and whose azimuths all lie within 6.3 deg of north: a
    surveyed near-vertical hole wanders in azimuth, so a real degree survey almost never
    passes; one that does only has to state ``angle_unit = "deg"``.
    """
    inc = np.asarray(inclination, dtype=float)
    azi = np.abs(np.asarray(azimuth, dtype=float))
    if inc.size == 0 or not np.isfinite(inc).all() or not np.isfinite(azi).all():
        return False
    return bool(inc.max() > 0.0 and inc.max() <= _RADIAN_INCLINATION_MAX
                and azi.max() <= _RADIAN_AZIMUTH_MAX)


def _column_unit(column: str) -> str | None:
    name = column.strip().lower()
    for unit, suffixes in (("deg", ("_deg", "[deg]", "(deg)", " deg")),
                           ("rad", ("_rad", "[rad]", "(rad)", " rad"))):
        if name.endswith(suffixes):
            return unit
    return None


def _angle_unit(source: str, config: SurveyConfig) -> str | None:
    """The stated angle unit: ``angle_unit``, else the CSV angle columns' suffix."""
    if config.file is None:
        return config.angle_unit
    stated = {_column_unit(config.inclination_column), _column_unit(config.azimuth_column)}
    stated.discard(None)
    if len(stated) > 1:
        raise ConfigError(source, "survey.inclination_column",
                          f"'{config.inclination_column}' and '{config.azimuth_column}' name "
                          "different angle units")
    from_columns = stated.pop() if stated else None
    if config.angle_unit is not None and from_columns not in (None, config.angle_unit):
        raise ConfigError(source, "survey.angle_unit",
                          f"'{config.angle_unit}' contradicts the column "
                          f"'{config.inclination_column}'")
    return config.angle_unit or from_columns


def _md_scale(source: str, unit: str) -> float:
    from tdmon.units import to_unit

    try:
        return to_unit(1.0, unit, "m")
    except ValueError as exc:
        raise ConfigError(source, "survey.md_unit", str(exc)) from exc


def _read_survey_csv(source: str, config: SurveyConfig) -> np.ndarray[Any, np.dtype[np.float64]]:
    assert config.file is not None
    import pandas as pd  # 0.4 s and pyarrow: only a well with a survey file pays it

    columns = [config.md_column, config.inclination_column, config.azimuth_column]
    try:
        size = config.file.stat().st_size
    except OSError:
        size = 0  # pandas names the problem below
    if size > MAX_SURVEY_FILE_BYTES:
        raise ConfigError(source, "survey.file", f"{config.file} holds {size} bytes, more than "
                          f"the {MAX_SURVEY_FILE_BYTES // 1024 ** 2} MiB a survey file may hold")
    try:
        frame = pd.read_csv(config.file)
    except FileNotFoundError as exc:
        raise ConfigError(source, "survey.file", f"no such file: {config.file}") from exc
    except (OSError, pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise ConfigError(source, "survey.file", f"cannot read {config.file}: {exc}") from exc
    missing = [column for column in columns if column not in frame.columns]
    if missing:
        raise ConfigError(
            source,
            "survey.file",
            f"{config.file} has no column {', '.join(missing)} "
            f"(columns: {', '.join(map(str, frame.columns))})",
        )
    try:
        _check_station_count(len(frame))
    except ValueError as exc:
        raise ConfigError(source, "survey.file", f"{config.file}: {exc}") from None
    try:
        return frame[columns].to_numpy(dtype=float)
    except ValueError as exc:
        raise ConfigError(source, "survey.file", f"non-numeric value in {config.file}") from exc


def load_well(path: str | Path) -> WellConfig:
    """Read and validate a well file (paths inside it are relative to the file)."""
    path = Path(path)
    return load_model(WellConfig, path, context={"base_dir": path.parent})


def load_well_model(path: str | Path) -> Well:
    """Read a well file and build the model layer's :class:`Well` from it."""
    return load_well(path).to_model(path)


def load_well_with_friction(path: str | Path) -> tuple[Well, NDArray[np.float64]]:
    """The well and the friction factor of each of its hole-grid elements (see
    :meth:`WellConfig.element_friction`)."""
    config = load_well(path)
    well = config.to_model(path)
    return well, config.element_friction(well, path)
