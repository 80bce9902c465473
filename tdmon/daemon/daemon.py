"""The asyncio daemon: supervised sources feed one bounded queue, one consumer runs the pipeline.

Backpressure: sources ``await queue.put``, so a slow pipeline slows the sources down instead of
losing data (the Zenoh bridge then blocks zenoh, and MQTT messages wait in the client). The only
places that can drop are the publisher queues and, for QoS 0 messages beyond ``[queues] ingest``,
the MQTT client's queue; they count every drop into the status.
Shutdown (``stop`` set, e.g. by SIGINT/SIGTERM): stop taking messages from the sources, process
everything already queued, flush the recorder and acknowledge what it holds (the sources'
connections are still open for that), close the sources, flush the aligner and the steps, send a
last status, give the publishers time to send what they hold, then close every sink.

Acknowledgements (at-least-once, docs/daemon.md): a message with an ``ack`` is acknowledged to
its transport only once the pipeline has processed it and the recorder has flushed it into its
file (:class:`AckWindow`), so a daemon killed at any moment leaves every unrecorded message with
the broker, which sends it again.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import AsyncIterator, Callable, Sequence
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass
from typing import Any, Protocol

from tdmon.daemon.inbox import Inbox
from tdmon.daemon.pipeline import Pipeline
from tdmon.daemon.supervisor import Backoff, supervise
from tdmon.ingest.types import RawMessage
from tdmon.record.sink import Recorder
from tdmon.vocabulary import ConnectionState

log = logging.getLogger(__name__)

#: Queued messages handed to the pipeline in one call at most (a burst, docs/daemon.md).
BURST = 256


@dataclass(frozen=True, slots=True)
class SourceSpec:
    """A source the supervisor can (re)open: ``open()`` returns a fresh async context manager
    whose value is an async iterator of RawMessages."""

    name: str
    open: Callable[[], AbstractAsyncContextManager[AsyncIterator[RawMessage]]]
    finite: bool = False


class ConnectedPublisher(Protocol):
    """A sink that needs a supervised connection (e.g. MQTT): it queues in ``write_batch`` and
    sends in ``pump``."""

    name: str

    def connect(self) -> AbstractAsyncContextManager[Any]: ...

    async def pump(self, connection: Any) -> None: ...

    async def drain(self, timeout: float) -> bool: ...

    @property
    def pending(self) -> int:
        """Messages queued and not sent yet."""
        ...


class AckWindow:
    """Acknowledgements waiting for the recorders to have what they acknowledge in their files.

    ``recorders`` are the flight recorders (:class:`~tdmon.record.sink.Recorder`; the list may
    grow while the daemon runs, as a fleet's rigs appear); without any, a message is
    acknowledged as soon as it is processed. The window never waits for a recorder: every
    ``check_s`` it takes each recorder's mark of what was written (``durable_mark``), and lets
    the acknowledgements that were waiting then go once every mark is in the file
    (``is_durable``; the recorder's own flush, every ``[recorder] flush_interval``, puts it
    there). The broker sends only a limited number of unacknowledged messages (mosquitto's
    ``max_inflight_messages``), so waiting for the next scheduled flush could starve it: the
    window asks the recorders for a flush (``request_flush``) when ``batch``
    acknowledgements wait, when at least ``idle_min`` wait and no message has come for
    ``idle_s`` (the broker is waiting for us), or when the oldest has waited ``max_age_s``.
    Only ``force`` (shutdown) flushes, waits and acknowledges everything.
    """

    def __init__(self, recorders: Sequence[Recorder], batch: int = 500, idle_s: float = 0.05,
                 idle_min: int = 16, max_age_s: float = 5.0, check_s: float = 0.05,
                 before_ack: Callable[[], None] | None = None) -> None:
        self.recorders = recorders
        #: called before acknowledgements go (the loss state is saved, so that what the
        #: broker will not send again is in it)
        self.before_ack = before_ack
        self.batch = batch
        self.idle_s = idle_s
        self.idle_min = idle_min
        self.max_age_s = max_age_s
        self.check_s = check_s
        self._pending: deque[tuple[float, Callable[[], None]]] = deque()
        self._last_check = float("-inf")
        # (leading entries waiting when the marks were taken, each recorder and its mark)
        self._marks: deque[tuple[int, list[tuple[Recorder, int]]]] = deque()
        self.acknowledged = 0
        self.forced_flushes = 0

    def __len__(self) -> int:
        return len(self._pending)

    def add(self, acks: list[Callable[[], None]], now: float) -> None:
        """Acknowledgements of messages just written; released by :meth:`release`."""
        if not self.recorders:
            self._ack(acks)
            return
        self._pending.extend((now, ack) for ack in acks)

    def release(self, now: float, idle: float, force: bool = False) -> None:
        """Acknowledge what the recorders have in their files; ask for a flush first when it
        is time (``idle``: seconds since the last message arrived); with ``force``, flush,
        wait and acknowledge everything."""
        pending, marks = self._pending, self._marks
        if not pending:
            return
        if force:
            self._release_all()
            return
        self._mark(now, idle)
        released = 0
        while marks and all(recorder.is_durable(mark) for recorder, mark in marks[0][1]):
            released = marks.popleft()[0]
        if released:
            for index, (waiting, taken) in enumerate(marks):
                marks[index] = (waiting - released, taken)
            self._ack([pending.popleft()[1] for _ in range(released)])

    def _release_all(self) -> None:
        """Flush every recorder, wait, and acknowledge everything pending."""
        for recorder in self.recorders:
            recorder.flush()  # a failed recorder flushes nothing: monitoring goes on
        self.forced_flushes += 1
        self._marks.clear()
        self._ack([ack for _, ack in self._pending])
        self._pending.clear()

    def _mark(self, now: float, idle: float) -> None:
        """Take the recorders' durability marks for what is pending, and ask them to flush
        when a batch is due (full, idle, or its oldest too old)."""
        pending, marks = self._pending, self._marks
        count = len(pending)
        due = (count >= self.batch or (idle >= self.idle_s and count >= self.idle_min)
               or now - pending[0][0] >= self.max_age_s)
        if due or now - self._last_check >= self.check_s:
            self._last_check = now
            if not marks or marks[-1][0] < count:
                marks.append((count, [(r, r.durable_mark()) for r in self.recorders]))
            if due:
                for recorder in self.recorders:
                    recorder.request_flush()
                self.forced_flushes += 1

    def _ack(self, acks: list[Callable[[], None]]) -> None:
        if acks and self.before_ack is not None:
            self.before_ack()
        for ack in acks:
            try:
                ack()
            except Exception:  # a transport that cannot acknowledge resends: not fatal
                log.debug("acknowledgement failed", exc_info=True)
        self.acknowledged += len(acks)


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
        self.queue: Inbox | None = None
        self.started = asyncio.Event()
        self.acks = AckWindow([])
        self._accepting = True
        self._last_arrival = time.monotonic()

    async def run(self, stop: asyncio.Event | None = None) -> None:
        stop = stop or asyncio.Event()
        queue = Inbox(self.queue_size)
        self.queue = queue
        self.acks = AckWindow(self.pipeline.recorders, before_ack=self.pipeline.save_state)
        self._accepting = True
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

    async def _supervise_source(self, spec: SourceSpec, queue: Inbox) -> None:
        async def pump(source: AsyncIterator[RawMessage]) -> None:
            batches = getattr(source, "batches", None)
            if batches is not None:
                # a source that hands over what it has at once: one entry per list
                async for batch in batches():
                    if not self._accepting:
                        continue  # shutting down: left unacknowledged, the broker keeps it
                    self._last_arrival = time.monotonic()
                    await queue.put_many(batch)
                return
            async for raw in source:
                if not self._accepting:
                    continue  # shutting down: left unacknowledged, the broker keeps it
                self._last_arrival = time.monotonic()
                # put_nowait skips a coroutine round trip per message; await only when full
                if queue.full():
                    await queue.put(raw)
                else:
                    queue.put_nowait(raw)

        await supervise(spec.name, spec.open, pump, self.connections, self.backoff,
                        finite=spec.finite)

    async def _consume(self, queue: Inbox) -> None:
        # A burst: what is queued, up to BURST messages, handed to the pipeline in one call
        # (its raw input and samples are recorded together: docs/daemon.md, "Bursts").
        process_burst = self.pipeline.process_burst
        stats = self.pipeline.stats
        acks: list[Callable[[], None]] = []
        while True:
            burst = await queue.take(BURST)
            if burst is None:  # ended (shutdown), after everything queued before
                self._settle(acks)
                return
            fresh: list[RawMessage] = []
            for raw in burst:
                if raw.duplicate:
                    stats.duplicate_deliveries += 1  # already handed to the pipeline this run
                else:
                    if raw.redelivered:
                        stats.redelivered += 1
                    fresh.append(raw)
                if raw.ack is not None:
                    acks.append(raw.ack)
            process_burst(fresh)
            self._settle(acks)
            # give the sources and the housekeeping a turn between bursts
            await asyncio.sleep(0)

    def _settle(self, acks: list[Callable[[], None]]) -> None:
        """Hand a burst's acknowledgements to the window and release what may go."""
        now = time.monotonic()
        if acks:
            self.acks.add(acks, now)
            acks.clear()
        self.acks.release(now, now - self._last_arrival)

    async def _housekeeping(self) -> None:
        next_status = time.monotonic() + self.status_interval
        while True:
            await asyncio.sleep(self.tick_interval)
            self.pipeline.tick()
            now = time.monotonic()
            self.acks.release(now, now - self._last_arrival)
            if time.monotonic() >= next_status:
                next_status += self.status_interval
                self.emit_status()

    def emit_status(self) -> None:
        self.pipeline.emit_status(self.connections)

    async def _shutdown(
        self,
        queue: Inbox,
        source_tasks: list[asyncio.Task[None]],
        publisher_tasks: list[asyncio.Task[None]],
        consumer: asyncio.Task[None],
        housekeeping: asyncio.Task[None],
    ) -> None:
        # Sources stay connected until what they delivered is processed and acknowledged;
        # what they deliver meanwhile is left unacknowledged for the next run.
        self._accepting = False
        housekeeping.cancel()
        await asyncio.gather(housekeeping, return_exceptions=True)
        if not consumer.done():
            queue.end()  # everything queued before this is still processed
            await asyncio.gather(consumer, return_exceptions=True)
        if len(self.acks):
            self.acks.release(time.monotonic(), 0.0, force=True)
            await asyncio.sleep(0.2)  # let the transports write the acknowledgements out
        for task in source_tasks:
            task.cancel()
        await asyncio.gather(*source_tasks, return_exceptions=True)
        for spec in self.sources:
            if self.connections.get(spec.name) != ConnectionState.FINISHED:
                self.connections[spec.name] = ConnectionState.CLOSED
        self.pipeline.flush()
        self.emit_status()
        for publisher in self.publishers:
            if not await publisher.drain(self.drain_timeout):
                lost = publisher.pending
                self.pipeline.stats.dropped += lost
                log.error("%s: %d results unsent after %.0f s at shutdown, dropped",
                          publisher.name, lost, self.drain_timeout)
        for task in publisher_tasks:
            task.cancel()
        await asyncio.gather(*publisher_tasks, return_exceptions=True)
        for publisher in self.publishers:
            self.connections[publisher.name] = ConnectionState.CLOSED
        self.pipeline.close_sinks()
