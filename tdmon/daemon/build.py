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
from typing import Any

from tdmon.config.daemon import DaemonConfig, ZenohConfig
from tdmon.daemon.aligner import Aligner
from tdmon.daemon.daemon import ConnectedPublisher, Daemon, SourceSpec
from tdmon.daemon.monitor import LoadModel, MonitorStep
from tdmon.daemon.pipeline import Pipeline, Sink, Stats, Step
from tdmon.daemon.rigstate import RigStateThresholds, SimpleRigState
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


def load_well(config: DaemonConfig) -> Any:
    """The model layer's ``Well`` for the configured well file (None when there is none)."""
    if config.well is None:
        return None
    from tdmon.config.well import load_well_model

    return load_well_model(config.resolve(config.well))


def load_model(config: DaemonConfig, well: Any = None) -> LoadModel | None:
    """The production load model for the configured well (None when no well is configured)."""
    if config.well is None:
        return None
    from tdmon.daemon.wellmodel import grid_model_for_well

    return grid_model_for_well(config, well)


def calibration_steps_for(config: DaemonConfig, well: Any = None) -> tuple[Step, list[Step]]:
    """The back-calculation's rig-state step and the steps after the monitor
    (docs/back-calculation.md, "Daemon composition"). The mu(T) calibration, which needs the
    well's temperature model and a friction law, is not wired yet."""
    from tdmon.calib.rigstate import RigStateThresholds as CalibThresholds
    from tdmon.daemon.calibrate import AlarmStep, CalibrationStep, RigStateStep
    from tdmon.model.torque_drag import WellModel

    assert config.well is not None
    if well is None:
        well = load_well(config)
    rs = config.rig_state
    rig_state = RigStateStep(CalibThresholds(
        block_weight=well.block_weight, in_slips_margin=config.calibration.in_slips_margin,
        moving_speed=rs.moving_speed, rotating_speed=rs.rotating_rpm,
        circulating_flow=rs.circulating_flow, on_bottom=rs.on_bottom))
    return rig_state, [CalibrationStep(WellModel(well), rig_state), AlarmStep()]


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
    # the well file is read once, for the monitor's grid and the back-calculation
    well = load_well(config) if model is None or needs_calibration else None
    if model is None:
        model = load_model(config, well)
    extra_steps = list(extra_steps)
    if needs_calibration:
        rig_state, calibration_steps = calibration_steps_for(config, well)
        extra_steps = calibration_steps + extra_steps
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
