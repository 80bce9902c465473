"""Run the daemon for a config file until SIGINT/SIGTERM (what ``tdmon run`` calls); SIGHUP
re-reads the well file in use (docs/daemon.md, "Model coverage")."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import logging
import signal
from collections.abc import Callable, Iterator
from typing import Any

from tdmon.config.daemon import DaemonConfig
from tdmon.daemon.build import Built, build_daemon
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
        if config.is_fleet:
            from tdmon.daemon.fleet import build_fleet

            building = build_fleet(config, **build_options)
        else:
            building = build_daemon(config, **build_options)
        async with building as built:
            if replays_only(config) and not config.is_fleet:
                # a recording of a replay spans the rig's time (docs/recording.md)
                built.pipeline.follow_input_time()
            log.info("tdmon daemon running: prefix %s, sources %s", config.prefix,
                     ", ".join(s.name for s in built.daemon.sources))
            with reload_on_sighup(built), collections_for_a_stream():
                await built.daemon.run(stop)
            return built.stats


#: Allocations between young-generation garbage collections while the daemon runs (CPython's
#: default is 700). Over MQTT each message leaves objects alive for a while (its
#: acknowledgement until the recorder flushes, its key in the window of recent deliveries):
#: at the default, 60 000 messages made 446 collections, 0.64 s (12 % of the run) with the
#: built pipeline in the heap; with this and the freeze, 14 collections, 0.05 s.
STREAM_GC_YOUNG = 10_000


@contextlib.contextmanager
def collections_for_a_stream() -> Iterator[None]:
    """While inside: what was built so far (well model, grids, filters) is moved out of the
    collector's way (``gc.freeze()``, as the fleet does after each rig), and young collections
    come every :data:`STREAM_GC_YOUNG` allocations. Both are undone on the way out."""
    previous = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(max(STREAM_GC_YOUNG, previous[0]), *previous[1:])
    try:
        yield
    finally:
        gc.set_threshold(*previous)
        gc.unfreeze()


def replays_only(config: DaemonConfig) -> bool:
    """Whether every source of ``config`` replays a recording (``[sources.mcap]`` alone)."""
    sources = config.sources
    return sources.mcap is not None and all(
        getattr(sources, name) is None for name in type(sources).model_fields if name != "mcap")


@contextlib.contextmanager
def reload_on_sighup(built: Built) -> Iterator[None]:
    """While inside, SIGHUP asks the coverage step to re-read the well file in use on the next
    frame (:class:`tdmon.daemon.steps.coverage.CoverageStep`); without a well file it is
    logged and ignored rather than ending the daemon. Only in the main thread."""
    from tdmon.daemon.steps.coverage import CoverageStep

    loop = asyncio.get_running_loop()
    coverage = next((s for s in built.steps if isinstance(s, CoverageStep)), None)

    def handle() -> None:
        if coverage is None:
            log.info("SIGHUP received: no well file to reload")
            return
        log.info("SIGHUP received: re-reading %s on the next frame", coverage.well_file.path)
        coverage.request_reload()

    try:
        loop.add_signal_handler(signal.SIGHUP, handle)
    except (NotImplementedError, RuntimeError):  # not the main thread
        yield
        return
    try:
        yield
    finally:
        loop.remove_signal_handler(signal.SIGHUP)


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
