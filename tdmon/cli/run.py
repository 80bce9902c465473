"""``tdmon run`` (the live daemon) and ``tdmon publish`` (play the rig from a CSV or recording)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import signal
import sys
import time
from collections.abc import Coroutine, Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.cli.arguments import (
    add_units_option,
    display_units,
    flag_targets,
    toward_zenoh_source,
)
from tdmon.errors import TdmonError

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig

#: Environment variable ``tdmon publish`` takes the MQTT password from when no option names one.
PASSWORD_ENV = "TDMON_MQTT_PASSWORD"


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``run`` and ``publish``."""
    run = subparsers.add_parser(
        "run", help="run the live daemon",
        description="Subscribe to the rig's channels (MQTT and/or Zenoh, or replay a "
                    "recording), model and record, publish results on <prefix>/tdmon/<name>. "
                    "Ctrl-C or SIGTERM flushes everything and exits 0; SIGHUP re-reads the "
                    "well file in use (docs/daemon.md, Model coverage).")
    run.add_argument("--config", required=True, type=Path, help="daemon TOML file")
    run.add_argument("--log-level", default="info",
                     choices=["debug", "info", "warning", "error"])
    add_units_option(run, "the Rerun views (default: $TDMON_UNITS, else the file's [display] "
                     "units)")
    run.set_defaults(func=_run)

    pub = subparsers.add_parser(
        "publish", help="publish a CSV log or a recording as a rig would",
        description="Send one JSON message per channel and row on <prefix>/<channel> "
                    "({'t', 'value', 'unit'}), paced at real time x SPEED or as fast as "
                    "possible. Connection from --config (the daemon's file: publishes to its "
                    "source) or from --mqtt / --zenoh-connect.")
    pub.add_argument("source", type=Path, help="CSV file (e.g. the Volve F-4 layout) or .mcap")
    pub.add_argument("--config", type=Path, help="daemon TOML: publish where it listens")
    pub.add_argument("--prefix", help="topic prefix (default: the config's, else rig/F4)")
    pub.add_argument("--mqtt", metavar="HOST:PORT", help="MQTT broker")
    pub.add_argument("--username")
    pub.add_argument("--password", help="MQTT password (visible to other users in the process "
                                        "list: prefer --password-file or --password-env)")
    pub.add_argument("--password-file", type=Path,
                     help="read the MQTT password from this file (first line)")
    pub.add_argument("--password-env", metavar="NAME",
                     help="read the MQTT password from this environment variable (without "
                          f"any password option: {PASSWORD_ENV} if set)")
    pub.add_argument("--ca-file", type=Path, help="CA certificate: connect with TLS")
    pub.add_argument("--client-id", default="tdmon-rig")
    pub.add_argument("--qos", type=int, default=1, choices=[0, 1, 2])
    pub.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT",
                     help="Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447")
    pub.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT")
    pub.add_argument("--columns", help="CSV column map: channel=column:unit,... "
                                       "(default: the Volve F-4 layout)")
    pub.add_argument("--time-column", default="time_utc")
    pub.add_argument("--speed", default="max", help="real time x N, or 'max' (default)")
    pub.add_argument("--now", action="store_true",
                     help="shift times to the present (live-looking data): the first row is "
                          "now at --speed 1; faster, the last row is now, so that no sample "
                          "is stamped ahead of the clock (the daemon refuses those)")
    pub.add_argument("--limit", type=int, help="stop after this many messages")
    pub.add_argument("--seq", action="store_true",
                     help="number each channel's messages (\"seq\": 1, 2, ...) so that the "
                          "daemon can count the ones that never arrive (CSV sources)")
    pub.add_argument("--wits0", metavar="URL",
                     help="serve WITS0 frames instead, as a rig's WITS server: one frame per "
                          "time step to every client of tcp://HOST:PORT, or to "
                          "serial:///dev/DEVICE?baud=9600 (docs/wits0.md, Simulator)")
    pub.add_argument("--wits0-clients", type=int, default=1, metavar="N",
                     help="with --wits0: wait for N clients before the first frame (0: none)")
    pub.add_argument("--wits0-units", default="metric", choices=["metric", "field"],
                     help="with --wits0: the WITS unit set of the items (default metric)")
    pub.add_argument("--wits0-decimals", type=int, metavar="N",
                     help="with --wits0: round values to N decimals (default: every digit)")
    pub.set_defaults(func=_publish)


def _run(args: argparse.Namespace) -> int:
    from tdmon.config.daemon import load_daemon_config
    from tdmon.daemon.runner import run_daemon
    from tdmon.display import using

    # before the file is read: its warnings (a password file readable by others) use it
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    config = load_daemon_config(args.config)
    startup_checks(config, args.config)
    # the Rerun views are built inside the daemon: they read the units from tdmon.display
    with using(display_units(args, config.display.units)):
        stats = asyncio.run(run_daemon(config))
    print(f"tdmon: stopped: {stats.samples_in} samples, {stats.rejected} rejected, "
          f"{stats.dropped} dropped, {stats.duplicates} duplicates, {stats.out_of_order} "
          f"out of order, {stats.frames} frames", file=sys.stderr)
    return 0


def startup_checks(config: DaemonConfig, file: Path) -> None:
    """What would otherwise fail only once the daemon runs, checked before it starts so that
    the mistake stops it with one line (exit 2) instead of a connection retried for ever or a
    viewer that never comes: every broker's TLS files load, the Rerun live port is free.

    Raises
    ------
    ConfigError
        Naming the file, the key and the reason.
    """
    from tdmon.config.daemon import broker_sections
    from tdmon.errors import ConfigError, IngestError
    from tdmon.ingest.mqtt import tls_context

    base = config.source_file.parent if config.source_file else file.parent
    for key, mqtt in broker_sections(config):
        try:
            tls_context(mqtt, base)
        except IngestError as exc:
            raise ConfigError(str(file), key, str(exc)) from exc
    if config.rerun.mode == "live":
        reason = port_in_use("127.0.0.1", config.rerun.port)
        if reason is not None:
            raise ConfigError(str(file), "rerun.port",
                              f"cannot serve the live viewer on 127.0.0.1:{config.rerun.port}: "
                              f"{reason}; choose another port or stop what holds it")


def port_in_use(host: str, port: int) -> str | None:
    """Why a TCP server cannot listen on ``host:port`` (e.g. "Address already in use"), or
    None when it can. SO_REUSEADDR as servers set it: a port left in TIME_WAIT is free."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
            probe.listen(1)
        except OSError as exc:
            return exc.strerror or str(exc)
    return None


def _publish(args: argparse.Namespace) -> int:
    from itertools import islice

    from tdmon.config.daemon import load_daemon_config
    from tdmon.ingest import publish as pub

    config = load_daemon_config(args.config) if args.config else None
    prefix = (args.prefix or (config.prefix if config else "rig/F4")).strip("/")
    speed: float | None
    if args.speed == "max":
        speed = None
    else:
        try:
            speed = float(args.speed)
        except ValueError:
            raise TdmonError(f"--speed must be a number or 'max', got '{args.speed}'") from None
        if speed <= 0:
            raise TdmonError("--speed must be positive")

    messages: Iterable[tuple[float, str, bytes]]
    total: int | None
    if args.source.suffix.lower() == ".mcap":
        shift = _now_shift(args.now, speed, (t for t, _, _ in
                                             pub.recording_messages(args.source, prefix)))
        messages = ((t + shift, topic, body) for t, topic, body in
                    pub.recording_messages(args.source, prefix))
        total = pub.recording_message_count(args.source)
    else:
        columns = pub.parse_columns(args.columns) if args.columns else pub.VOLVE_COLUMNS
        shift = _now_shift(args.now, speed, (t for t, _, _ in pub.csv_messages(
            args.source, prefix, columns, args.time_column)))
        messages = pub.csv_messages(args.source, prefix, columns, args.time_column, shift,
                                    seq=args.seq)
        total = pub.csv_message_count(args.source, columns)
    if args.wits0:
        from tdmon.cli.bridge import serve_wits0

        return serve_wits0(args, messages, speed, _progress())  # counts frames, not messages
    if args.limit is not None:
        messages = islice(messages, args.limit)
        total = args.limit if total is None else min(total, args.limit)

    mqtt, zenoh = flag_targets(args, _password(args) if args.mqtt else None)
    if mqtt is None and zenoh is None:
        if config is not None and config.sources.mqtt is not None:
            update: dict[str, Any] = {"client_id": args.client_id, "clean_session": True}
            password = _password(args, fallback=config.sources.mqtt.resolved_password())
            if password is not None:
                update["password"] = password
            if args.username:
                update["username"] = args.username
            mqtt = config.sources.mqtt.model_copy(update=update)
        elif config is not None and config.sources.zenoh is not None:
            zenoh = toward_zenoh_source(config.sources.zenoh)
        else:
            raise TdmonError("say where to publish: --config, --mqtt or --zenoh-connect")

    def say(line: str) -> None:
        print(f"tdmon: publish: {line}", file=sys.stderr, flush=True)

    stopped_by: list[str] = []

    async def main() -> int:
        # Explicit handlers: a job started in the background of a non-interactive shell
        # inherits SIGINT ignored, and asyncio.run only handles SIGINT when it is not.
        loop = asyncio.get_running_loop()
        task = asyncio.current_task()
        assert task is not None

        def stop(name: str) -> None:
            if not stopped_by:
                stopped_by.append(name)
                task.cancel()

        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop, signum.name)
        progress = _progress(total)
        sent = [0]

        def on_sent(count: int) -> None:
            sent[0] = count
            progress(count)

        try:
            if mqtt is not None:
                sender = pub.MqttSender(mqtt, args.qos, on_state=say)
                await sender.start()
                try:
                    await _interruptible(pub.publish(messages, sender, speed, on_sent),
                                         stopped_by)
                    if stopped_by:  # what is in flight gets a moment to be acknowledged
                        with contextlib.suppress(TimeoutError):
                            await asyncio.wait_for(sender.flush(), 5.0)
                finally:
                    await sender.close()
                if sender.reconnects:
                    say(f"{sender.reconnects} reconnection(s), {sender.resent} message(s) "
                        "sent again")
                return sender.confirmed
            assert zenoh is not None
            async with pub.zenoh_sender(zenoh) as zsender:
                await _interruptible(pub.publish(messages, zsender, speed, on_sent),
                                     stopped_by)
            return sent[0]
        finally:
            progress(None)
            for signum in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(signum)

    count = asyncio.run(main())
    of = f" of {total}" if total is not None else ""
    if stopped_by:
        print(f"tdmon: publish stopped by {stopped_by[0]}: {count}{of} messages delivered on "
              f"{prefix}/...", file=sys.stderr)
        return 130 if stopped_by[0] == "SIGINT" else 143
    print(f"tdmon: published {count} messages on {prefix}/...", file=sys.stderr)
    return 0


async def _interruptible(work: Coroutine[Any, Any, int], stopped_by: list[str]) -> None:
    """Run ``work``; a cancellation from our own signal handler ends it quietly."""
    try:
        await work
    except asyncio.CancelledError:
        if not stopped_by:
            raise
        task = asyncio.current_task()
        if task is not None:
            task.uncancel()


def _password(args: argparse.Namespace, fallback: str | None = None) -> str | None:
    """The MQTT password: --password, --password-file, --password-env, the config's, or
    $TDMON_MQTT_PASSWORD, in that order."""
    if args.password is not None:
        return str(args.password)
    if args.password_file is not None:
        return read_password_file(args.password_file, "--password-file")
    if args.password_env is not None:
        value = os.environ.get(args.password_env)
        if value is None:
            raise TdmonError(f"--password-env: environment variable {args.password_env} is "
                             "not set")
        return value
    if fallback is not None:
        return fallback
    return os.environ.get(PASSWORD_ENV)


def read_password_file(path: Path, what: str) -> str:
    """The first line of a password file; warns when others may read it."""
    try:
        text = path.read_text(encoding="utf-8")
        mode = path.stat().st_mode
    except (OSError, UnicodeDecodeError) as exc:
        raise TdmonError(f"{what}: cannot read {path}: {exc}") from None
    password = text.splitlines()[0] if text else ""
    if not password:
        raise TdmonError(f"{what}: {path} is empty: put the password on its first line")
    if mode & 0o077:
        print(f"tdmon: warning: {path} holds a clear-text password and is readable by others "
              f"(chmod 600 {path})", file=sys.stderr)
    return password


def _now_shift(now: bool, speed: float | None, times: Iterator[float]) -> float:
    """How far ``--now`` moves a session's times [s]. At real time the first row is stamped
    now and the rest follow as the rig's clock would; played faster, the session would run
    ahead of the clock (a daemon rejects stamps in the future), so the last row is now."""
    if not now:
        return 0.0
    first = next(times, None)
    if first is None:
        return 0.0
    if speed == 1.0:
        return time.time() - first
    last = first
    for last in times:  # noqa: B007 (the last time is what is wanted)
        pass
    return time.time() - last


def _progress(total: int | None = None) -> Any:
    """A callback updating a tqdm bar on a terminal (and nothing otherwise): count, rate and,
    when the number of messages is known, total and time left."""
    if not sys.stderr.isatty():
        return lambda count: None
    from tqdm import tqdm

    bar = tqdm(unit="msg", file=sys.stderr, total=total)
    state = {"last": 0}

    def update(count: int | None) -> None:
        if count is None:
            bar.close()
            return
        bar.update(count - state["last"])
        state["last"] = count

    return update
