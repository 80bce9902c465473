"""Run one replay from Python, synchronously: :func:`replay_file` (``tdmon.replay(...)``).

The daemon's pipeline is :func:`tdmon.replay.driver.replay`, as for ``tdmon replay``; this adds
what a caller outside asyncio needs: a configuration given as a file, an object or not at all
(then the replay's expectations name it), and an event loop of its own (in a helper thread
when the caller already runs one, e.g. a Jupyter notebook).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import os
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from tdmon.errors import ConfigError

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig
    from tdmon.replay.driver import ReplayResult

__all__ = ["replay_file", "resolve_config", "run_sync"]

T = TypeVar("T")


def resolve_config(
    recording: str | os.PathLike[str], config: str | os.PathLike[str] | DaemonConfig | None,
) -> DaemonConfig:
    """The daemon configuration of a replay: ``config`` itself, the daemon file it names, or
    (None) the file named by the replay's expectations (``expectations/<name>.toml`` beside it).

    Raises
    ------
    ConfigError
        The file is unusable, or None was given and the replay has no expectations.
    """
    from tdmon.config.daemon import DaemonConfig, load_daemon_config

    if isinstance(config, DaemonConfig):
        return config
    if config is not None:
        return load_daemon_config(Path(config))
    from tdmon.config.expectations import load_expectations
    from tdmon.replay.expectations import find_expectations

    found = find_expectations(recording)
    if found is None:
        raise ConfigError(str(recording), "--config",
                          "no expectations beside the replay name a daemon file; give one")
    return load_daemon_config(load_expectations(found).config_path)


def run_sync(coroutine: Coroutine[Any, Any, T]) -> T:
    """Run ``coroutine`` to the end: in this thread, or in a helper thread when an event loop
    already runs here (``asyncio.run`` refuses to nest)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(coroutine)
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="tdmon-replay") as pool:
        return pool.submit(asyncio.run, coroutine).result()


def replay_file(
    recording: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | DaemonConfig | None = None,
    rrd: str | os.PathLike[str] | None = None,
    speed: float | None = None,
    progress: Callable[[int], None] | None = None,
    recorder: Literal["process", "inline"] = "inline",
) -> ReplayResult:
    """Replay ``recording`` through the daemon's pipeline and record everything to ``out``.

    Parameters
    ----------
    recording : the replay (MCAP with ``/tdmon/raw`` input: a flight recording, a simulated
        session, an imported log)
    out : the flight recording to write (replaced if present)
    config : the daemon file, a loaded ``DaemonConfig``, or None for the file named by the
        replay's expectations
    rrd : a Rerun recording to write as well
    speed : real time x ``speed``; None: as fast as possible
    progress : called with the number of input messages handled since the last call
    recorder : ``"inline"`` (default) records in this process; ``"process"`` from a child
        process, on a second core (at most ~5 % faster on a long replay when a core is idle,
        more CPU in all)

    Returns
    -------
    ReplayResult
        Counts, rig-state shares and the path of the recording (``.out``; read it with
        :func:`tdmon.read_recording`).

    Raises
    ------
    TdmonError
        The replay cannot be read, the configuration is unusable, ``out`` cannot be written.
    """
    from tdmon.replay.driver import check_replay_file, replay

    check_replay_file(Path(recording))  # a missing replay is named as such, not by its config
    daemon_config = resolve_config(recording, config)
    return run_sync(replay(Path(recording), daemon_config, Path(out),
                           rrd=None if rrd is None else Path(rrd), speed=speed, progress=progress,
                           separate_writer=recorder == "process"))
