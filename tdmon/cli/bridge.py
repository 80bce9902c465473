"""``tdmon bridge wits0`` (one WITS0 feed to many consumers over Zenoh or MQTT) and the
``--wits0`` side of ``tdmon publish`` (the WITS0 simulator). See docs/wits0.md."""

from __future__ import annotations

import argparse
import asyncio
import signal
import sys
from collections.abc import Callable, Iterable
from itertools import islice
from pathlib import Path
from typing import Any

from tdmon.errors import TdmonError


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
    wits0.add_argument("--wits0", metavar="tcp://HOST:PORT",
                       help="the rig's WITS0 server to connect to (default map, metric units)")
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

    address = ws.parse_serve_url(args.wits0)
    if args.wits0_clients < 0:
        raise TdmonError("--wits0-clients must be 0 or more")
    items = ws.default_served_items()
    frames: Iterable[tuple[float, str, bytes]] = (
        (step.t, "wits0", ws.build_frame(step.t, step.values, items))
        for step in ws.session_steps(messages))
    if args.limit is not None:
        frames = islice(frames, args.limit)

    async def main() -> tuple[int, int]:
        try:
            async with ws.wits0_sender(address, args.wits0_clients) as sender:
                count = await pub.publish(frames, sender, speed, progress)
                return count, sender.server.clients_served
        finally:
            progress(None)

    print(f"tdmon: serving WITS0 on {address.host}:{address.port}; waiting for "
          f"{args.wits0_clients} client(s)", file=sys.stderr, flush=True)
    count, clients = asyncio.run(main())
    print(f"tdmon: served {count} WITS0 frames to {clients} client(s) on "
          f"{address.host}:{address.port}", file=sys.stderr)
    return 0
