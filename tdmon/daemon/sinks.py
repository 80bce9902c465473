"""The sinks a daemon writes to, one builder per configuration section.

:data:`SINKS` (the flight recorder, Rerun) come before the caller's own sinks, so that the
recording gets every message first; :data:`PUBLISHERS` (``[publish]``) after them. A new sink
is its module (a :class:`~tdmon.record.sink.Sink`), a configuration section and one builder
and row here. A fleet daemon wires each rig's sinks from these tables too
(:meth:`~tdmon.daemon.wiring.Wiring.for_rig`).
"""

from __future__ import annotations

import logging
import os
from typing import Any

from tdmon.config.daemon import DaemonConfig, MqttConfig, RecorderConfig, RerunConfig, ZenohConfig
from tdmon.daemon.wiring import Entry, Table, Wiring
from tdmon.ingest.mqtt import MqttPublisher
from tdmon.ingest.zenoh_io import ZenohPublisher
from tdmon.record.sink import Recorder

log = logging.getLogger(__name__)


def folder_recorder(wiring: Wiring, section: RecorderConfig) -> None:
    """Record everything to rotating MCAP files in the configured folder, from a child process
    or this one (``process``); its health alarms go through the pipeline like any other
    alarm. A rig of a fleet records in this process, into a folder of its own named after its
    prefix (:func:`rig_folder_name`): a process per rig would each want a core."""
    from tdmon.record.mcap_recorder import McapRecorder
    from tdmon.record.writer_process import RecorderProcess

    config = wiring.config
    folder, options = config.resolve(section.output), dict[str, Any]()
    if wiring.in_fleet:
        name = rig_folder_name(config.prefix)
        folder, options, in_child = folder / name, {"prefix": name}, False
    else:
        in_child = section.process == "child" or (section.process == "auto"
                                                  and usable_cores() > 1)
    recorder_type = RecorderProcess if in_child else McapRecorder
    recorder: Recorder = recorder_type(folder, rotate_s=section.rotation,
                                       flush_interval_s=section.flush_interval,
                                       on_alarm=wiring.emit_alarm, **options)
    log.info("recording into %s (%s)", recorder.path,
             "from its own process" if in_child else "in the daemon's process")
    wiring.add_sink(recorder)


def rerun_views(wiring: Wiring, section: RerunConfig) -> None:
    """Rerun views, to an .rrd file (``mode = 'file'``) or served live (``'live'``)."""
    from tdmon.record.rerun_views import RerunViews

    rrd = wiring.config.resolve(section.path) if section.path else None
    live_port = section.port if section.mode == "live" else None
    wiring.add_sink(RerunViews(rrd, live_port=live_port))


def zenoh_publisher(wiring: Wiring, section: ZenohConfig) -> None:
    """Results on ``<prefix>/tdmon/<name>`` over Zenoh."""
    session = wiring.zenoh_session(section)
    config = wiring.config
    wiring.add_sink(ZenohPublisher(session, config.prefix, list(config.publish.names)))


def mqtt_publisher(wiring: Wiring, section: MqttConfig) -> None:
    """Results on ``<prefix>/tdmon/<name>`` over MQTT; queued, sent on a supervised
    connection (one per section: a fleet's rigs share it), drops counted in the status."""
    config = wiring.config
    publisher = wiring.connection(section, lambda: MqttPublisher(
        section, config.prefix, list(config.publish.names), qos=config.publish.qos,
        queue_size=config.queues.publish, on_drop=wiring.count_drop, base=wiring.base))
    wiring.add_sink(publisher.for_prefix(config.prefix))


def rig_folder_name(prefix: str) -> str:
    """The recording folder (and file name prefix) of rig ``prefix``: "rig/F4" -> "rig_F4"."""
    return prefix.replace("/", "_")


def usable_cores() -> int:
    """CPUs this process may run on (its affinity, e.g. a container's or ``taskset``'s)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity on this platform
        return os.cpu_count() or 1


def _enabled_recorder(config: DaemonConfig) -> RecorderConfig | None:
    return config.recorder if config.recorder.enabled else None


def _rerun_on(config: DaemonConfig) -> RerunConfig | None:
    return None if config.rerun.mode == "off" else config.rerun


def _publish_zenoh(config: DaemonConfig) -> ZenohConfig | None:
    """``[publish.zenoh]``'s own session, or with ``true`` the source's (shared)."""
    setting = config.publish.zenoh
    if setting is False:
        return None
    if setting is True:
        assert config.sources.zenoh is not None  # DaemonConfig's validator requires it
        return config.sources.zenoh
    return setting


def _publish_mqtt(config: DaemonConfig) -> MqttConfig | None:
    """``[publish.mqtt]``'s broker, or with ``true`` the source's."""
    setting = config.publish.mqtt
    if setting is False:
        return None
    if setting is True:
        assert config.sources.mqtt is not None  # DaemonConfig's validator requires it
        return config.sources.mqtt
    return setting


#: Sinks written to before the caller's own: section -> builder, in writing order.
SINKS: Table = {
    "recorder": Entry(_enabled_recorder, folder_recorder),
    "rerun": Entry(_rerun_on, rerun_views),
}

#: ``[publish]`` transports, written to after the caller's sinks, in this order.
PUBLISHERS: Table = {
    "zenoh": Entry(_publish_zenoh, zenoh_publisher),
    "mqtt": Entry(_publish_mqtt, mqtt_publisher),
}
