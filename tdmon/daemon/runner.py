"""Run the daemon for a config file until SIGINT/SIGTERM (what ``tdmon run`` calls)."""

from __future__ import annotations

import asyncio
import logging
import signal
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
    loop = asyncio.get_running_loop()
    installed = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, _on_signal, sig, stop)
            installed.append(sig)
        except (NotImplementedError, RuntimeError):  # not the main thread
            pass
    try:
        async with build_daemon(config, **build_options) as built:
            log.info("tdmon daemon running: prefix %s, sources %s", config.prefix,
                     ", ".join(s.name for s in built.daemon.sources))
            await built.daemon.run(stop)
            return built.stats
    finally:
        for sig in installed:
            loop.remove_signal_handler(sig)


def _on_signal(sig: signal.Signals, stop: asyncio.Event) -> None:
    log.info("%s received: flushing and stopping", sig.name)
    stop.set()
