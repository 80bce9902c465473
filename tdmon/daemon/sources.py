"""The sources a daemon reads from, one builder per ``[sources.<name>]`` section.

Each builder adds a :class:`~tdmon.daemon.daemon.SourceSpec` that the supervisor opens (and
reopens after a failure). A new transport is its module in ``tdmon.ingest``, a section in
:class:`~tdmon.config.daemon.SourcesConfig` and one builder and row here.
"""

from __future__ import annotations

from tdmon.config.daemon import (
    McapSourceConfig,
    MqttConfig,
    OpcUaConfig,
    Wits0Config,
    ZenohConfig,
)
from tdmon.daemon.daemon import SourceSpec
from tdmon.daemon.loss import DropAlarm
from tdmon.daemon.wiring import Entry, Table, Wiring
from tdmon.errors import ConfigError, IngestError
from tdmon.ingest.decode import topic_for
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.mqtt import MqttSource, RecentDeliveries
from tdmon.ingest.wits0 import MAX_FRAME_BYTES, ItemOverride, item_map, resolve_timezone
from tdmon.ingest.wits0_source import REJECT_TOPIC, Wits0Source
from tdmon.ingest.zenoh_io import ZenohSource, key_expr_for


def zenoh_source(wiring: Wiring, section: ZenohConfig) -> None:
    """Subscribe to everything under the prefix on the section's session."""
    session = wiring.zenoh_session(section)
    key_expr = key_expr_for(wiring.config.prefix)
    ignore = (wiring.own_prefix,)
    max_buffer = wiring.config.queues.ingest

    def open_zenoh() -> ZenohSource:
        return ZenohSource(session, key_expr, ignore, max_buffer)

    wiring.sources.append(SourceSpec("zenoh", open_zenoh))


def mqtt_source(wiring: Wiring, section: MqttConfig) -> None:
    """Subscribe to ``<prefix>/#`` on the section's broker."""
    subscribe = [f"{wiring.config.prefix}/#"]
    ignore = (wiring.own_prefix,)
    base = wiring.base
    recent = RecentDeliveries()  # over reconnects: a resent message is recognised
    max_queued = wiring.config.queues.ingest
    drops = DropAlarm(f"more than {max_queued} QoS 0 messages waiting in the MQTT client "
                      "([queues] ingest)", wiring.count_drop, wiring.emit_alarm)

    def open_mqtt() -> MqttSource:
        return MqttSource(section, subscribe, ignore, base, recent, max_queued, drops.add)

    wiring.sources.append(SourceSpec("mqtt", open_mqtt))


def mcap_source(wiring: Wiring, section: McapSourceConfig) -> None:
    """Replay a recording (a finite source: the daemon may stop when it is done)."""
    path = wiring.config.resolve(section.path)
    speed = None if section.speed == "max" else float(section.speed)

    def open_mcap() -> McapSource:
        return McapSource(path, speed)

    wiring.sources.append(SourceSpec("mcap", open_mcap, finite=True))


def wits0_source(wiring: Wiring, section: Wits0Config) -> None:
    """Read a rig's WITS0 feed; its items go in as samples on the configured channel topics
    (docs/wits0.md). The item map is checked here, where the codec's unit table is."""
    config = wiring.config
    overrides = {code: ItemOverride(item.channel, item.unit)
                 for code, item in section.items.items()}
    try:
        items = item_map(section.units, overrides)
    except ValueError as exc:
        raise ConfigError(str(config.source_file), "sources.wits0.items", str(exc)) from None
    topics = {spec.channel: topic_for(config.prefix, spec.topic)
              for spec in config.channel_specs()}
    reject_topic = topic_for(config.prefix, REJECT_TOPIC)
    tz = resolve_timezone(section.timezone)  # checked when the config was read
    # the first item message of a frame carries the frame: keep it under the payload limit
    max_frame = max(256, min(MAX_FRAME_BYTES, config.queues.max_payload_bytes - 512))

    def open_wits0() -> Wits0Source:
        return Wits0Source(section, items, topics, reject_topic, tz, max_frame)

    wiring.sources.append(SourceSpec("wits0", open_wits0))


def opcua_source(wiring: Wiring, section: OpcUaConfig) -> None:
    """Subscribe to the rig's OPC UA server; each configured node goes in as samples on its
    channel's topic (docs/opcua.md). Without asyncua the daemon does not start."""
    from tdmon.ingest.opcua_source import OpcUaSource, import_asyncua

    config = wiring.config
    try:
        import_asyncua()
    except IngestError as exc:
        raise ConfigError(str(config.source_file), "sources.opcua", str(exc)) from None
    topics = {spec.channel: topic_for(config.prefix, spec.topic)
              for spec in config.channel_specs()}
    max_pending = config.queues.ingest

    def open_opcua() -> OpcUaSource:
        return OpcUaSource(section, topics, max_pending)

    wiring.sources.append(SourceSpec("opcua", open_opcua))


#: ``[sources.<name>]`` -> its builder, in the order the sources are started.
SOURCES: Table = {
    "zenoh": Entry(lambda config: config.sources.zenoh, zenoh_source),
    "mqtt": Entry(lambda config: config.sources.mqtt, mqtt_source),
    "mcap": Entry(lambda config: config.sources.mcap, mcap_source),
    "wits0": Entry(lambda config: config.sources.wits0, wits0_source),
    "opcua": Entry(lambda config: config.sources.opcua, opcua_source),
}
