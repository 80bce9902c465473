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
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from tdmon.config.daemon import DaemonConfig
from tdmon.config.well_file import WellFile, read_well_file
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.clock import ClockGuard, ClockSettings
from tdmon.daemon.daemon import Daemon
from tdmon.daemon.pipeline import Pipeline, Sink, Stats, Step
from tdmon.daemon.sinks import PUBLISHERS, SINKS
from tdmon.daemon.sources import SOURCES
from tdmon.daemon.steps.compose import calibration_steps_for, default_steps
from tdmon.daemon.steps.monitor import LoadModel
from tdmon.daemon.steps.profile import profile_step
from tdmon.daemon.supervisor import Backoff
from tdmon.daemon.wiring import Wiring, wire
from tdmon.ingest.decode import Decoder, SampleChecks
from tdmon.ingest.loss_state import LOSS_STATE_FILE

log = logging.getLogger(__name__)


@dataclass
class Built:
    """A daemon and what was built for it (handy for tests and the CLI)."""

    daemon: Daemon
    pipeline: Pipeline
    stats: Stats
    sinks: list[Sink] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)


def load_model(config: DaemonConfig, well: Any = None) -> LoadModel | None:
    """The production load model for the configured well (None when no well is configured)."""
    if config.well is None:
        return None
    from tdmon.daemon.wellmodel import grid_model_for_well

    return grid_model_for_well(config, well)


def assemble_pipeline(config: DaemonConfig, well: Any, steps: Sequence[Step],
                      sinks: Sequence[Sink], stats: Stats) -> Pipeline:
    """The pipeline of one rig: its decoder (channel map, sample checks against ``well``),
    aligner and clock guard from ``config``, then ``steps``, writing to ``sinks``."""
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
    return Pipeline(decoder, aligner, steps, sinks, stats, clock=clock)


def rig_steps(config: DaemonConfig, well_file: WellFile | None, model: LoadModel | None,
              rig_state: Step | None = None, extra_steps: Sequence[Step] = (), *,
              own_model: bool = True) -> list[Step]:
    """A rig's steps: the model-coverage step first when there is a well file (a new well, by
    run or reload, is in place before the monitor's frame), rig state and monitor, the
    calibration's steps when it is on (around ``extra_steps``), else the profile step.
    ``own_model``: the monitor's model is the well file's (not a caller's), so a new well
    file replaces it."""
    extra_steps = list(extra_steps)
    if config.calibration.enabled and rig_state is None:
        assert well_file is not None  # the config needs a well file for calibration
        rig_state, calibration_steps = calibration_steps_for(config, well_file.well, well_file)
        extra_steps = calibration_steps[:-1] + extra_steps + calibration_steps[-1:]
    elif well_file is not None:
        from tdmon.daemon.steps.calibrate import CalibrationStep
        from tdmon.model.well import hole_grid

        # a caller composing its own calibration still gets its profile reported
        calibration = next((s for s in extra_steps if isinstance(s, CalibrationStep)), None)
        extra_steps.append(profile_step(config, well_file, hole_grid(well_file.well),
                                        calibration=calibration))
    steps = default_steps(config, model, rig_state) + extra_steps
    if well_file is not None:
        from tdmon.daemon.steps.fluids import fluid_step_for
        from tdmon.daemon.steps.rig_state import RigStateStep

        detector = steps[0] if isinstance(steps[0], RigStateStep) else None
        fluid = fluid_step_for(config, well_file, detector)
        if fluid is not None:  # after the rig state, before the monitor and the calibration
            steps.insert(1, fluid)
    _read_through_the_sensor(steps, well_file)
    if well_file is not None:
        from tdmon.daemon.steps.coverage import coverage_step

        steps.insert(0, coverage_step(config, well_file, steps, own_model=own_model))
    return steps


def _read_through_the_sensor(steps: Sequence[Step], well_file: WellFile | None) -> None:
    """The monitor shows its hook loads as the rig's sensor reads them: through the
    calibration's estimate of the measurement where it runs, else through the well file's
    sensor as configured (nothing for a sensor that reads the load on the hook)."""
    from tdmon.daemon.steps.calibrate import CalibrationStep
    from tdmon.daemon.steps.monitor import MonitorStep

    monitor = next((s for s in steps if isinstance(s, MonitorStep)), None)
    if monitor is None:
        return
    calibration = next((s for s in steps if isinstance(s, CalibrationStep)), None)
    if calibration is not None:
        monitor.sensor = calibration.sensor_reading
        return
    if well_file is None:
        return
    well = well_file.well
    sensor = well.hookload_sensor
    if not (sensor.reads_sheave_friction and sensor.efficiency < 1.0) and \
            sensor.above_sensor == 0.0:
        return
    from tdmon.calib.measurement import SensorEstimate

    fixed = (SensorEstimate(sensor, well.block_weight - sensor.above_sensor, 0.0,
                            efficiency=sensor.efficiency), well.block_weight)
    monitor.sensor = lambda: fixed


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

    ``model`` overrides the well file's model (tests); ``rig_state`` replaces the default
    rig-state step; ``extra_steps`` run after the monitor (back-calculation, alarms);
    ``extra_sinks`` receive everything (the recorder is added first when enabled).
    """
    # the well file is read once, for the monitor's grid, the back-calculation, the
    # temperatures and the well/profile messages
    well_file = read_well_file(config)
    well = None if well_file is None else well_file.well
    model_from_well = model is None
    if model is None:
        model = load_model(config, well)
    steps = rig_steps(config, well_file, model, rig_state, extra_steps,
                      own_model=model_from_well)
    stats = Stats()
    wiring = Wiring(config, stats)
    try:
        wire(SINKS, wiring)
        wiring.sinks.extend(extra_sinks)
        wire(SOURCES, wiring)
        wire(PUBLISHERS, wiring)
        sources = wiring.sources

        pipeline = assemble_pipeline(config, well, steps, wiring.sinks, stats)
        wiring.pipeline = pipeline
        if config.recorder.enabled and any(not source.finite for source in sources):
            # a live daemon's loss counting goes on across its restarts (not a replay's)
            pipeline.loss.keep_state(config.resolve(config.recorder.output) / LOSS_STATE_FILE)
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
