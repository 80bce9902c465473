"""The daemon's ingest queue: raw messages from the sources to the pipeline, bounded in messages.

A source hands over one message at a time (:meth:`Inbox.put_nowait`, :meth:`Inbox.put`) or a
list of them (:meth:`Inbox.put_many`: what a transport had waiting, or a chunk of a recording);
the pipeline's consumer takes what is queued, up to a burst at a time (:meth:`Inbox.take`). A
list travels as one entry, so handing over and taking a burst costs about what one message did
through an ``asyncio.Queue`` (docs/daemon.md, "Bursts").

Backpressure as before: a source waits while ``limit`` messages are queued. A list is queued
whole once there is room, so at most one list more than ``limit`` may wait.
"""

from __future__ import annotations

import asyncio
from collections import deque

from tdmon.ingest.types import RawMessage


class Inbox:
    """A bounded FIFO of raw messages for one event loop (not thread-safe).

    Parameters
    ----------
    limit
        Messages queued at most before a source has to wait (``[queues] ingest``).
    """

    def __init__(self, limit: int) -> None:
        if limit < 1:
            raise ValueError(f"the ingest queue needs room for at least 1 message, got {limit}")
        self.limit = limit
        self._entries: deque[RawMessage | list[RawMessage]] = deque()
        self._count = 0
        self._ended = False
        self._readable = asyncio.Event()
        self._room = asyncio.Event()
        self._room.set()

    def __len__(self) -> int:
        """Messages queued."""
        return self._count

    def full(self) -> bool:
        return self._count >= self.limit

    def empty(self) -> bool:
        return self._count == 0

    def put_nowait(self, raw: RawMessage) -> None:
        """Queue one message now, room or not (check :meth:`full` first to keep the bound)."""
        self._entries.append(raw)
        self._count += 1
        self._readable.set()

    async def put(self, raw: RawMessage) -> None:
        """Queue one message once there is room."""
        await self._wait_for_room()
        self.put_nowait(raw)

    async def put_many(self, raws: list[RawMessage]) -> None:
        """Queue several messages, in order, once there is room (the list is kept: do not
        change it afterwards)."""
        if not raws:
            return
        await self._wait_for_room()
        self._entries.append(raws)
        self._count += len(raws)
        self._readable.set()

    def end(self) -> None:
        """No more messages: :meth:`take` returns what is queued, then None."""
        self._ended = True
        self._readable.set()

    async def take(self, most: int) -> list[RawMessage] | None:
        """The queued messages in order, waiting for the first: up to ``most`` of them, or a
        whole list put at once even if longer. None once ended and empty."""
        entries = self._entries
        while not entries:
            if self._ended:
                return None
            self._readable.clear()
            await self._readable.wait()
        taken: list[RawMessage] = []
        while entries and len(taken) < most:
            entry = entries.popleft()
            if type(entry) is list:
                taken.extend(entry)
            else:
                taken.append(entry)  # type: ignore[arg-type]  # a RawMessage
        self._count -= len(taken)
        if self._count < self.limit:
            self._room.set()
        return taken

    async def _wait_for_room(self) -> None:
        while self._count >= self.limit:
            self._room.clear()
            await self._room.wait()
