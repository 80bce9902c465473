"""The builder tables' machinery: what source and sink builders share while a daemon is built.

A builder table (:data:`tdmon.daemon.sources.SOURCES`, :data:`tdmon.daemon.sinks.SINKS`,
:data:`tdmon.daemon.sinks.PUBLISHERS`) maps a configuration section to the function that
builds what the section asks for. Each row is an :class:`Entry`: where the section is in the
:class:`~tdmon.config.daemon.DaemonConfig` (None when it is not configured) and a typed
builder ``async (wiring, section) -> None`` that adds its source or sink to the
:class:`Wiring`. Adding a transport is one builder and one row (docs/daemon.md, "Composing").
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

import zenoh

from tdmon.config.daemon import DaemonConfig, ZenohConfig
from tdmon.daemon.daemon import ConnectedPublisher, SourceSpec
from tdmon.daemon.pipeline import Pipeline, Sink, Stats
from tdmon.ingest.zenoh_io import open_session

S = TypeVar("S")


@dataclass
class Wiring:
    """What the builders add to, in table order, and the resources they share.

    ``sinks`` are in the order the pipeline writes to them; ``owned`` the ones built here
    (closed here if the daemon is never assembled), ``connected`` the sinks that need a
    supervised connection. ``pipeline`` is set once it exists, for the recorder's alarms.
    """

    config: DaemonConfig
    stats: Stats
    sources: list[SourceSpec] = field(default_factory=list)
    sinks: list[Sink] = field(default_factory=list)
    owned: list[Sink] = field(default_factory=list)
    connected: list[ConnectedPublisher] = field(default_factory=list)
    pipeline: Pipeline | None = None
    _sessions: list[tuple[ZenohConfig, zenoh.Session]] = field(default_factory=list)

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

    def add_publisher(self, sink: Sink, connection: ConnectedPublisher | None = None) -> None:
        """A publishing sink; ``connection`` when the daemon must supervise its connection."""
        self.add_sink(sink)
        if connection is not None:
            self.connected.append(connection)

    def emit_alarm(self, message: dict[str, Any]) -> None:
        """Send a sink's health alarm (e.g. the recorder's) through the pipeline, if built."""
        if self.pipeline is not None:
            self.pipeline.emit("alarm", message)

    async def zenoh_session(self, config: ZenohConfig) -> zenoh.Session:
        """The session for ``config``, opened on first use.

        Keyed by the configuration object, not its value: ``publish.zenoh = true`` passes the
        source's own section and so shares its session, while a ``[publish.zenoh]`` table
        always gets a session of its own.
        """
        for opened_for, session in self._sessions:
            if opened_for is config:
                return session
        session = await asyncio.to_thread(open_session, config)
        self._sessions.append((config, session))
        return session

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
    build: Callable[[Wiring, S], Awaitable[None]]

    async def wire(self, wiring: Wiring) -> None:
        """Build the section's source or sink when the section is configured."""
        section = self.section(wiring.config)
        if section is not None:
            await self.build(wiring, section)


class Wire(Protocol):
    """A row of any builder table (an :class:`Entry` of any section type)."""

    async def wire(self, wiring: Wiring) -> None: ...


#: A builder table: section name -> row, built in this order.
Table = Mapping[str, Wire]


async def wire(table: Table, wiring: Wiring) -> None:
    """Build every configured row of ``table`` into ``wiring``, in table order."""
    for entry in table.values():
        await entry.wire(wiring)
