"""A scenario file into the simulator's :class:`tdmon.replay.spec.Scenario`.

The scenario TOML is read and validated by :mod:`tdmon.config.scenario`;
:func:`to_scenario` reads the well file it names, computes the true friction of every hole-grid
element (mu(T) at the well's annulus temperature) and builds the pure :class:`Scenario` the
generator (:func:`tdmon.replay.session.simulate_session`) takes. Every problem is a
:class:`tdmon.errors.ConfigError` naming the file, the key and the reason. See docs/replays.md
for the keys.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from tdmon.config.scenario import (
    ModelErrorConfig,
    NoiseConfig,
    PhaseConfig,
    ScenarioConfig,
    SensorTruthConfig,
    load_scenario,
)
from tdmon.config.well import WellConfig, load_well
from tdmon.errors import ConfigError, ModelError
from tdmon.model.friction import FrictionModel, local_friction
from tdmon.model.hookload_sensor import HookloadSensor, SensorLocation
from tdmon.model.string import DrillString
from tdmon.model.well import Fluid, Well, hole_grid
from tdmon.replay.spec import (
    FrictionAnomaly,
    HookloadMeasurement,
    ModelMismatch,
    NoiseSettings,
    Phase,
    RigSettings,
    Scenario,
    SensorFault,
    TightSpot,
)

__all__ = ["load_scenario_model", "to_scenario"]


def to_scenario(config: ScenarioConfig, source: str | Path = "<scenario>", *,
                seed: int | None = None) -> Scenario:
    """The generator's :class:`Scenario` of a validated scenario file.

    Parameters
    ----------
    config : the scenario file
    source : its path; the well file is relative to it
    seed : replaces the file's seed

    Raises
    ------
    ConfigError
        The well file is missing or invalid, a fault names a channel that is not sampled.
    """
    info = config.scenario
    well_path = info.well if info.well.is_absolute() else Path(source).parent / info.well
    if not well_path.exists():
        raise ConfigError(str(source), "scenario.well", f"no such file: {well_path}")
    well_config = load_well(well_path)
    well = well_config.to_model(well_path)
    mu, temperature, mud_in, mud_out = _friction(well_config, well, well_path,
                                                 config.friction.temperature_model)
    channels = list(config.sampling.channels)
    if temperature is None:
        channels = [c for c in channels if c not in ("mud_temp_in", "mud_temp_out")]
    intervals = {c: config.sampling.intervals.get(c, config.sampling.interval) for c in channels}
    for index, fault in enumerate(config.fault):
        missing = [c for c in fault.channels if c not in intervals]
        if missing:
            raise ConfigError(str(source), f"fault[{index}].channels",
                              f"channel '{missing[0]}' is not sampled")
    mismatch = _mismatch(config.model_error, well, source)
    true_well = _true_well(well, mismatch)
    return Scenario(
        name=info.name or Path(source).stem,
        seed=info.seed if seed is None else seed,
        start=float(info.start),
        prefix=info.prefix,
        well=true_well,
        friction=mu,
        temperature=temperature,
        mud_temp_in=mud_in,
        mud_temp_out=mud_out,
        method=info.method,
        bit_depth=info.bit_depth,
        hole_depth=info.hole_depth if info.hole_depth is not None else info.bit_depth,
        block_position=(info.block_position if info.block_position is not None
                        else config.rig.block_low),
        phases=tuple(_phase(phase) for phase in config.phase),
        rig=RigSettings(**config.rig.model_dump()),
        anomalies=tuple(FrictionAnomaly(a.top, a.bottom, a.delta_mu)
                        for a in config.friction.anomaly),
        tight_spots=tuple(TightSpot(s.md, s.length, s.force) for s in config.tight_spot),
        sample_interval=intervals,
        noise={c: _noise(config.noise.for_channel(c)) for c in channels},
        faults=tuple(SensorFault(f.kind, tuple(f.channels), f.start, f.duration)
                     for f in config.fault),
        mismatch=mismatch,
        model_well=well if mismatch.any else None,
        measurement=_measurement(config.sensor, well),
    )


def _measurement(config: SensorTruthConfig | None, well: Well) -> HookloadMeasurement:
    """The hook-load channel's truth: the scenario's ``[sensor]``, else the well file's
    ``[hookload_sensor]`` with no offset."""
    if config is None:
        return HookloadMeasurement(well.hookload_sensor)
    sensor = HookloadSensor(SensorLocation(config.location), config.lines, config.efficiency,
                            config.above_sensor)
    return HookloadMeasurement(sensor, config.offset_start, config.offset_end)


def _mismatch(config: ModelErrorConfig, well: Well, source: str | Path) -> ModelMismatch:
    """The validated ``[model_error]`` against the well file's string and fluid."""
    components = well.string.components
    index = 0
    if config.string_component is not None:
        names = [c.name for c in components]
        if config.string_component not in names:
            raise ConfigError(str(source), "model_error.string_component",
                              f"the well file has no string component "
                              f"'{config.string_component}' (it has {', '.join(names)})")
        index = names.index(config.string_component)
    if config.density_factor != 1.0 or config.fill_level is not None:
        fixed = [c.name for c in components if c.buoyed_weight is not None]
        if fixed:
            # a buoyed weight does not change with the fluid: the error would not show
            raise ConfigError(str(source), "model_error",
                              f"a fluid error needs the weight in air of every string component; "
                              f"'{fixed[0]}' gives buoyed_weight")
    return ModelMismatch(density_factor=config.density_factor, fill_level=config.fill_level,
                         extra_length=config.string_extra_length, extra_component=index)


def _true_well(well: Well, mismatch: ModelMismatch) -> Well:
    """The rig's true well: the well file's with the fluid density scaled and one component
    longer (the fill level depends on the bit depth: :class:`tdmon.replay.loads.Loads`)."""
    if not mismatch.any:
        return well
    fluid = well.fluid
    inside = fluid.inside_density
    true_fluid = Fluid(fluid.density * mismatch.density_factor,
                       None if inside is None else inside * mismatch.density_factor)
    components = list(well.string.components)
    if mismatch.extra_length > 0.0:
        longer = components[mismatch.extra_component]
        components[mismatch.extra_component] = replace(
            longer, length=longer.length + mismatch.extra_length)
    return replace(well, fluid=true_fluid, string=DrillString(tuple(components)),
                   name=f"{well.name} (truth)")


def _phase(config: PhaseConfig) -> Phase:
    """A validated phase; ``speed`` is the rate of penetration of a ``drill`` phase."""
    speed = config.rop if config.kind == "drill" else config.speed
    return Phase(kind=config.kind, duration=config.duration, to=config.to, speed=speed or 0.0,
                 rpm=config.rpm, flow=config.flow, wob=config.wob, slips_time=config.slips_time,
                 density=config.density)


def _noise(config: NoiseConfig) -> NoiseSettings:
    return NoiseSettings(**config.model_dump())


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


def load_scenario_model(path: str | Path, *, seed: int | None = None) -> Scenario:
    """Read a scenario file and its well file into the generator's :class:`Scenario`."""
    return to_scenario(load_scenario(path), path, seed=seed)
