"""Build a runnable daemon from a :class:`~tdmon.config.daemon.DaemonConfig`.

This is the thin adapter between configuration and the composer: the builder tables create
the sources (:data:`tdmon.daemon.sources.SOURCES`), the recorder, Rerun and the publishers
(:data:`tdmon.daemon.sinks.SINKS`, :data:`~tdmon.daemon.sinks.PUBLISHERS`); this module makes
the steps and hands everything to :class:`Daemon`. Extra sinks and steps (back-calculation,
Rerun, tests) are passed in by the caller.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tdmon.config.daemon import DaemonConfig
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.clock import ClockGuard, ClockSettings
from tdmon.daemon.daemon import Daemon
from tdmon.daemon.monitor import LoadModel, MonitorStep
from tdmon.daemon.pipeline import Pipeline, Sink, Stats, Step
from tdmon.daemon.rigstate import RigStateThresholds, SimpleRigState
from tdmon.daemon.sinks import PUBLISHERS, SINKS
from tdmon.daemon.sources import SOURCES
from tdmon.daemon.supervisor import Backoff
from tdmon.daemon.wiring import Wiring, wire
from tdmon.errors import ConfigError
from tdmon.ingest.decode import Decoder, SampleChecks
from tdmon.model.friction import FrictionModel

log = logging.getLogger(__name__)


@dataclass
class Built:
    """A daemon and what was built for it (handy for tests and the CLI)."""

    daemon: Daemon
    pipeline: Pipeline
    stats: Stats
    sinks: list[Sink] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)


def default_steps(config: DaemonConfig, model: LoadModel | None,
                  rig_state: Step | None = None) -> list[Step]:
    """Rig state (``rig_state``, else the simple threshold step), then the monitor when a
    model is available."""
    rs = config.rig_state
    steps: list[Step] = [rig_state or SimpleRigState(RigStateThresholds(
        in_slips_hookload=rs.in_slips_hookload, moving_speed=rs.moving_speed,
        rotating_rpm=rs.rotating_rpm, circulating_flow=rs.circulating_flow,
        on_bottom=rs.on_bottom, steady_frames=rs.steady_frames,
    ))]
    if model is not None:
        steps.append(MonitorStep(model))
    return steps


@dataclass(frozen=True)
class WellFile:
    """The daemon's well file, read once: its configuration, the model's ``Well``, the path."""

    config: Any  # tdmon.config.well.WellConfig (imported lazily with pydantic's models)
    well: Any  # tdmon.model.well.Well
    path: Path


def read_well_file(config: DaemonConfig) -> WellFile | None:
    """Read the configured well file (None when there is none)."""
    if config.well is None:
        return None
    from tdmon.config.well import load_well as load_well_config

    path = config.resolve(config.well)
    well_config = load_well_config(path)
    return WellFile(well_config, well_config.to_model(path), path)


def load_well(config: DaemonConfig) -> Any:
    """The model layer's ``Well`` for the configured well file (None when there is none)."""
    well_file = read_well_file(config)
    return None if well_file is None else well_file.well


def load_model(config: DaemonConfig, well: Any = None) -> LoadModel | None:
    """The production load model for the configured well (None when no well is configured)."""
    if config.well is None:
        return None
    from tdmon.daemon.wellmodel import grid_model_for_well

    return grid_model_for_well(config, well)


@dataclass(frozen=True)
class MuTSetup:
    """What the live mu(T) calibration gets from the well file (docs/back-calculation.md).

    ``temperature`` is the annulus temperature per hole-grid element [degC] (None without a
    ``[temperature]`` table; also used for the profile view); ``law`` the prior law (family
    mode) or the lab fit (scale mode), None when the calibration is off, and then ``note``
    says why. ``mask`` selects the elements of the calibrated section (None: all); the other
    elements keep ``base_mu``, the well file's friction.
    """

    temperature: NDArray[np.float64] | None
    law: FrictionModel | None
    mode: str = "family"
    mask: NDArray[np.bool_] | None = None
    base_mu: float | NDArray[np.float64] = 0.0
    prior_std: list[float] | None = None
    note: str | None = None
    friction: NDArray[np.float64] | None = None


def _section_index(config: DaemonConfig, well_file: WellFile) -> int:
    sections = well_file.config.hole
    wanted = config.calibration.mu_t_section
    if wanted is None:
        return len(sections) - 1
    if isinstance(wanted, int):
        if not -len(sections) <= wanted < len(sections):
            raise ConfigError(str(config.source_file), "calibration.mu_t_section",
                              f"the well file has {len(sections)} hole sections, no {wanted}")
        return wanted % len(sections)
    names = [section.name for section in sections]
    if wanted not in names:
        raise ConfigError(str(config.source_file), "calibration.mu_t_section",
                          f"no hole section named '{wanted}' (sections: {', '.join(names)})")
    return names.index(wanted)


def mu_t_setup(config: DaemonConfig, well_file: WellFile, grid: Any) -> MuTSetup:
    """Annulus temperatures (computed once, at start-up) and the law to calibrate.

    A family law is calibrated in its own coefficients; a constant friction becomes the
    linear law ``a + b T`` with ``b = 0`` as the prior, since a constant has no temperature
    dependence to calibrate.
    """
    calibration = config.calibration
    well_config, path = well_file.config, well_file.path
    try:
        friction: NDArray[np.float64] | None = well_config.element_friction(well_file.well, path)
    except ConfigError as exc:
        log.warning("no friction profile from the well file: %s", exc)
        friction = None
    temperature = None
    if well_config.temperature is not None:
        temperature = np.asarray(
            well_config.annulus_temperature(well_file.well, grid.element_mid_md, path).annulus,
            dtype=np.float64)
    if calibration.mu_t == "off":
        return MuTSetup(temperature, None, friction=friction,
                        note="mu(T) calibration is off ([calibration] mu_t = 'off')")
    if temperature is None:
        return MuTSetup(None, None, friction=friction,
                        note=f"mu(T) calibration is off: the well file {path.name} has no "
                             f"[temperature] table")
    index = _section_index(config, well_file)
    section = well_config.hole[index]
    if calibration.mu_t == "scale":
        assert calibration.lab_fit is not None  # checked when the config was read
        law = calibration.lab_fit.friction_model()
    elif section.friction is None:
        law = FrictionModel("linear", {"a": config.monitor.mu, "b": 0.0})
    else:
        law = section.friction.friction_model()
        if law.family == "constant":
            law = FrictionModel("linear", {"a": float(law.coefficients["mu"]), "b": 0.0})
    n_params = 1 if calibration.mu_t == "scale" else len(law.coefficients)
    prior_std = calibration.mu_t_prior_std
    if prior_std is not None and len(prior_std) != n_params:
        raise ConfigError(str(config.source_file), "calibration.mu_t_prior_std",
                          f"give {n_params} values, one per parameter of "
                          f"{law.describe()} ({calibration.mu_t} mode)")
    mask = np.asarray(grid.element_section == index)
    base: float | NDArray[np.float64] = (friction if friction is not None
                                         else config.monitor.mu)
    return MuTSetup(temperature, law, calibration.mu_t, None if mask.all() else mask, base,
                    prior_std, friction=friction)


def calibration_steps_for(config: DaemonConfig, well: Any = None,
                          well_file: WellFile | None = None) -> tuple[Step, list[Step]]:
    """The back-calculation's rig-state step and the steps after the monitor
    (docs/back-calculation.md, "Daemon composition"), with the mu(T) calibration when the
    well file has a temperature model, and the well/profile step last."""
    from tdmon.calib.rigstate import RigStateThresholds as CalibThresholds
    from tdmon.daemon.calibrate import (
        AlarmStep,
        CalibrationSettings,
        CalibrationStep,
        RigStateStep,
    )
    from tdmon.errors import FitError
    from tdmon.model.torque_drag import WellModel

    assert config.well is not None
    if well_file is None:
        well_file = read_well_file(config)
    assert well_file is not None
    if well is None:
        well = well_file.well
    rs = config.rig_state
    rig_state = RigStateStep(CalibThresholds(
        block_weight=well.block_weight, in_slips_margin=config.calibration.in_slips_margin,
        moving_speed=rs.moving_speed, rotating_speed=rs.rotating_rpm,
        circulating_flow=rs.circulating_flow, on_bottom=rs.on_bottom))
    model = WellModel(well)
    setup = mu_t_setup(config, well_file, model.grid)
    settings = CalibrationSettings(mu_t_mode=setup.mode)
    try:
        calibration = CalibrationStep(
            model, rig_state, settings, temperature=setup.temperature if setup.law else None,
            friction_law=setup.law, mu_t_mask=setup.mask, mu_t_base=setup.base_mu,
            mu_t_prior_std=setup.prior_std)
    except FitError as exc:
        # e.g. a law undefined at the well's temperatures: monitor anyway, say why
        setup = replace(setup, law=None, note=f"mu(T) calibration is off: {exc}")
        calibration = CalibrationStep(model, rig_state, settings)
    if setup.note is not None:
        log.info("%s", setup.note)
    else:
        assert setup.law is not None and setup.temperature is not None
        log.info("mu(T) calibration on: %s (%s mode) over %.1f-%.1f degC", setup.law.describe(),
                 setup.mode, float(np.min(setup.temperature)), float(np.max(setup.temperature)))
    return rig_state, [calibration, AlarmStep(),
                       profile_step(config, well_file, model.grid, setup, calibration)]


#: at most this many points in a ``well`` or ``profile`` message (a 6 km well at 1 m elements
#: would otherwise send 6000-point arrays every profile interval)
MAX_PROFILE_POINTS = 500


def profile_step(config: DaemonConfig, well_file: WellFile, grid: Any,
                 setup: MuTSetup | None = None, calibration: Any = None) -> Step:
    """The step emitting ``well`` and ``profile`` (see :class:`ProfileStep`)."""
    from tdmon.daemon.calibrate import ProfileStep

    if setup is None:
        setup = mu_t_setup(config.model_copy(update={
            "calibration": config.calibration.model_copy(update={"mu_t": "off"})}),
            well_file, grid)
        setup = replace(setup, note=None)  # no calibration: nothing to explain
    nodes = _thin(grid.md.size)
    well_message = {
        "name": well_file.well.name or well_file.path.stem,
        "md_m": grid.md[nodes].tolist(), "tvd_m": grid.tvd[nodes].tolist(),
        "north_m": grid.north[nodes].tolist(), "east_m": grid.east[nodes].tolist(),
    }
    elements = _thin(grid.n_elements)
    return ProfileStep(well_message, grid.element_mid_md[elements], elements,
                       temperature=setup.temperature, friction=setup.friction,
                       calibration=calibration, interval=config.calibration.profile_interval,
                       mu_t_note=setup.note)


def _thin(n: int) -> NDArray[np.int64]:
    """Indices of at most MAX_PROFILE_POINTS evenly spread points out of n, ends included."""
    stride = max(1, math.ceil(n / MAX_PROFILE_POINTS))
    index = np.arange(0, n, stride, dtype=np.int64)
    if index[-1] != n - 1:
        index = np.append(index, n - 1)
    return index


@contextlib.asynccontextmanager
async def build_daemon(
    config: DaemonConfig,
    *,
    model: LoadModel | None = None,
    extra_sinks: Sequence[Sink] = (),
    extra_steps: Sequence[Step] = (),
    rig_state: Step | None = None,
    backoff: Backoff | None = None,
    stop_when_sources_done: bool | None = None,
) -> AsyncIterator[Built]:
    """Create the daemon for ``config``; resources (Zenoh sessions) close on exit.

    ``model`` overrides the well file's model (tests); ``rig_state`` replaces the simple
    rig-state step; ``extra_steps`` run after the monitor (back-calculation, alarms);
    ``extra_sinks`` receive everything (the recorder is added first when enabled).
    """
    needs_calibration = config.calibration.enabled and rig_state is None
    # the well file is read once, for the monitor's grid, the back-calculation, the
    # temperatures and the well/profile messages
    well_file = read_well_file(config)
    well = None if well_file is None else well_file.well
    if model is None:
        model = load_model(config, well)
    extra_steps = list(extra_steps)
    if needs_calibration:
        assert well_file is not None  # the config needs a well file for calibration
        rig_state, calibration_steps = calibration_steps_for(config, well, well_file)
        extra_steps = calibration_steps[:-1] + extra_steps + calibration_steps[-1:]
    elif well_file is not None:
        from tdmon.daemon.calibrate import CalibrationStep
        from tdmon.model.well import hole_grid

        # a caller composing its own calibration still gets its profile reported
        calibration = next((s for s in extra_steps if isinstance(s, CalibrationStep)), None)
        extra_steps.append(profile_step(config, well_file, hole_grid(well_file.well),
                                        calibration=calibration))
    stats = Stats()
    wiring = Wiring(config, stats)
    try:
        await wire(SINKS, wiring)
        wiring.sinks.extend(extra_sinks)
        await wire(SOURCES, wiring)
        await wire(PUBLISHERS, wiring)
        sources = wiring.sources

        steps = default_steps(config, model, rig_state) + list(extra_steps)
        align = config.align
        aligner = Aligner(
            wait_for=align.wait_for,
            expected=list(config.channels),
            stale_timeout=align.stale_timeout,
            max_wait=align.max_wait,
            jump_samples=align.clock_jump_samples,
            jump_spread=align.clock_jump_spread,
            jump_min=align.future_tolerance,
        )
        checks = SampleChecks(
            earliest_t=align.earliest_time,
            well_depth=None if well is None else well.hole_bottom,
            depth_margins=config.depth_margins())
        decoder = Decoder(config.prefix, config.channel_specs(),
                          max_payload_bytes=config.queues.max_payload_bytes, checks=checks)
        clock = ClockGuard(ClockSettings(align.future_tolerance, align.clock_jump_samples,
                                         align.clock_jump_spread))
        pipeline = Pipeline(decoder, aligner, steps, wiring.sinks, stats, clock=clock)
        wiring.pipeline = pipeline
        if stop_when_sources_done is None:
            stop_when_sources_done = bool(sources) and all(s.finite for s in sources)
        daemon = Daemon(
            pipeline, sources, wiring.connected,
            queue_size=config.queues.ingest,
            status_interval=config.publish.status_interval,
            backoff=backoff,
            stop_when_sources_done=stop_when_sources_done,
        )
        yield Built(daemon, pipeline, stats, wiring.sinks, steps)
    finally:
        # the sinks built here are the daemon's to close, unless it never came to be
        await wiring.release(close_sinks=wiring.pipeline is None)
