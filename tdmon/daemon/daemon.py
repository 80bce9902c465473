"""The asyncio daemon: supervised sources feed one bounded queue, one consumer runs the pipeline.

Backpressure: sources ``await queue.put``, so a slow pipeline slows the sources down instead of
losing data (the Zenoh bridge then blocks zenoh, and MQTT messages wait in the client). The only
places that can drop are the publisher queues, and they count every drop into the status.
Shutdown (``stop`` set, e.g. by SIGINT/SIGTERM): stop the sources, process everything already
queued, flush the aligner and the steps, send a last status, give the publishers time to send
what they hold, then close every sink.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass
from typing import Any, Protocol

from tdmon.daemon.pipeline import Pipeline
from tdmon.daemon.supervisor import Backoff, supervise
from tdmon.ingest.types import RawMessage
from tdmon.vocabulary import ConnectionState

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class SourceSpec:
    """A source the supervisor can (re)open: ``open()`` returns a fresh async context manager
    whose value is an async iterator of RawMessages."""

    name: str
    open: Callable[[], AbstractAsyncContextManager[AsyncIterator[RawMessage]]]
    finite: bool = False


class ConnectedPublisher(Protocol):
    """A sink that needs a supervised connection (e.g. MQTT): it queues in ``write`` and sends
    in ``pump``."""

    name: str

    def connect(self) -> AbstractAsyncContextManager[Any]: ...

    async def pump(self, connection: Any) -> None: ...

    async def drain(self, timeout: float) -> bool: ...


class Daemon:
    """Compose sources, the pipeline and connected publishers; run until ``stop``."""

    def __init__(
        self,
        pipeline: Pipeline,
        sources: Sequence[SourceSpec],
        publishers: Sequence[ConnectedPublisher] = (),
        *,
        queue_size: int = 10_000,
        status_interval: float = 1.0,
        tick_interval: float = 0.02,
        backoff: Backoff | None = None,
        stop_when_sources_done: bool = False,
        drain_timeout: float = 10.0,
    ) -> None:
        self.pipeline = pipeline
        self.sources = list(sources)
        self.publishers = list(publishers)
        self.queue_size = queue_size
        self.status_interval = status_interval
        self.tick_interval = tick_interval
        self.backoff = backoff or Backoff()
        self.stop_when_sources_done = stop_when_sources_done
        self.drain_timeout = drain_timeout
        self.connections: dict[str, str] = {}
        self.queue: asyncio.Queue[RawMessage | None] | None = None
        self.started = asyncio.Event()

    async def run(self, stop: asyncio.Event | None = None) -> None:
        stop = stop or asyncio.Event()
        queue: asyncio.Queue[RawMessage | None] = asyncio.Queue(maxsize=self.queue_size)
        self.queue = queue
        source_tasks = [
            asyncio.create_task(self._supervise_source(spec, queue), name=f"source {spec.name}")
            for spec in self.sources
        ]
        publisher_tasks = [
            asyncio.create_task(
                supervise(p.name, p.connect, p.pump, self.connections, self.backoff),
                name=f"publisher {p.name}",
            )
            for p in self.publishers
        ]
        consumer = asyncio.create_task(self._consume(queue), name="pipeline")
        housekeeping = asyncio.create_task(self._housekeeping(), name="housekeeping")
        self.started.set()
        try:
            waiters: list[asyncio.Future[Any]] = [asyncio.ensure_future(stop.wait()), consumer]
            if self.stop_when_sources_done and source_tasks:
                waiters.append(asyncio.ensure_future(asyncio.gather(*source_tasks,
                                                                    return_exceptions=True)))
            await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
            others = [waiter for waiter in waiters if waiter is not consumer]
            for waiter in others:
                if not waiter.done():
                    waiter.cancel()
            # collect the cancelled waiters' outcome (else "exception was never retrieved")
            await asyncio.gather(*others, return_exceptions=True)
            if consumer.done():
                consumer.result()  # a bug in the pipeline: surface it
        finally:
            await self._shutdown(queue, source_tasks, publisher_tasks, consumer, housekeeping)

    async def _supervise_source(self, spec: SourceSpec,
                                queue: asyncio.Queue[RawMessage | None]) -> None:
        async def pump(source: AsyncIterator[RawMessage]) -> None:
            async for raw in source:
                # put_nowait skips a coroutine round trip per message; await only when full
                if queue.full():
                    await queue.put(raw)
                else:
                    queue.put_nowait(raw)

        await supervise(spec.name, spec.open, pump, self.connections, self.backoff,
                        finite=spec.finite)

    async def _consume(self, queue: asyncio.Queue[RawMessage | None]) -> None:
        process = self.pipeline.process
        handled = 0
        while True:
            raw = await queue.get()
            while True:
                if raw is None:
                    return
                process(raw)
                handled += 1
                if handled % 256 == 0 or queue.empty():
                    break
                raw = queue.get_nowait()
            # give the sources and the housekeeping a turn between bursts
            await asyncio.sleep(0)

    async def _housekeeping(self) -> None:
        next_status = time.monotonic() + self.status_interval
        while True:
            await asyncio.sleep(self.tick_interval)
            self.pipeline.tick()
            if time.monotonic() >= next_status:
                next_status += self.status_interval
                self.emit_status()

    def emit_status(self) -> None:
        self.pipeline.emit("status", self.pipeline.status_message(self.connections))

    async def _shutdown(
        self,
        queue: asyncio.Queue[RawMessage | None],
        source_tasks: list[asyncio.Task[None]],
        publisher_tasks: list[asyncio.Task[None]],
        consumer: asyncio.Task[None],
        housekeeping: asyncio.Task[None],
    ) -> None:
        for task in source_tasks:
            task.cancel()
        await asyncio.gather(*source_tasks, return_exceptions=True)
        for spec in self.sources:
            if self.connections.get(spec.name) != ConnectionState.FINISHED:
                self.connections[spec.name] = ConnectionState.CLOSED
        housekeeping.cancel()
        await asyncio.gather(housekeeping, return_exceptions=True)
        if not consumer.done():
            await queue.put(None)  # everything queued before this is still processed
            await asyncio.gather(consumer, return_exceptions=True)
        self.pipeline.flush()
        self.emit_status()
        for publisher in self.publishers:
            if not await publisher.drain(self.drain_timeout):
                lost = int(getattr(publisher, "pending", 0))
                self.pipeline.stats.dropped += lost
                log.error("%s: %d results unsent after %.0f s at shutdown, dropped",
                          publisher.name, lost, self.drain_timeout)
        for task in publisher_tasks:
            task.cancel()
        await asyncio.gather(*publisher_tasks, return_exceptions=True)
        for publisher in self.publishers:
            self.connections[publisher.name] = ConnectionState.CLOSED
        self.pipeline.close_sinks()
