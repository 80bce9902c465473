"""The builder tables' machinery: what source and sink builders share while a daemon is built.

A builder table (:data:`tdmon.daemon.sources.SOURCES`, :data:`tdmon.daemon.sinks.SINKS`,
:data:`tdmon.daemon.sinks.PUBLISHERS`) maps a configuration section to the function that
builds what the section asks for. Each row is an :class:`Entry`: where the section is in the
:class:`~tdmon.config.daemon.DaemonConfig` (None when it is not configured) and a typed
builder ``(wiring, section) -> None`` that adds its source or sink to the :class:`Wiring`.
Adding a transport is one builder and one row (docs/daemon.md, "Composing"). A fleet daemon
wires each rig's sinks from the same tables, on a wiring of the rig's own
(:meth:`Wiring.for_rig`) that shares the daemon's sessions and connections.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import zenoh

from tdmon.config.daemon import DaemonConfig, ZenohConfig
from tdmon.daemon.daemon import ConnectedPublisher, SourceSpec
from tdmon.daemon.pipeline import Pipeline, Sink, Stats
from tdmon.ingest.zenoh_io import open_session

S = TypeVar("S")
P = TypeVar("P", bound=ConnectedPublisher)


@dataclass
class Wiring:
    """What the builders add to, in table order, and the resources they share.

    ``sinks`` are in the order the pipeline writes to them; ``owned`` the ones built here
    (closed here if the daemon is never assembled), ``connected`` the publishers whose
    connection the daemon supervises. ``pipeline`` is set once it exists, for the recorder's
    alarms. ``in_fleet``: the wiring of one rig of a fleet daemon (:meth:`for_rig`).
    """

    config: DaemonConfig
    stats: Stats
    in_fleet: bool = False
    sources: list[SourceSpec] = field(default_factory=list)
    sinks: list[Sink] = field(default_factory=list)
    owned: list[Sink] = field(default_factory=list)
    connected: list[ConnectedPublisher] = field(default_factory=list)
    pipeline: Pipeline | None = None
    # shared with the wirings made by for_rig: sessions and connections by their section,
    # and the daemon's counters (a shared publisher's drops are the daemon's, not a rig's)
    _sessions: list[tuple[ZenohConfig, zenoh.Session]] = field(default_factory=list)
    _connections: list[tuple[object, ConnectedPublisher]] = field(default_factory=list)
    _daemon_stats: Stats | None = None

    def for_rig(self, config: DaemonConfig) -> Wiring:
        """The wiring of one rig of a fleet daemon (``config``: the rig's own, see
        ``DaemonConfig.for_rig``): its own sinks and counters; this wiring's Zenoh sessions,
        supervised connections and counters of drops."""
        return Wiring(config, Stats(), in_fleet=True, connected=self.connected,
                      _sessions=self._sessions, _connections=self._connections,
                      _daemon_stats=self._daemon_stats or self.stats)

    @property
    def base(self) -> Path | None:
        """The config file's folder: relative paths in the file (TLS files) start there."""
        source_file = self.config.source_file
        return source_file.parent if source_file else None

    @property
    def own_prefix(self) -> str:
        """Topics under which the daemon publishes: a source sharing the prefix skips them."""
        return f"{self.config.prefix}/tdmon/"

    def add_sink(self, sink: Sink) -> None:
        self.sinks.append(sink)
        self.owned.append(sink)

    def count_drop(self, count: int = 1) -> None:
        """Count results a publisher had to drop, in the daemon's status."""
        (self._daemon_stats or self.stats).count_drop(count)

    def emit_alarm(self, message: dict[str, Any]) -> None:
        """Send a sink's health alarm (e.g. the recorder's) through the pipeline, if built."""
        if self.pipeline is not None:
            self.pipeline.emit("alarm", message)

    def zenoh_session(self, config: ZenohConfig) -> zenoh.Session:
        """The session for ``config``, opened on first use (blocking: while the daemon is
        built, or when a fleet's first rig publishes on a session of its own).

        Keyed by the configuration object, not its value: ``publish.zenoh = true`` passes the
        source's own section and so shares its session, while a ``[publish.zenoh]`` table
        always gets a session of its own.
        """
        for opened_for, session in self._sessions:
            if opened_for is config:
                return session
        session = open_session(config)
        self._sessions.append((config, session))
        return session

    def connection(self, section: object, make: Callable[[], P]) -> P:
        """The publisher of ``section`` whose connection the daemon supervises, made by
        ``make`` on first use (a fleet's rigs share it; keyed by the section object, as
        :meth:`zenoh_session`)."""
        for made_for, publisher in self._connections:
            if made_for is section:
                return publisher  # type: ignore[return-value]  # made by this section's make
        publisher = make()
        self._connections.append((section, publisher))
        self.connected.append(publisher)
        return publisher

    async def release(self, *, close_sinks: bool) -> None:
        """Close the sessions, and first the sinks built here when ``close_sinks`` (the daemon
        closes them when it runs)."""
        try:
            if close_sinks:
                for sink in self.owned:
                    sink.close()
        finally:
            for _, session in self._sessions:
                with contextlib.suppress(Exception):  # closing a session that lost its peers
                    await asyncio.to_thread(session.close)
            self._sessions.clear()


@dataclass(frozen=True)
class Entry(Generic[S]):
    """One row of a builder table: the section's place in the config and its builder."""

    section: Callable[[DaemonConfig], S | None]
    build: Callable[[Wiring, S], None]

    def wire(self, wiring: Wiring) -> None:
        """Build the section's source or sink when the section is configured."""
        section = self.section(wiring.config)
        if section is not None:
            self.build(wiring, section)


class Wire(Protocol):
    """A row of any builder table (an :class:`Entry` of any section type)."""

    def wire(self, wiring: Wiring) -> None: ...


#: A builder table: section name -> row, built in this order.
Table = Mapping[str, Wire]


def wire(table: Table, wiring: Wiring) -> None:
    """Build every configured row of ``table`` into ``wiring``, in table order."""
    for entry in table.values():
        entry.wire(wiring)
