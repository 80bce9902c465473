"""``tdmon fleet``: the operations centre's view of every rig, from the results their daemons
publish on Zenoh (docs/fleet.md)."""

from __future__ import annotations

import argparse
import json
import queue
import shutil
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from tdmon.cli.arguments import quantity_arg
from tdmon.errors import TdmonError
from tdmon.record.rerun_web import DEFAULT_WEB_PORT

if TYPE_CHECKING:
    from tdmon.daemon.fleet_board import FleetBoard
    from tdmon.record.fleet_views import FleetViews

#: What ``tdmon fleet`` subscribes to unless ``--key`` says otherwise.
DEFAULT_KEY = "rig/*/tdmon/**"
#: The live Rerun view's port (the daemon's default is 9876: both can run on one machine).
DEFAULT_RERUN_PORT = 9877
#: How long ``--once`` listens before it prints, unless ``--duration`` says [s].
ONCE_LISTEN_S = 3.0

_CLEAR = "\x1b[H\x1b[J"  # cursor home, clear to the end: the table is redrawn in place


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``fleet``."""
    fleet = subparsers.add_parser(
        "fleet", help="watch every rig's state, friction and alarms",
        description="Subscribe on Zenoh to the results of the rigs' daemons (KEY, default "
                    f"'{DEFAULT_KEY}') and show each rig's state, latest friction and open "
                    "alarms: a table redrawn in place on a terminal, plain text blocks "
                    "otherwise. As the operations centre's router: --listen tcp/0.0.0.0:7447 "
                    "(the rigs' daemons connect there); or --connect to a router.")
    fleet.add_argument("--key", default=DEFAULT_KEY,
                       help=f"Zenoh key expression of the results (default '{DEFAULT_KEY}')")
    fleet.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                       help="listen here, e.g. tcp/127.0.0.1:7447 (repeatable)")
    fleet.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                       help="connect to a router or peer here (repeatable)")
    fleet.add_argument("--mode", choices=["router", "peer", "client"],
                       help="Zenoh mode (default: router with --listen, else client)")
    fleet.add_argument("--zenoh", type=Path, metavar="ZENOH.toml",
                       help="the Zenoh session as a [sources.zenoh] table of a daemon file "
                            "(mode, listen, connect, tls, access_control; docs/configuration.md, "
                            "\"Zenoh TLS and access control\"); --listen, --connect and "
                            "--mode replace its own")
    fleet.add_argument("--interval", type=quantity_arg("s", "2 s", positive=True),
                       default=1.0, help="refresh period (default 1 s)")
    fleet.add_argument("--duration", type=quantity_arg("s", "30 s", positive=True),
                       help="stop after this long (default: until Ctrl-C; with --once "
                            f"{ONCE_LISTEN_S:g} s)")
    fleet.add_argument("--once", action="store_true",
                       help="listen for --duration, print the table once and exit")
    fleet.add_argument("--hold", type=quantity_arg("s", "10 min", positive=True),
                       default=600.0, help="an alarm stays open this long after it was raised "
                                           "(rig time; default 10 min)")
    fleet.add_argument("--stale", type=quantity_arg("s", "10 s", positive=True),
                       default=10.0, help="a rig silent this long is shown silent (default "
                                          "10 s)")
    fleet.add_argument("--rerun", action="store_true",
                       help="serve a live Rerun view on 127.0.0.1:--rerun-port "
                            "(rerun --connect rerun+http://127.0.0.1:PORT/proxy)")
    fleet.add_argument("--rerun-port", type=int, default=DEFAULT_RERUN_PORT,
                       help=f"port of the live Rerun view (default {DEFAULT_RERUN_PORT})")
    fleet.add_argument("--rerun-file", type=Path, metavar="X.rrd",
                       help="write the Rerun view to this file")
    fleet.add_argument("--web", action="store_true",
                       help="serve the live Rerun view for a browser (implies --rerun): "
                            "Rerun's web viewer on 127.0.0.1:--web-port; open the address "
                            "it prints")
    fleet.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                       help=f"port of the web viewer (default {DEFAULT_WEB_PORT})")
    fleet.set_defaults(func=_fleet)


def _session_config(args: argparse.Namespace) -> Any:
    from pydantic import ValidationError

    from tdmon.config.daemon import ZenohConfig

    base: dict[str, Any] = {}
    if args.zenoh is not None:
        from tdmon.config.common import load_model

        base = load_model(ZenohConfig, args.zenoh, context={"base_dir": args.zenoh.parent}
                          ).model_dump(exclude_unset=True)
    listen = args.listen or base.get("listen", [])
    connect = args.connect or base.get("connect", [])
    mode = args.mode or base.get("mode") or ("router" if listen else "client")
    if mode == "client" and not connect:
        raise TdmonError("tdmon fleet: give --listen ENDPOINT (to be the router the rigs "
                         "connect to) or --connect ENDPOINT (a router's)")
    try:
        return ZenohConfig.model_validate({**base, "mode": mode, "listen": listen,
                                           "connect": connect})
    except ValidationError as exc:
        reason = exc.errors()[0]["msg"].removeprefix("Value error, ")
        raise TdmonError(f"--listen/--connect: {reason}") from None


def _fleet(args: argparse.Namespace) -> int:
    from tdmon.daemon.fleet_board import FleetBoard

    args.rerun = args.rerun or args.web
    if args.rerun:
        from tdmon.cli.run import check_web_port, port_in_use

        reason = port_in_use("127.0.0.1", args.rerun_port)
        if reason is not None:
            raise TdmonError(f"--rerun-port {args.rerun_port}: {reason}; choose another port")
        if args.web:
            check_web_port(args.web_port)
    config = _session_config(args)
    board = FleetBoard(hold=args.hold, stale=args.stale)
    inbox: queue.SimpleQueue[tuple[str, bytes, float]] = queue.SimpleQueue()
    views = _views(args)
    web = None
    try:
        if args.web and views is not None and views.grpc_uri:
            from tdmon.record.rerun_web import WebViewer

            web = WebViewer(views.grpc_uri, args.web_port)
            print(f"tdmon: fleet: web view: {web.url}", file=sys.stderr, flush=True)
        _listen(args, config, board, inbox, views)
    finally:
        if web is not None:
            web.close()
        if views is not None:
            views.close()
    return 0


def _listen(args: argparse.Namespace, config: Any, board: FleetBoard,
            inbox: queue.SimpleQueue[tuple[str, bytes, float]],
            views: FleetViews | None) -> None:
    """Subscribe on Zenoh and watch until the end (--duration, Ctrl-C or SIGTERM)."""
    import zenoh

    from tdmon.ingest.zenoh_io import open_session

    def on_sample(sample: zenoh.Sample) -> None:  # a zenoh thread: copy and hand over
        inbox.put((str(sample.key_expr), sample.payload.to_bytes(), time.time()))

    session = open_session(config)
    try:
        try:
            subscriber = session.declare_subscriber(args.key, on_sample)
        except zenoh.ZError as exc:
            raise TdmonError(f"--key '{args.key}': not a Zenoh key expression: {exc}") from None
        where = ", ".join(config.listen + config.connect)
        print(f"tdmon: fleet: {config.mode} on {where}, watching {args.key}"
              + (f", Rerun on {views.grpc_uri}" if views is not None and views.grpc_uri
                 else ""), file=sys.stderr, flush=True)
        previous = signal.signal(signal.SIGTERM, _interrupt)  # a service stop: as Ctrl-C
        try:
            _watch(args, board, inbox, views, sys.stdout)
        finally:
            signal.signal(signal.SIGTERM, previous)
            subscriber.undeclare()
    finally:
        session.close()


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _views(args: argparse.Namespace) -> FleetViews | None:
    if not args.rerun and args.rerun_file is None:
        return None
    from tdmon.record.fleet_views import FleetViews

    return FleetViews(args.rerun_file, args.rerun_port if args.rerun else None)


def _watch(args: argparse.Namespace, board: FleetBoard,
           inbox: queue.SimpleQueue[tuple[str, bytes, float]], views: FleetViews | None,
           out: TextIO) -> None:
    """Take results until --duration or Ctrl-C, redrawing every --interval; print last."""
    live = out.isatty() and not args.once
    duration = args.duration if args.duration is not None else (
        ONCE_LISTEN_S if args.once else None)
    started = time.monotonic()
    next_draw = started + (args.interval if not args.once else float("inf"))
    try:
        while duration is None or time.monotonic() - started < duration:
            try:
                key, body, received = inbox.get(timeout=0.1)
            except queue.Empty:
                pass
            else:
                _take(board, views, key, body, received)
                while True:  # a burst: take all of it before drawing
                    try:
                        key, body, received = inbox.get_nowait()
                    except queue.Empty:
                        break
                    _take(board, views, key, body, received)
            if time.monotonic() >= next_draw:
                next_draw += args.interval
                _draw(board, out, live)
    except KeyboardInterrupt:
        pass
    while True:  # what arrived before the end is shown
        try:
            _take(board, views, *inbox.get_nowait())
        except queue.Empty:
            break
    _draw(board, out, live)


def _take(board: FleetBoard, views: FleetViews | None, key: str, body: bytes,
          received: float) -> None:
    try:
        message = json.loads(body)
    except ValueError:
        board.skipped += 1
        return
    before = None
    if views is not None:
        rig = board.rigs.get(key.rpartition("/tdmon/")[0])
        before = None if rig is None else (rig.state, rig.friction_t)
    rig = board.update(key, message, received)
    if views is None or rig is None:
        return
    name = key.rpartition("/")[2]
    if name == "state" and (before is None or before[0] != rig.state):
        views.event(rig.prefix, received, f"state: {rig.state}")
    elif name == "estimate" and rig.mu is not None and (
            before is None or before[1] != rig.friction_t):
        views.friction(rig.prefix, received, rig.mu, rig.mu_std)
    elif name == "alarm":
        views.event(rig.prefix, received, f"[{message.get('kind')}] {message.get('message')}",
                    str(message.get("severity")))
        views.open_alarms(rig.prefix, received, len(rig.open_alarms(board.hold)))


def _draw(board: FleetBoard, out: TextIO, live: bool) -> None:
    from tdmon.daemon.fleet_board import render_table

    now = time.time()
    stamp = time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime(now))
    heading = f"tdmon fleet  {stamp}  {len(board.rigs)} rig{'s' if len(board.rigs) != 1 else ''}"
    if live:
        width = shutil.get_terminal_size().columns
        out.write(_CLEAR + heading + "\n" + render_table(board, now, width) + "\n")
    else:
        out.write(heading + "\n" + render_table(board, now) + "\n\n")
    out.flush()
