"""The scenario TOML of ``tdmon simulate``: a well file, a rig programme, sampling, noise, faults.

``load_scenario(path)`` validates the file (pydantic) and returns a :class:`ScenarioConfig`;
``ScenarioConfig.to_scenario(path)`` reads the well file it names and builds the pure
:class:`tdmon.replay.session.Scenario` the generator takes. Quantities are numbers in SI or
strings with a unit (``"28 m"``, ``"120 rpm"``, ``"2000 L/min"``, ``"3 min"``, ``"150 kN"``).
Every problem is a :class:`tdmon.errors.ConfigError` naming the file, the key and the reason.
See docs/replays.md for the keys.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BeforeValidator, Field, field_validator, model_validator

from tdmon.channels import validate_prefix
from tdmon.config.common import StrictModel, load_model
from tdmon.config.well import WellConfig, load_well
from tdmon.errors import ConfigError, ModelError
from tdmon.ingest.decode import parse_time
from tdmon.model.friction import FrictionModel, local_friction
from tdmon.model.well import Well, hole_grid
from tdmon.replay.session import (
    CHANNELS,
    FrictionAnomaly,
    NoiseSettings,
    Phase,
    RigSettings,
    Scenario,
    SensorFault,
    TightSpot,
)
from tdmon.units import parse_quantity

__all__ = ["ScenarioConfig", "load_scenario", "load_scenario_model"]


def _reader(target: str) -> Callable[[Any], float]:
    def read(value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise ValueError(f"expected a number in {target} or a string with a unit")
        number = parse_quantity(value, target)
        if number != number or abs(number) == float("inf"):
            raise ValueError("must be a finite number")
        return number

    return read


Length = Annotated[float, BeforeValidator(_reader("m"))]
Speed = Annotated[float, BeforeValidator(_reader("m/s"))]
Seconds = Annotated[float, BeforeValidator(_reader("s"))]
Force = Annotated[float, BeforeValidator(_reader("N"))]
Pressure = Annotated[float, BeforeValidator(_reader("Pa"))]
Rotation = Annotated[float, BeforeValidator(_reader("rad/s"))]
Flow = Annotated[float, BeforeValidator(_reader("m**3/s"))]
Fraction = Annotated[float, BeforeValidator(_reader("dimensionless"))]

_TIMED = ("static", "circulate", "rotate", "slips")


class ScenarioInfo(StrictModel):
    name: str = ""
    well: Path
    seed: int = 0
    start: float | str = "2024-01-01T00:00:00Z"
    prefix: str = "sim/rig"
    method: Literal["soft-string", "aadnoy"] = "soft-string"
    bit_depth: Length = Field(gt=0)
    hole_depth: Length | None = None
    block_position: Length | None = None

    @field_validator("start")
    @classmethod
    def _time(cls, value: float | str) -> float:
        parsed = parse_time(value)
        if isinstance(parsed, str):
            raise ValueError(parsed.replace("'t'", "start"))
        return parsed

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, value: str) -> str:
        return validate_prefix(value)


class AnomalyConfig(StrictModel):
    top: Length
    bottom: Length
    delta_mu: float

    @model_validator(mode="after")
    def _ordered(self) -> AnomalyConfig:
        if self.bottom <= self.top:
            raise ValueError(f"bottom ({self.bottom:g} m) must be below top ({self.top:g} m)")
        return self


class FrictionConfig(StrictModel):
    temperature_model: Literal["well", "geothermal"] = "well"
    anomaly: list[AnomalyConfig] = Field(default_factory=list)


class TightSpotConfig(StrictModel):
    md: Length = Field(gt=0)
    length: Length = Field(default=5.0, gt=0)
    force: Force = Field(gt=0)


class RigConfig(StrictModel):
    stand_length: Length = Field(default=28.0, gt=1)
    block_low: Length = Field(default=2.0, ge=0)
    spp_reference: Pressure = Field(default=150e5, ge=0)
    flow_reference: Flow = Field(default=2000.0 / 60000.0, gt=0)
    bit_torque_factor: Length = Field(default=0.02, ge=0)
    latency: Seconds = Field(default=0.2, ge=0)
    break_over: Force = Field(default=0.0, ge=0)
    break_over_time: Seconds = Field(default=3.0, gt=0)


class SamplingConfig(StrictModel):
    interval: Seconds = Field(default=5.0, gt=0, le=60)
    channels: list[str] = Field(default_factory=lambda: list(CHANNELS))
    intervals: dict[str, Annotated[float, BeforeValidator(_reader("s")), Field(gt=0, le=60)]] = \
        Field(default_factory=dict)

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: list[str]) -> list[str]:
        unknown = [c for c in channels if c not in CHANNELS]
        if unknown:
            raise ValueError(f"unknown channel '{unknown[0]}' (one of {', '.join(CHANNELS)})")
        return channels

    @model_validator(mode="after")
    def _overrides_known(self) -> SamplingConfig:
        unknown = [c for c in self.intervals if c not in self.channels]
        if unknown:
            raise ValueError(f"interval given for '{unknown[0]}', which is not in channels")
        return self


class NoiseConfig(StrictModel):
    relative: Fraction = Field(default=0.0, ge=0)
    absolute: float = Field(default=0.0, ge=0)
    spike_rate: Fraction = Field(default=0.0, ge=0, le=1)
    spike_size: Fraction = Field(default=0.2, ge=0)
    missing_rate: Fraction = Field(default=0.0, ge=0, lt=1)
    clock_jitter: Seconds = Field(default=0.0, ge=0)


class NoiseTable(NoiseConfig):
    """Defaults for every channel, and ``[noise.channels.<name>]`` overrides (merged)."""

    channels: dict[str, dict[str, Any]] = Field(default_factory=dict)

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
        for name, table in channels.items():
            if name not in CHANNELS:
                raise ValueError(f"unknown channel '{name}' (one of {', '.join(CHANNELS)})")
            NoiseConfig.model_validate(table)
        return channels

    def settings(self, channel: str) -> NoiseSettings:
        base = self.model_dump(exclude={"channels"})
        merged = NoiseConfig.model_validate({**base, **self.channels.get(channel, {})})
        return NoiseSettings(**merged.model_dump())


class FaultConfig(StrictModel):
    kind: Literal["stuck", "dropout"]
    channels: list[str] = Field(min_length=1)
    start: Seconds = Field(ge=0)
    duration: Seconds = Field(gt=0)

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: list[str]) -> list[str]:
        return SamplingConfig._known(channels)


class PhaseConfig(StrictModel):
    kind: Literal["static", "circulate", "rotate", "slips", "trip_out", "trip_in", "ream",
                  "back_ream", "drill"]
    duration: Seconds = Field(default=0.0, ge=0)
    to: Length | None = None
    speed: Speed | None = Field(default=None, gt=0)
    rop: Speed | None = Field(default=None, gt=0)
    rpm: Rotation = Field(default=0.0, ge=0)
    flow: Flow = Field(default=0.0, ge=0)
    wob: Force = Field(default=0.0, ge=0)
    slips_time: Seconds = Field(default=60.0, gt=0)

    @model_validator(mode="after")
    def _complete(self) -> PhaseConfig:
        if self.kind in _TIMED:
            if self.duration <= 0:
                raise ValueError(f"a '{self.kind}' phase needs a positive duration")
            if self.kind == "rotate" and self.rpm <= 0:
                raise ValueError("a 'rotate' phase needs rpm")
            if self.kind == "circulate" and self.flow <= 0:
                raise ValueError("a 'circulate' phase needs flow")
            return self
        if self.to is None:
            raise ValueError(f"a '{self.kind}' phase needs 'to'")
        if self.kind == "drill":
            if self.rop is None or self.wob <= 0 or self.rpm <= 0:
                raise ValueError("a 'drill' phase needs rop, wob and rpm")
        elif self.speed is None:
            raise ValueError(f"a '{self.kind}' phase needs speed")
        if self.kind in ("ream", "back_ream") and self.rpm <= 0:
            raise ValueError(f"a '{self.kind}' phase needs rpm")
        return self

    def to_phase(self) -> Phase:
        speed = self.rop if self.kind == "drill" else self.speed
        return Phase(kind=self.kind, duration=self.duration, to=self.to, speed=speed or 0.0,
                     rpm=self.rpm, flow=self.flow, wob=self.wob, slips_time=self.slips_time)


class ScenarioConfig(StrictModel):
    """The whole scenario file."""

    scenario: ScenarioInfo
    friction: FrictionConfig = FrictionConfig()
    tight_spot: list[TightSpotConfig] = Field(default_factory=list)
    rig: RigConfig = RigConfig()
    sampling: SamplingConfig = SamplingConfig()
    noise: NoiseTable = NoiseTable()
    fault: list[FaultConfig] = Field(default_factory=list)
    phase: list[PhaseConfig] = Field(min_length=1)

    def to_scenario(self, source: str | Path = "<scenario>", *,
                    seed: int | None = None) -> Scenario:
        """The generator's :class:`Scenario`; reads the well file (relative to ``source``)."""
        info = self.scenario
        well_path = info.well if info.well.is_absolute() else Path(source).parent / info.well
        if not well_path.exists():
            raise ConfigError(str(source), "scenario.well", f"no such file: {well_path}")
        well_config = load_well(well_path)
        well = well_config.to_model(well_path)
        mu, temperature, mud_in, mud_out = _friction(well_config, well, well_path,
                                                     self.friction.temperature_model)
        channels = list(self.sampling.channels)
        if temperature is None:
            channels = [c for c in channels if c not in ("mud_temp_in", "mud_temp_out")]
        intervals = {c: self.sampling.intervals.get(c, self.sampling.interval) for c in channels}
        for index, fault in enumerate(self.fault):
            missing = [c for c in fault.channels if c not in intervals]
            if missing:
                raise ConfigError(str(source), f"fault[{index}].channels",
                                  f"channel '{missing[0]}' is not sampled")
        return Scenario(
            name=info.name or Path(source).stem,
            seed=info.seed if seed is None else seed,
            start=float(info.start),
            prefix=info.prefix,
            well=well,
            friction=mu,
            temperature=temperature,
            mud_temp_in=mud_in,
            mud_temp_out=mud_out,
            method=info.method,
            bit_depth=info.bit_depth,
            hole_depth=info.hole_depth if info.hole_depth is not None else info.bit_depth,
            block_position=(info.block_position if info.block_position is not None
                            else self.rig.block_low),
            phases=tuple(phase.to_phase() for phase in self.phase),
            rig=RigSettings(**self.rig.model_dump()),
            anomalies=tuple(FrictionAnomaly(a.top, a.bottom, a.delta_mu)
                            for a in self.friction.anomaly),
            tight_spots=tuple(TightSpot(s.md, s.length, s.force) for s in self.tight_spot),
            sample_interval=intervals,
            noise={c: self.noise.settings(c) for c in channels},
            faults=tuple(SensorFault(f.kind, tuple(f.channels), f.start, f.duration)
                         for f in self.fault),
        )


def _friction(config: WellConfig, well: Well, source: Path, mode: str) -> tuple[
        np.ndarray[Any, np.dtype[np.float64]], np.ndarray[Any, np.dtype[np.float64]] | None,
        float | None, float | None]:
    """Friction per hole-grid element from the sections' mu(T) at the annulus temperature of
    the well's ``[temperature]`` model (``mode="well"``) or of the geotherm (``"geothermal"``:
    mud at rest long enough to take the formation's temperature); with the surface mud-in and
    mud-out temperatures [degC]."""
    if config.temperature is None:
        return config.element_friction(well, source), None, None, None
    grid = hole_grid(well)
    if mode == "geothermal":
        config = config.model_copy(update={
            "temperature": config.temperature.model_copy(update={"model": "geothermal"})})
    laws: list[FrictionModel | float] = []
    for index, section in enumerate(config.hole):
        if section.friction is None:
            raise ConfigError(str(source), f"hole[{index}].friction", "missing key")
        laws.append(section.friction.friction_model())
    # the well file's own adapter, so that the truth is the profile `tdmon model` computes
    depths = np.concatenate([[well.hole_top], grid.element_mid_md])
    profile = config.annulus_temperature(well, depths, source)
    try:
        mu = local_friction(laws, grid.element_section, profile.annulus[1:])
    except ModelError as exc:
        raise ConfigError(str(source), "hole", str(exc)) from exc
    return (np.asarray(mu, dtype=np.float64), np.asarray(profile.annulus[1:], dtype=np.float64),
            float(profile.pipe[0]), float(profile.annulus[0]))


def load_scenario(path: str | Path) -> ScenarioConfig:
    """Read and validate a scenario file."""
    return load_model(ScenarioConfig, path)


def load_scenario_model(path: str | Path, *, seed: int | None = None) -> Scenario:
    """Read a scenario file and its well file into the generator's :class:`Scenario`."""
    return load_scenario(path).to_scenario(path, seed=seed)
