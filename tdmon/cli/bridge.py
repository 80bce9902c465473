"""``tdmon bridge wits0`` (one WITS0 feed to many consumers over Zenoh or MQTT) and the
``--wits0`` side of ``tdmon publish`` (the WITS0 simulator). See docs/wits0.md."""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from collections.abc import AsyncIterator, Callable, Iterable
from contextlib import AbstractAsyncContextManager, AsyncExitStack, asynccontextmanager
from itertools import islice
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.cli.arguments import flag_targets, toward_zenoh_source
from tdmon.errors import TdmonError

if TYPE_CHECKING:  # heavy modules stay out of the command line's start-up
    from tdmon.config.daemon import DaemonConfig
    from tdmon.ingest.publish import Sender
    from tdmon.ingest.types import RawMessage


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``bridge`` with its one kind, ``wits0``."""
    bridge = subparsers.add_parser(
        "bridge", help="relay a rig feed to tdmon's own topics (WITS0 -> Zenoh/MQTT)",
        description="Read a rig's feed and publish tdmon's JSON payloads on "
                    "<prefix>/<channel>, so that any number of `tdmon run` consume it.")
    kinds = bridge.add_subparsers(dest="kind", metavar="KIND", required=True)
    wits0 = kinds.add_parser(
        "wits0", help="WITS Level 0 in, <prefix>/<channel> out on Zenoh or MQTT",
        description=(
            "Connect to a rig's WITS0 server (--wits0, else the --config file's "
            "[sources.wits0]) and publish every item of the map as {'t', 'value', 'unit'} in SI "
            "on <prefix>/<channel>: over --mqtt / --zenoh-*, else the --config file's "
            "[publish.mqtt] / [publish.zenoh], else where its [sources.mqtt] / "
            "[sources.zenoh] listen. A lost or silent feed is reconnected with backoff. "
            "Ctrl-C or SIGTERM stops cleanly (exit 0). See docs/wits0.md, Bridge."))
    wits0.add_argument("--config", type=Path, help="daemon TOML: [sources.wits0], prefix, "
                                                   "where to publish")
    wits0.add_argument("--wits0", metavar="URL",
                       help="the rig's WITS0 server to connect to, tcp://HOST:PORT, or a "
                            "serial line, serial:///dev/DEVICE?baud=9600 (default item map)")
    wits0.add_argument("--wits0-units", default="metric", choices=["metric", "field"],
                       help="with --wits0: the WITS unit set the rig sends (default metric)")
    wits0.add_argument("--prefix", help="topic prefix (default: the config's, else rig/F4)")
    wits0.add_argument("--mqtt", metavar="HOST:PORT", help="MQTT broker to publish to")
    wits0.add_argument("--username")
    wits0.add_argument("--password")
    wits0.add_argument("--ca-file", type=Path, help="CA certificate: connect with TLS")
    wits0.add_argument("--client-id", default="tdmon-wits0-bridge")
    wits0.add_argument("--qos", type=int, default=1, choices=[0, 1, 2])
    wits0.add_argument("--zenoh-connect", action="append", default=[], metavar="ENDPOINT",
                       help="Zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447")
    wits0.add_argument("--zenoh-listen", action="append", default=[], metavar="ENDPOINT")
    wits0.add_argument("--limit", type=int, metavar="N",
                       help="stop after N published messages (tests, demonstrations)")
    wits0.add_argument("--log-level", default="info",
                       choices=["debug", "info", "warning", "error"])
    wits0.set_defaults(func=bridge_wits0_command)


def serve_wits0(args: argparse.Namespace, messages: Iterable[tuple[float, str, bytes]],
                speed: float | None, progress: Callable[[int | None], None]) -> int:
    """``tdmon publish ... --wits0 tcp://HOST:PORT``: one frame per time step of ``messages``
    to every connected client, paced at real time x ``speed`` (None: at once)."""
    from tdmon.ingest import publish as pub
    from tdmon.ingest import wits0_server as ws
    from tdmon.ingest.wits0 import item_map

    address = ws.parse_serve_url(args.wits0)
    if args.wits0_clients < 0:
        raise TdmonError("--wits0-clients must be 0 or more")
    if args.wits0_decimals is not None and not 0 <= args.wits0_decimals <= 9:
        raise TdmonError("--wits0-decimals must be between 0 and 9")
    items = item_map(args.wits0_units)
    frames: Iterable[tuple[float, str, bytes]] = (
        (step.t, "wits0", ws.build_frame(step, items, decimals=args.wits0_decimals))
        for step in ws.session_steps(messages))
    if args.limit is not None:
        frames = islice(frames, args.limit)

    async def main() -> tuple[int, str]:
        try:
            if isinstance(address, ws.SerialAddress):
                async with ws.Wits0SerialPort(address.device, address.baud) as port:
                    count = await pub.publish(frames, ws.Wits0Sender(port), speed, progress)
                    return count, f"{address.device} at {address.baud} bit/s"
            async with ws.Wits0Server(address.host, address.port) as server:
                # said once listening, so that a script may connect as soon as it reads this
                print(f"tdmon: serving WITS0 on {address.host}:{server.bound_port}; waiting "
                      f"for {args.wits0_clients} client(s)", file=sys.stderr, flush=True)
                await server.wait_for_clients(args.wits0_clients)
                count = await pub.publish(frames, ws.Wits0Sender(server), speed, progress)
                return count, (f"{server.clients_served} client(s) on "
                               f"{address.host}:{server.bound_port}")
        finally:
            progress(None)

    count, where = asyncio.run(main())
    print(f"tdmon: served {count} WITS0 frames to {where}", file=sys.stderr)
    return 0


def bridge_wits0_command(args: argparse.Namespace) -> int:
    """``tdmon bridge wits0``: supervised WITS0 input, tdmon payloads out."""
    from tdmon.channels import validate_prefix
    from tdmon.config.daemon import load_daemon_config

    config = load_daemon_config(args.config) if args.config else None
    try:
        prefix = validate_prefix(args.prefix or (config.prefix if config else "rig/F4"))
    except ValueError as exc:
        raise TdmonError(f"--prefix: {exc}") from None
    if args.limit is not None and args.limit <= 0:
        raise TdmonError("--limit must be positive")
    open_source = _wits0_input(args, config, prefix)
    open_sender, where = _output(args, config)
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    count = asyncio.run(_bridge_until_stopped(open_source, open_sender, args.limit))
    print(f"tdmon: bridged {count} messages to {where} on {prefix}/...", file=sys.stderr)
    return 0


def _output(args: argparse.Namespace, config: DaemonConfig | None
            ) -> tuple[Callable[[], AbstractAsyncContextManager[Sender]], str]:
    """Where the bridge publishes: flags, else the config's [publish.*], else where its
    [sources.mqtt] / [sources.zenoh] listen (like ``tdmon publish --config``)."""
    from tdmon.ingest import publish as pub

    mqtt, zenoh = flag_targets(args, args.password)
    if mqtt is None and zenoh is None:
        if config is not None and config.publish.mqtt is not False:
            mqtt = config.sources.mqtt if config.publish.mqtt is True else config.publish.mqtt
        elif config is not None and config.publish.zenoh is not False:
            zenoh = config.sources.zenoh if config.publish.zenoh is True else config.publish.zenoh
        elif config is not None and config.sources.mqtt is not None:
            mqtt = config.sources.mqtt.model_copy(
                update={"client_id": args.client_id, "clean_session": True})
        elif config is not None and config.sources.zenoh is not None:
            zenoh = toward_zenoh_source(config.sources.zenoh)
        else:
            raise TdmonError("say where to publish: --mqtt, --zenoh-connect/--zenoh-listen, or "
                             "--config with [publish.mqtt]/[publish.zenoh] or an MQTT/Zenoh source")
    if mqtt is not None:
        chosen_mqtt = mqtt
        if mqtt.client_id == (config.sources.mqtt.client_id if config is not None
                              and config.sources.mqtt is not None else None):
            # a daemon's own client id: the broker would throw one of the two off
            chosen_mqtt = mqtt.model_copy(update={"client_id": args.client_id})
        return (lambda: pub.mqtt_sender(chosen_mqtt, args.qos)), \
            f"mqtt {mqtt.host}:{mqtt.port}"
    assert zenoh is not None
    chosen_zenoh = zenoh
    where = ", ".join(zenoh.connect + zenoh.listen) or "default endpoints"
    return (lambda: pub.zenoh_sender(chosen_zenoh)), f"zenoh {where}"


async def _bridge_until_stopped(  # noqa: C901  (complex today; simplify when next touched)
    open_source: Callable[[], AbstractAsyncContextManager[AsyncIterator[RawMessage]]],
    open_sender: Callable[[], AbstractAsyncContextManager[Sender]],
    limit: int | None,
) -> int:
    """Relay until SIGINT/SIGTERM (or ``limit`` messages); return how many were published."""
    from tdmon.daemon.supervisor import supervise

    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, stop.set)
    states: dict[str, str] = {}
    count = 0
    current: list[Sender] = []  # the open sender, flushed before stopping

    @asynccontextmanager
    async def connect() -> AsyncIterator[tuple[Sender, AsyncIterator[RawMessage]]]:
        # output and input are one pipe: losing either reopens both through the supervisor
        async with AsyncExitStack() as stack:
            sender = await stack.enter_async_context(open_sender())
            source = await stack.enter_async_context(open_source())
            current[:] = [sender]
            try:
                yield sender, source
            finally:
                current.clear()

    async def work(connection: tuple[Sender, AsyncIterator[RawMessage]]) -> None:
        nonlocal count
        sender, source = connection
        async for raw in source:
            # already on <prefix>/<channel> (or <prefix>/wits0 for what the feed rejected)
            await sender.send(raw.topic, raw.payload)
            count += 1
            if limit is not None and count >= limit:
                stop.set()
                await asyncio.Event().wait()  # hold the connection until the caller stops

    task = asyncio.create_task(supervise("wits0 bridge", connect, work, states))
    stopping = asyncio.create_task(stop.wait())
    try:
        await asyncio.wait({task, stopping}, return_when=asyncio.FIRST_COMPLETED)
        if task.done():
            task.result()  # a bug or an error that is not a connection's: raise it
        if current:
            try:
                await asyncio.wait_for(current[0].flush(), 10.0)
            except TdmonError as exc:
                logging.getLogger(__name__).warning("wits0 bridge: %s", exc)
            except TimeoutError:
                logging.getLogger(__name__).warning("wits0 bridge: flush timed out")
    finally:
        for pending in (task, stopping):
            pending.cancel()
        await asyncio.gather(task, stopping, return_exceptions=True)
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(signum)
    return count


def _wits0_input(args: argparse.Namespace, config: DaemonConfig | None, prefix: str
                 ) -> Callable[[], AbstractAsyncContextManager[AsyncIterator[RawMessage]]]:
    """The feed: ``--wits0 URL`` (a TCP client or a serial line with the default item map in
    ``--wits0-units``), else the config's ``[sources.wits0]``. Its messages are those the
    daemon's own WITS0 source makes, on ``<prefix>/<channel>`` and ``<prefix>/wits0``."""
    from tdmon.config.daemon import QueuesConfig, Wits0Config
    from tdmon.errors import ConfigError
    from tdmon.ingest.wits0 import MAX_FRAME_BYTES, ItemOverride, item_map, resolve_timezone
    from tdmon.ingest.wits0_server import SerialAddress, parse_serve_url
    from tdmon.ingest.wits0_source import REJECT_TOPIC, Wits0Source

    where = "--wits0"
    if args.wits0:
        address = parse_serve_url(args.wits0)
        if isinstance(address, SerialAddress):
            section = Wits0Config(mode="serial", device=address.device,
                                  baud_rate=address.baud, units=args.wits0_units)
        else:
            section = Wits0Config(mode="tcp-client", host=address.host, port=address.port,
                                  units=args.wits0_units)
    elif config is not None and config.sources.wits0 is not None:
        section = config.sources.wits0
        where = str(config.source_file)
    else:
        raise TdmonError("say where the feed is: --wits0 tcp://HOST:PORT, or --config with "
                         "a [sources.wits0] section")
    overrides = {code: ItemOverride(item.channel, item.unit)
                 for code, item in section.items.items()}
    try:
        items = item_map(section.units, overrides)
    except ValueError as exc:
        raise ConfigError(where, "sources.wits0.items", str(exc)) from None
    # the daemon file's channel topics ([channels.X] topic), as its own WITS0 source uses them,
    # so that a `tdmon run` with the same file takes what the bridge publishes
    topics = {spec.channel: f"{prefix}/{spec.channel}" for spec in items.values()}
    if config is not None:
        from tdmon.ingest.decode import topic_for

        topics.update({spec.channel: topic_for(prefix, spec.topic)
                       for spec in config.channel_specs()})
    tz = resolve_timezone(section.timezone)
    # the first message of a frame carries the frame: keep it under the consumers' limit
    limit = (config.queues if config is not None else QueuesConfig()).max_payload_bytes
    max_frame = max(256, min(MAX_FRAME_BYTES, limit - 512))

    def open_source() -> Wits0Source:
        return Wits0Source(section, items, topics, f"{prefix}/{REJECT_TOPIC}", tz, max_frame)

    return open_source
