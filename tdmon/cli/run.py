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
from tdmon.record.rerun_web import DEFAULT_WEB_PORT

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
    run.add_argument("--status-every", type=_seconds, default=10.0, metavar="SECONDS",
                     help="print a status line on stderr this often: sample rate, rig state, "
                          "latest friction, alarms (default 10; 0: never). One line rewritten "
                          "in place on a terminal, plain lines otherwise")
    add_units_option(run, "the Rerun views (default: $TDMON_UNITS, else the file's [display] "
                     "units)")
    run.add_argument("--web", action="store_true",
                     help="serve the live Rerun view for a browser: the recording on "
                          "127.0.0.1:[rerun] port (as mode = 'live'; a file, if set, is "
                          "written too) and Rerun's web viewer on 127.0.0.1:--web-port; "
                          "open the address it prints")
    run.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                     help=f"port of the web viewer (default {DEFAULT_WEB_PORT})")
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
    pub.add_argument("--speed", default=None,
                     help="real time x N, or 'max' (default; with --opcua: 1, real time)")
    pub.add_argument("--now", action="store_true",
                     help="shift times to the present (live-looking data): the first row is "
                          "now at --speed 1; faster, the last row is now, so that no sample "
                          "is stamped ahead of the clock (the daemon refuses those)")
    pub.add_argument("--limit", type=int, help="stop after this many messages")
    pub.add_argument("--status-every", type=_seconds, default=10.0, metavar="SECONDS",
                     help="not on a terminal (a script, a log file): print the progress "
                          "(messages sent of the total, rate, time left) this often on stderr "
                          "(default 10; 0: never). A terminal gets a progress bar")
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
    pub.add_argument("--opcua", metavar="URL",
                     help="serve the session from an OPC UA server instead, as a rig's drilling "
                          "control system: one variable per channel, written at each time step "
                          "with its time as source timestamp, at opc.tcp://HOST:PORT "
                          "(docs/opcua.md, Simulator)")
    pub.add_argument("--opcua-clients", type=int, default=1, metavar="N",
                     help="with --opcua: wait for N subscriptions before the first step (0: "
                          "none)")
    pub.add_argument("--opcua-linger", type=_seconds, default=5.0, metavar="SECONDS",
                     help="with --opcua: keep serving this long after the last step, so that "
                          "subscribers get it at their next publish (default 5)")
    pub.set_defaults(func=_publish)


def _seconds(text: str) -> float:
    """A non-negative number of seconds for an option (argparse reports the mistake)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number of seconds") from None
    if not value >= 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"'{text}' must be 0 or more seconds")
    return value


def _run(args: argparse.Namespace) -> int:
    from tdmon.cli.status import StatusLine
    from tdmon.config.daemon import load_daemon_config
    from tdmon.daemon.runner import run_daemon
    from tdmon.display import using

    interruptible()
    # before the file is read: its warnings (a password file readable by others) use it
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    config = load_daemon_config(args.config)
    if args.web:
        config = served_live(config, args.config)
        check_web_port(args.web_port)
    startup_checks(config, args.config)
    status = StatusLine(args.status_every) if args.status_every > 0 else None

    async def main() -> Any:
        if status is None:
            return await run_daemon(config)
        printer = asyncio.create_task(status.run())
        try:
            stats = await run_daemon(config, extra_sinks=[status])
        finally:
            printer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await printer
            status.close()
        # where it ended, before the one-line summary (not after a start-up error: its one
        # line is all the user needs)
        status.show()
        status.close()
        return stats

    # the Rerun views are built inside the daemon: they read the units from tdmon.display
    with using(display_units(args, config.display.units)), contextlib.ExitStack() as stack:
        if args.web:
            from tdmon.record.rerun_web import WebViewer

            viewer = stack.enter_context(WebViewer(
                f"rerun+http://127.0.0.1:{config.rerun.port}/proxy", args.web_port))
            print(f"tdmon: web view: {viewer.url}", file=sys.stderr, flush=True)
        stats = asyncio.run(main())
    jumps = f", {stats.clock_jumps} clock jumps" if stats.clock_jumps else ""  # logged sparingly
    print(f"tdmon: stopped: {stats.samples_in} samples, {stats.rejected} rejected, "
          f"{stats.dropped} dropped, {stats.duplicates} duplicates, {stats.out_of_order} "
          f"out of order, {stats.frames} frames{jumps}", file=sys.stderr)
    return 0


def served_live(config: DaemonConfig, file: Path) -> DaemonConfig:
    """``config`` with its Rerun views served live (``--web``): mode 'live' on its port, its
    .rrd file, if any, still written."""
    from tdmon.errors import ConfigError

    if config.is_fleet:
        raise ConfigError(str(file), "rerun.mode", "a daemon of many rigs has no Rerun views; "
                          "watch the fleet in a browser with 'tdmon fleet --web'")
    return config.model_copy(update={"rerun": config.rerun.model_copy(update={"mode": "live"})})


def check_web_port(port: int) -> None:
    """The web viewer's port is free on 127.0.0.1 (else one line, exit 2)."""
    reason = port_in_use("127.0.0.1", port)
    if reason is not None:
        raise TdmonError(f"--web-port {port}: cannot serve the web viewer on 127.0.0.1:{port}: "
                         f"{reason}; choose another port")


def interruptible() -> None:
    """Let SIGINT interrupt us even when started with it ignored.

    A shell without job control starts a background job (``tdmon publish ... &`` in a script)
    with SIGINT ignored, and Python then installs no handler of its own: ``kill -INT`` would
    do nothing until the event loop installs its handlers, and be lost if it came earlier.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


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


def _publish(args: argparse.Namespace) -> int:  # noqa: C901  (complex today; simplify when next touched)
    from itertools import islice

    interruptible()

    from tdmon.config.daemon import load_daemon_config
    from tdmon.ingest import publish as pub

    config = load_daemon_config(args.config) if args.config else None
    prefix = (args.prefix or (config.prefix if config else "rig/F4")).strip("/")
    speed: float | None
    if args.opcua and args.speed == "max":
        raise TdmonError("--opcua needs --speed N (real time x N): OPC UA has no flow control, "
                         "a subscriber gets what its queue holds between two publishes")
    if args.speed is None and args.opcua:
        speed = 1.0
    elif args.speed in (None, "max"):
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
    if args.wits0 and args.opcua:
        raise TdmonError("give one of --wits0 and --opcua")
    if args.opcua:
        assert speed is not None  # refused above
        return serve_opcua(args, messages, speed, _progress())  # counts steps, not messages
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

    async def main() -> int:  # noqa: C901  (complex today; simplify when next touched)
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
        progress = _progress(total, args.status_every)
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
        except asyncio.CancelledError:
            # stopped while connecting (an MQTT broker, a Zenoh peer not there yet)
            if not stopped_by:
                raise
            task.uncancel()
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


def serve_opcua(args: argparse.Namespace, messages: Iterable[tuple[float, str, bytes]],
                speed: float, progress: Any) -> int:
    """``tdmon publish ... --opcua opc.tcp://HOST:PORT``: each time step of ``messages`` written
    to the variables of an OPC UA server, paced at real time x ``speed``."""
    from itertools import islice

    from tdmon.ingest import opcua_server
    from tdmon.ingest import publish as pub
    from tdmon.ingest.wits0_server import session_steps

    host, port = opcua_server.parse_opcua_url(args.opcua)
    if args.opcua_clients < 0:
        raise TdmonError("--opcua-clients must be 0 or more")
    # asyncua's server warns at start about the security it was not given: the simulator
    # serves without security on purpose (docs/opcua.md)
    logging.getLogger("asyncua").setLevel(logging.ERROR)
    steps: Iterable[tuple[float, str, bytes]] = (
        (step.t, "opcua", opcua_server.step_payload(step)) for step in session_steps(messages))
    if args.limit is not None:
        steps = islice(steps, args.limit)

    async def main() -> tuple[int, str, int]:
        try:
            async with opcua_server.OpcUaRigServer(host, port) as server:
                # said once listening, so that a script may connect as soon as it reads this
                print(f"tdmon: serving OPC UA on {server.endpoint}; waiting for "
                      f"{args.opcua_clients} subscription(s)", file=sys.stderr, flush=True)
                await server.wait_for_subscribers(args.opcua_clients)
                count = await pub.publish(steps, opcua_server.OpcUaSender(server), speed,
                                          progress)
                await asyncio.sleep(args.opcua_linger)
                return count, server.endpoint, len(server.subscriptions)
        finally:
            progress(None)

    count, where, subscribers = asyncio.run(main())
    print(f"tdmon: served {count} time steps on {where} to {subscribers} subscription(s)",
          file=sys.stderr)
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


def _progress(total: int | None = None, every: float = 0.0) -> Any:
    """A callback taking the count of messages sent (None: done). On a terminal a tqdm bar
    (count, rate and, when the number of messages is known, total and time left); otherwise,
    every ``every`` seconds (0: never), a plain line with the same."""
    if not sys.stderr.isatty():
        if every <= 0:
            return lambda count: None
        return _ProgressLines(total, every)
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


class _ProgressLines:
    """Progress as plain lines on stderr, for scripts and log files:
    ``tdmon: publish: 1200 of 11169 messages (10.7 %), 118 msg/s, about 1 min 24 s left``."""

    def __init__(self, total: int | None, every: float) -> None:
        self.total = total
        self.every = every
        self.start = time.monotonic()
        self.next = self.start + every

    def __call__(self, count: int | None) -> None:
        now = time.monotonic()
        if count is None or now < self.next:
            return
        self.next = now + self.every
        print(f"tdmon: publish: {self.line(count, now - self.start)}", file=sys.stderr,
              flush=True)

    def line(self, count: int, elapsed: float) -> str:
        """The progress after ``count`` messages in ``elapsed`` seconds."""
        rate = count / elapsed if elapsed > 0 else 0.0
        if self.total is None:
            return f"{count} messages, {rate:.0f} msg/s"
        share = 100.0 * count / self.total if self.total else 100.0
        left = f", about {_duration((self.total - count) / rate)} left" if rate > 0 else ""
        return f"{count} of {self.total} messages ({share:.1f} %), {rate:.0f} msg/s{left}"


def _duration(seconds: float) -> str:
    """``42 s``, ``3 min 05 s``, ``2 h 07 min``."""
    seconds = max(0, round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    minutes, seconds = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes} min {seconds:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"
