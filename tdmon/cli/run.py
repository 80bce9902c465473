"""``tdmon run`` (the live daemon) and ``tdmon publish`` (play the rig from a CSV or recording)."""

from __future__ import annotations

import argparse
import asyncio
import logging
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from tdmon.errors import TdmonError


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``run`` and ``publish``."""
    run = subparsers.add_parser(
        "run", help="run the live daemon",
        description="Subscribe to the rig's channels (MQTT and/or Zenoh, or replay a "
                    "recording), model and record, publish results on <prefix>/tdmon/<name>. "
                    "Ctrl-C or SIGTERM flushes everything and exits 0.")
    run.add_argument("--config", required=True, type=Path, help="daemon TOML file")
    run.add_argument("--log-level", default="info",
                     choices=["debug", "info", "warning", "error"])
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
    pub.add_argument("--password")
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
                     help="shift times so that the first row is now (live-looking data)")
    pub.add_argument("--limit", type=int, help="stop after this many messages")
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

    config = load_daemon_config(args.config)
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    stats = asyncio.run(run_daemon(config))
    print(f"tdmon: stopped: {stats.samples_in} samples, {stats.rejected} rejected, "
          f"{stats.dropped} dropped, {stats.duplicates} duplicates, {stats.out_of_order} "
          f"out of order, {stats.frames} frames", file=sys.stderr)
    return 0


def _publish(args: argparse.Namespace) -> int:
    from itertools import islice

    from tdmon.config.daemon import MqttConfig, TlsConfig, ZenohConfig, load_daemon_config
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
    if args.source.suffix.lower() == ".mcap":
        first = next(iter(pub.recording_messages(args.source, prefix)), None)
        shift = time.time() - first[0] if args.now and first else 0.0
        messages = ((t + shift, topic, body) for t, topic, body in
                    pub.recording_messages(args.source, prefix))
    else:
        columns = pub.parse_columns(args.columns) if args.columns else pub.VOLVE_COLUMNS
        first = next(iter(pub.csv_messages(args.source, prefix, columns, args.time_column)),
                     None)
        shift = time.time() - first[0] if args.now and first else 0.0
        messages = pub.csv_messages(args.source, prefix, columns, args.time_column, shift)
    if args.wits0:
        from tdmon.cli.bridge import serve_wits0

        return serve_wits0(args, messages, speed, _progress())
    if args.limit is not None:
        messages = islice(messages, args.limit)

    mqtt: MqttConfig | None = None
    zenoh: ZenohConfig | None = None
    if args.mqtt:
        host, _, port = args.mqtt.rpartition(":")
        if not host or not port.isdigit():
            raise TdmonError(f"--mqtt must be HOST:PORT, got '{args.mqtt}'")
        mqtt = MqttConfig(host=host, port=int(port), client_id=args.client_id,
                          username=args.username, password=args.password,
                          tls=TlsConfig(ca_file=args.ca_file) if args.ca_file else None,
                          clean_session=True)
    elif args.zenoh_connect or args.zenoh_listen:
        zenoh = ZenohConfig(connect=args.zenoh_connect, listen=args.zenoh_listen)
    elif config is not None and config.sources.mqtt is not None:
        mqtt = config.sources.mqtt.model_copy(
            update={"client_id": args.client_id, "clean_session": True})
    elif config is not None and config.sources.zenoh is not None:
        source = config.sources.zenoh
        zenoh = ZenohConfig(mode="peer" if source.mode == "peer" else "client",
                            connect=source.listen or source.connect)
    else:
        raise TdmonError("say where to publish: --config, --mqtt or --zenoh-connect")

    async def main() -> int:
        progress = _progress()
        try:
            if mqtt is not None:
                async with pub.mqtt_sender(mqtt, args.qos) as sender:
                    return await pub.publish(messages, sender, speed, progress)
            assert zenoh is not None
            async with pub.zenoh_sender(zenoh) as zsender:
                return await pub.publish(messages, zsender, speed, progress)
        finally:
            progress(None)

    count = asyncio.run(main())
    print(f"tdmon: published {count} messages on {prefix}/...", file=sys.stderr)
    return 0


def _progress() -> Any:
    """A callback updating a tqdm bar on a terminal (and nothing otherwise)."""
    if not sys.stderr.isatty():
        return lambda count: None
    from tqdm import tqdm

    bar = tqdm(unit="msg", file=sys.stderr)
    state = {"last": 0}

    def update(count: int | None) -> None:
        if count is None:
            bar.close()
            return
        bar.update(count - state["last"])
        state["last"] = count

    return update
