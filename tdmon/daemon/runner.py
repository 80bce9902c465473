"""Run the daemon for a config file until SIGINT/SIGTERM (what ``tdmon run`` calls)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
from collections.abc import Callable, Iterator
from typing import Any

from tdmon.config.daemon import DaemonConfig
from tdmon.daemon.build import build_daemon
from tdmon.daemon.pipeline import Stats

log = logging.getLogger(__name__)


async def run_daemon(config: DaemonConfig, stop: asyncio.Event | None = None,
                     **build_options: Any) -> Stats:
    """Run until ``stop`` is set, a signal arrives, or every (finite) source is done.

    SIGINT and SIGTERM start the graceful shutdown: whatever has arrived is processed,
    recorded and published before this returns.
    """
    stop = stop or asyncio.Event()
    with stop_on_signals(stop):
        async with build_daemon(config, **build_options) as built:
            if replays_only(config):
                # a recording of a replay spans the rig's time (docs/recording.md)
                built.pipeline.follow_input_time()
            log.info("tdmon daemon running: prefix %s, sources %s", config.prefix,
                     ", ".join(s.name for s in built.daemon.sources))
            await built.daemon.run(stop)
            return built.stats


def replays_only(config: DaemonConfig) -> bool:
    """Whether every source of ``config`` replays a recording (``[sources.mcap]`` alone)."""
    sources = config.sources
    return sources.mcap is not None and all(
        getattr(sources, name) is None for name in type(sources).model_fields if name != "mcap")


@contextlib.contextmanager
def stop_on_signals(stop: asyncio.Event,
                    on_signal: Callable[[signal.Signals], None] | None = None) -> Iterator[None]:
    """While inside, SIGINT and SIGTERM set ``stop`` (the daemon's graceful shutdown) and call
    ``on_signal``; a second signal of the same kind is handled the default way again (Ctrl-C
    twice interrupts a shutdown that takes too long). Only in the main thread; elsewhere
    nothing is installed."""
    loop = asyncio.get_running_loop()
    installed: list[signal.Signals] = []

    def handle(sig: signal.Signals) -> None:
        log.info("%s received: flushing and stopping", sig.name)
        stop.set()
        if sig in installed:
            loop.remove_signal_handler(sig)
            installed.remove(sig)
        if on_signal is not None:
            on_signal(sig)

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, handle, sig)
            installed.append(sig)
        except (NotImplementedError, RuntimeError):  # not the main thread
            pass
    try:
        yield
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)
