"""The one place where connections are retried: open, run, and on failure back off and reopen.

Sources and publishers only know how to connect once (an async context manager) and how to
work on an open connection; they raise :class:`tdmon.errors.IngestError` when that fails. The
supervisor keeps the state of each connection for the status message.
"""

from __future__ import annotations

import asyncio
import logging
import random
from collections.abc import Awaitable, Callable
from contextlib import AbstractAsyncContextManager
from dataclasses import dataclass
from typing import TypeVar

from tdmon.errors import IngestError
from tdmon.vocabulary import ConnectionState

log = logging.getLogger(__name__)

T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class Backoff:
    """Exponential backoff with jitter [s]; the delay resets once a connection succeeds."""

    initial: float = 0.5
    maximum: float = 30.0
    factor: float = 2.0
    jitter: float = 0.1

    def next(self, delay: float) -> float:
        return min(delay * self.factor, self.maximum)

    def wait(self, delay: float) -> float:
        # jitter keeps many daemons from hammering a restarted broker in lock step
        return delay * (1.0 + self.jitter * random.random())


async def supervise(
    name: str,
    connect: Callable[[], AbstractAsyncContextManager[T]],
    work: Callable[[T], Awaitable[None]],
    states: dict[str, str],
    backoff: Backoff = Backoff(),
    finite: bool = False,
) -> None:
    """Run ``work`` on a connection from ``connect`` until cancelled, reconnecting on failure.

    A ``finite`` connection (a recording) ends the supervision when ``work`` returns; for the
    others returning is treated like a lost connection. ``states[name]`` tracks the state.
    """
    delay = backoff.initial
    attempt = 0
    while True:
        attempt += 1
        states[name] = ConnectionState.CONNECTING
        try:
            async with connect() as connection:
                states[name] = ConnectionState.CONNECTED
                if attempt > 1:
                    log.info("%s: connected again after %d attempts", name, attempt - 1)
                attempt = 0
                delay = backoff.initial
                await work(connection)
            if finite:
                states[name] = ConnectionState.FINISHED
                return
            reason = "connection ended"
        except (IngestError, OSError) as exc:
            reason = str(exc)
        wait = backoff.wait(delay)
        states[name] = f"{ConnectionState.RETRYING} in {wait:.1f} s: {reason}"
        log.warning("%s: %s; retrying in %.1f s", name, reason, wait)
        await asyncio.sleep(wait)
        delay = backoff.next(delay)
