"""The scenario TOML of ``tdmon simulate`` as pydantic models, and ``load_scenario(path)``.

A scenario names a well file, a rig programme (``[[phase]]``), sampling, noise, faults, friction
anomalies and tight spots. Quantities are strings with a unit (``"28 m"``, ``"120 rpm"``,
``"2000 L/min"``, ``"3 min"``, ``"150 kN"``; plain numbers only where dimensionless). Every
problem is a :class:`tdmon.errors.ConfigError` naming the file, the key and the reason. The
simulator's :class:`tdmon.replay.spec.Scenario` is built from a validated file by
:func:`tdmon.replay.scenario.to_scenario`. See docs/replays.md for the keys.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Final, Literal, get_args

from pydantic import Field, ValidationInfo, field_validator, model_validator

from tdmon.channels import CHANNEL_UNITS, check_channel, validate_prefix
from tdmon.config.common import (
    UNITS_REQUIRED,
    CrossFieldError,
    Density,
    Force,
    Length,
    Pressure,
    StrictModel,
    _converter,
    load_model,
    missing_unit,
    quantity,
)
from tdmon.units import parse_time

__all__ = [
    "CHANNELS",
    "FAULT_KINDS",
    "PHASE_KINDS",
    "TIMED_PHASE_KINDS",
    "FaultConfig",
    "ModelErrorConfig",
    "NoiseConfig",
    "PhaseConfig",
    "ScenarioConfig",
    "SensorTruthConfig",
    "load_scenario",
]

CHANNELS: Final[tuple[str, ...]] = (
    "hookload", "torque", "bit_depth", "hole_depth", "block_position", "rpm", "flow_in", "spp",
    "wob", "mud_temp_in", "mud_temp_out", "mud_density")
"""Channels a scenario can sample, in the order the simulator seeds their random streams
(changing the order changes every simulated replay). ``mud_density`` (the mud pumped in) is
sent only for a well file with a ``[hydraulics]`` table."""

PhaseKind = Literal["static", "circulate", "rotate", "slips", "trip_out", "trip_in", "ream",
                    "back_ream", "drill"]
PHASE_KINDS: Final[tuple[str, ...]] = get_args(PhaseKind)
"""The steps a rig programme is made of."""

TIMED_PHASE_KINDS: Final[tuple[str, ...]] = ("static", "circulate", "rotate", "slips")
"""Phases that last a ``duration`` (the others move the bit ``to`` a depth)."""

FaultKind = Literal["stuck", "dropout"]
FAULT_KINDS: Final[tuple[str, ...]] = get_args(FaultKind)
"""Scheduled sensor faults: the last good value repeats, or nothing is sent."""

Speed = Annotated[float, quantity("m/s")]
Seconds = Annotated[float, quantity("s")]
Rotation = Annotated[float, quantity("rad/s")]
Flow = Annotated[float, quantity("m**3/s")]
Fraction = Annotated[float, quantity("dimensionless")]


def _known_channels(channels: list[str]) -> list[str]:
    for name in channels:
        check_channel(name, CHANNELS)
    return channels


class ScenarioInfo(StrictModel):
    name: str = ""
    well: Path
    seed: int = 0
    # validated too when left out: the default is a string the generator cannot use as is
    start: float | str = Field(default="2024-01-01T00:00:00Z", validate_default=True)
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
    intervals: dict[str, Annotated[Seconds, Field(gt=0, le=60)]] = Field(default_factory=dict)

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: list[str]) -> list[str]:
        return _known_channels(channels)

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
    offset: float = 0.0


class NoiseTable(NoiseConfig):
    """Defaults for every channel, and ``[noise.channels.<name>]`` overrides (merged).

    ``absolute`` is in the channel's unit, so in a file it is given per channel with its unit
    (``absolute = "5 mm"``) and converted to the channel's SI unit here."""

    channels: dict[str, dict[str, Any]] = Field(default_factory=dict)

    @field_validator("absolute", "offset", mode="before")
    @classmethod
    def _absolute_per_channel(cls, value: Any, info: ValidationInfo) -> Any:
        if (info.context or {}).get(UNITS_REQUIRED) and value not in (0, 0.0):
            what, example = (("absolute noise", '[noise.channels.bit_depth] absolute = "5 mm"')
                             if info.field_name == "absolute" else
                             ("zero offset", '[noise.channels.torque] offset = "0.5 kN m"'))
            raise ValueError(f"the {what} is in each channel's unit: give it per channel, "
                             f"e.g. {example}")
        return value

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: dict[str, dict[str, Any]],
               info: ValidationInfo) -> dict[str, dict[str, Any]]:
        read = {}
        for name, table in channels.items():
            _known_channels([name])
            table = dict(table)
            for key in ("absolute", "offset"):
                if key not in table:
                    continue
                target = CHANNEL_UNITS[name][0]
                # the key at fault is the channel's, not `channels`
                reason = missing_unit(table[key], target, key) \
                    if (info.context or {}).get(UNITS_REQUIRED) else None
                try:
                    if reason is not None:
                        raise ValueError(reason)
                    table[key] = _converter(target)(table[key], None)
                except ValueError as exc:
                    raise CrossFieldError(f"{name}.{key}", str(exc)) from None
            NoiseConfig.model_validate(table, context=info.context)
            read[name] = table
        return read

    def for_channel(self, channel: str) -> NoiseConfig:
        """The noise of ``channel``: the defaults with the channel's overrides."""
        base = self.model_dump(exclude={"channels"})
        return NoiseConfig.model_validate({**base, **self.channels.get(channel, {})})


class FaultConfig(StrictModel):
    kind: FaultKind
    channels: list[str] = Field(min_length=1)
    start: Seconds = Field(ge=0)
    duration: Seconds = Field(gt=0)

    @field_validator("channels")
    @classmethod
    def _known(cls, channels: list[str]) -> list[str]:
        return _known_channels(channels)


class PhaseConfig(StrictModel):
    kind: PhaseKind
    duration: Seconds = Field(default=0.0, ge=0)
    to: Length | None = None
    speed: Speed | None = Field(default=None, gt=0)
    rop: Speed | None = Field(default=None, gt=0)
    rpm: Rotation = Field(default=0.0, ge=0)
    flow: Flow = Field(default=0.0, ge=0)
    wob: Force = Field(default=0.0, ge=0)
    slips_time: Seconds = Field(default=60.0, gt=0)
    # the mud pumped in this phase (a pill, a slug); None: the well file's [fluid] density
    density: Density | None = Field(default=None, gt=0)

    @model_validator(mode="after")
    def _complete(self) -> PhaseConfig:
        if self.kind in TIMED_PHASE_KINDS:
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


class ModelErrorConfig(StrictModel):
    """``[model_error]``: how the rig's truth differs from the scenario's well file, which is
    then the daemon's (wrong) well file. The truth is simulated with the error, the well file
    stays as written."""

    density_factor: float = Field(default=1.0, gt=0.5, lt=2.0)
    fill_level: Length | None = Field(default=None, ge=0)
    string_extra_length: Length = Field(default=0.0, ge=0)
    string_component: str | None = None

    @model_validator(mode="after")
    def _component_with_length(self) -> ModelErrorConfig:
        if self.string_component is not None and self.string_extra_length <= 0:
            raise ValueError("string_component needs string_extra_length")
        return self


class SensorTruthConfig(StrictModel):
    """``[sensor]``: how the rig's hook-load channel reads the load on the hook, the truth
    the daemon's well file (``[hookload_sensor]``) may describe differently: where the sensor
    sits, the lines strung, the true sheave efficiency, and a zero offset drifting linearly
    from ``offset_start`` to ``offset_end`` over the session."""

    location: Literal["deadline", "hook", "top_drive"] = "hook"
    lines: int = Field(default=10, ge=1, le=24)
    efficiency: float = Field(default=1.0, ge=0.8, le=1.0)
    above_sensor: Force = Field(default=0.0, ge=0)
    offset_start: Force = 0.0
    offset_end: Force = 0.0

    @model_validator(mode="after")
    def _consistent(self) -> SensorTruthConfig:
        if self.location == "deadline" and self.above_sensor != 0.0:
            raise ValueError("a deadline sensor weighs all the travelling equipment: "
                             "above_sensor applies to 'hook' and 'top_drive' only")
        return self


class ScenarioConfig(StrictModel):
    """The whole scenario file."""

    scenario: ScenarioInfo
    friction: FrictionConfig = FrictionConfig()
    tight_spot: list[TightSpotConfig] = Field(default_factory=list)
    rig: RigConfig = RigConfig()
    sampling: SamplingConfig = SamplingConfig()
    noise: NoiseTable = NoiseTable()
    fault: list[FaultConfig] = Field(default_factory=list)
    model_error: ModelErrorConfig = ModelErrorConfig()
    sensor: SensorTruthConfig | None = None
    phase: list[PhaseConfig] = Field(min_length=1)


def load_scenario(path: str | Path) -> ScenarioConfig:
    """Read and validate a scenario file.

    Raises
    ------
    ConfigError
        The file is missing, not TOML, or invalid; the message names the key and the reason.
    """
    return load_model(ScenarioConfig, path)
