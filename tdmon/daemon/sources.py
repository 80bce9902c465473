"""The sources a daemon reads from, one builder per ``[sources.<name>]`` section.

Each builder adds a :class:`~tdmon.daemon.daemon.SourceSpec` that the supervisor opens (and
reopens after a failure). A new transport is its module in ``tdmon.ingest``, a section in
:class:`~tdmon.config.daemon.SourcesConfig` and one builder and row here.
"""

from __future__ import annotations

from tdmon.config.daemon import McapSourceConfig, MqttConfig, ZenohConfig
from tdmon.daemon.daemon import SourceSpec
from tdmon.daemon.wiring import Entry, Table, Wiring
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.mqtt import MqttSource, RecentDeliveries
from tdmon.ingest.zenoh_io import ZenohSource, key_expr_for


async def zenoh_source(wiring: Wiring, section: ZenohConfig) -> None:
    """Subscribe to everything under the prefix on the section's session."""
    session = await wiring.zenoh_session(section)
    key_expr = key_expr_for(wiring.config.prefix)
    ignore = (wiring.own_prefix,)
    max_buffer = wiring.config.queues.ingest

    def open_zenoh() -> ZenohSource:
        return ZenohSource(session, key_expr, ignore, max_buffer)

    wiring.sources.append(SourceSpec("zenoh", open_zenoh))


async def mqtt_source(wiring: Wiring, section: MqttConfig) -> None:
    """Subscribe to ``<prefix>/#`` on the section's broker."""
    subscribe = [f"{wiring.config.prefix}/#"]
    ignore = (wiring.own_prefix,)
    base = wiring.base
    recent = RecentDeliveries()  # over reconnects: a resent message is recognised

    def open_mqtt() -> MqttSource:
        return MqttSource(section, subscribe, ignore, base, recent)

    wiring.sources.append(SourceSpec("mqtt", open_mqtt))


async def mcap_source(wiring: Wiring, section: McapSourceConfig) -> None:
    """Replay a recording (a finite source: the daemon may stop when it is done)."""
    path = wiring.config.resolve(section.path)
    speed = None if section.speed == "max" else float(section.speed)

    def open_mcap() -> McapSource:
        return McapSource(path, speed)

    wiring.sources.append(SourceSpec("mcap", open_mcap, finite=True))


#: ``[sources.<name>]`` -> its builder, in the order the sources are started.
SOURCES: Table = {
    "zenoh": Entry(lambda config: config.sources.zenoh, zenoh_source),
    "mqtt": Entry(lambda config: config.sources.mqtt, mqtt_source),
    "mcap": Entry(lambda config: config.sources.mcap, mcap_source),
}
