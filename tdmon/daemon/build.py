"""Build a runnable daemon from a :class:`~tdmon.config.daemon.DaemonConfig`.

This is the thin adapter between configuration and the composer: it opens the Zenoh session,
creates sources, publishers, the recorder and the steps, and hands them to :class:`Daemon`.
Extra sinks and steps (back-calculation, Rerun, tests) are passed in by the caller.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tdmon.config.daemon import DaemonConfig, ZenohConfig
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.daemon import ConnectedPublisher, Daemon, SourceSpec
from tdmon.daemon.monitor import LoadModel
from tdmon.daemon.pipeline import Pipeline, Sink, Stats, Step
from tdmon.daemon.steps.compose import calibration_steps_for, default_steps
from tdmon.daemon.steps.profile import profile_step
from tdmon.daemon.supervisor import Backoff
from tdmon.errors import ConfigError
from tdmon.ingest.decode import Decoder
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.mqtt import MqttPublisher, MqttSource
from tdmon.ingest.zenoh_io import ZenohPublisher, ZenohSource, key_expr_for, open_session

log = logging.getLogger(__name__)


@dataclass
class Built:
    """A daemon and what was built for it (handy for tests and the CLI)."""

    daemon: Daemon
    pipeline: Pipeline
    stats: Stats
    sinks: list[Sink] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)


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
        from tdmon.daemon.steps.calibrate import CalibrationStep
        from tdmon.model.well import hole_grid

        # a caller composing its own calibration still gets its profile reported
        calibration = next((s for s in extra_steps if isinstance(s, CalibrationStep)), None)
        extra_steps.append(profile_step(config, well_file, hole_grid(well_file.well),
                                        calibration=calibration))
    stats = Stats()
    base = config.source_file.parent if config.source_file else None
    sinks: list[Sink] = []
    sessions: list[Any] = []
    recorder: Any = None
    pipeline: Pipeline | None = None
    try:
        if config.recorder.enabled:
            from tdmon.record.mcap_recorder import McapRecorder

            def on_alarm(message: dict[str, Any]) -> None:
                if pipeline is not None:
                    pipeline.emit("alarm", message)

            recorder = McapRecorder(
                config.resolve(config.recorder.output),
                rotate_s=config.recorder.rotation,
                flush_interval_s=config.recorder.flush_interval,
                on_alarm=on_alarm,
            )
            sinks.append(recorder)
        if config.rerun.mode != "off":
            from tdmon.record.rerun_views import RerunViews

            rrd = config.resolve(config.rerun.path) if config.rerun.path else None
            if config.rerun.mode == "file" and rrd is None:
                raise ConfigError(str(config.source_file), "rerun.path",
                                  "mode 'file' needs a path for the .rrd file")
            sinks.append(RerunViews(
                rrd, live_port=config.rerun.port if config.rerun.mode == "live" else None))
        sinks.extend(extra_sinks)

        own = f"{config.prefix}/tdmon/"
        sources: list[SourceSpec] = []
        publishers: list[ConnectedPublisher] = []
        zenoh_session = None
        if config.sources.zenoh is not None or config.publish.zenoh is True:
            zcfg = config.sources.zenoh
            if zcfg is None:
                raise ConfigError(str(config.source_file), "publish.zenoh",
                                  "true needs [sources.zenoh]; give a table with endpoints")
            zenoh_session = await asyncio.to_thread(open_session, zcfg)
            sessions.append(zenoh_session)
        if config.sources.zenoh is not None:
            assert zenoh_session is not None
            session = zenoh_session
            max_buffer = config.queues.ingest

            def open_zenoh() -> ZenohSource:
                return ZenohSource(session, key_expr_for(config.prefix), (own,), max_buffer)

            sources.append(SourceSpec("zenoh", open_zenoh))
        if config.sources.mqtt is not None:
            mqtt = config.sources.mqtt

            def open_mqtt() -> MqttSource:
                return MqttSource(mqtt, [f"{config.prefix}/#"], (own,), base)

            sources.append(SourceSpec("mqtt", open_mqtt))
        if config.sources.mcap is not None:
            mcap = config.sources.mcap
            path = config.resolve(mcap.path)
            speed = None if mcap.speed == "max" else float(mcap.speed)

            def open_mcap() -> McapSource:
                return McapSource(path, speed)

            sources.append(SourceSpec("mcap", open_mcap, finite=True))

        names = list(config.publish.names)
        if config.publish.zenoh is not False:
            if isinstance(config.publish.zenoh, ZenohConfig):
                publish_session = await asyncio.to_thread(open_session, config.publish.zenoh)
                sessions.append(publish_session)
            else:
                assert zenoh_session is not None
                publish_session = zenoh_session
            sinks.append(ZenohPublisher(publish_session, config.prefix, names))
        if config.publish.mqtt is not False:
            if config.publish.mqtt is True:
                if config.sources.mqtt is None:
                    raise ConfigError(str(config.source_file), "publish.mqtt",
                                      "true needs [sources.mqtt]; give a table with the broker")
                pub_cfg = config.sources.mqtt
            else:
                pub_cfg = config.publish.mqtt
            publisher = MqttPublisher(pub_cfg, config.prefix, names, qos=config.publish.qos,
                                      queue_size=config.queues.publish,
                                      on_drop=stats.count_drop, base=base)
            sinks.append(publisher)
            publishers.append(publisher)

        steps = default_steps(config, model, rig_state) + list(extra_steps)
        aligner = Aligner(
            wait_for=config.align.wait_for,
            expected=list(config.channels),
            stale_timeout=config.align.stale_timeout,
            max_wait=config.align.max_wait,
        )
        decoder = Decoder(config.prefix, config.channel_specs(),
                          max_payload_bytes=config.queues.max_payload_bytes)
        pipeline = Pipeline(decoder, aligner, steps, sinks, stats)
        if stop_when_sources_done is None:
            stop_when_sources_done = bool(sources) and all(s.finite for s in sources)
        daemon = Daemon(
            pipeline, sources, publishers,
            queue_size=config.queues.ingest,
            status_interval=config.publish.status_interval,
            backoff=backoff,
            stop_when_sources_done=stop_when_sources_done,
        )
        yield Built(daemon, pipeline, stats, sinks, steps)
    finally:
        if pipeline is None and recorder is not None:
            recorder.close()
        for session in sessions:
            with contextlib.suppress(Exception):  # closing a session that lost its peers
                await asyncio.to_thread(session.close)
