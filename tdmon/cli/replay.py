"""Commands that make replay files: ``tdmon simulate`` and ``tdmon import``.

(``tdmon replay`` itself follows with the replay driver.)
"""

from __future__ import annotations

import argparse
import json
import sys
from datetime import UTC, datetime
from typing import Any

from tdmon.errors import ConfigError, ModelError


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``simulate`` and ``import``."""
    simulate = subparsers.add_parser(
        "simulate",
        help="generate a rig session with known truth as MCAP",
        description=(
            "Simulate a rig session from a scenario TOML (well file, rig programme, sampling, "
            "noise, faults) and write it as MCAP: input payloads on /tdmon/raw as in a flight "
            "recording, the truth on /truth/... topics. See docs/replays.md."
        ),
    )
    simulate.add_argument("--scenario", required=True, metavar="S.toml", help="scenario file")
    simulate.add_argument("--out", required=True, metavar="X.mcap", help="output MCAP file")
    simulate.add_argument("--seed", type=int, default=None,
                          help="random seed (default: the scenario's)")
    simulate.add_argument("--json", action="store_true", help="print a summary as JSON")
    simulate.set_defaults(func=_simulate)

    importer = subparsers.add_parser(
        "import",
        help="real rig data (CSV) to MCAP input messages",
        description=(
            "Convert rig time logs to the input format (one JSON payload per value, SI) in an "
            "MCAP file that tdmon replays like a flight recording. Empty cells send nothing; a "
            "non-numeric cell is an error naming the line and the column."
        ),
    )
    kinds = importer.add_subparsers(dest="layout", metavar="LAYOUT", required=True)
    volve = kinds.add_parser("volve", help="a Volve F-4 CSV time log",
                             description="Import a CSV in the Volve F-4 layout (time_utc, "
                                         "hookload_kN, surface_torque_kNm, bit_depth_m, ...).")
    volve.add_argument("csv", metavar="CSV", help="the CSV file")
    volve.add_argument("--out", required=True, metavar="X.mcap", help="output MCAP file")
    volve.add_argument("--prefix", default="rig/F4", help="topic prefix (default: rig/F4)")
    volve.add_argument("--json", action="store_true", help="print a summary as JSON")
    volve.set_defaults(func=_import_volve)

    generic = kinds.add_parser("csv", help="any CSV with a column map",
                               description="Import a CSV with a TOML column map: [time] column "
                                           "and format, [channels.<channel>] column and unit.")
    generic.add_argument("csv", metavar="FILE", help="the CSV file")
    generic.add_argument("--map", required=True, metavar="MAP.toml", help="column map")
    generic.add_argument("--out", required=True, metavar="X.mcap", help="output MCAP file")
    generic.add_argument("--prefix", default=None,
                         help="topic prefix (default: the map's, else rig/import)")
    generic.add_argument("--json", action="store_true", help="print a summary as JSON")
    generic.set_defaults(func=_import_generic)


def _utc(t: float | None) -> str:
    return "-" if t is None else datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def _simulate(args: argparse.Namespace) -> int:
    from tdmon.replay.scenario import load_scenario_model
    from tdmon.replay.simulate import simulate_to_mcap

    scenario = load_scenario_model(args.scenario, seed=args.seed)
    try:
        session, count = simulate_to_mcap(scenario, args.out, progress=sys.stderr.isatty())
    except ModelError as exc:
        raise ConfigError(args.scenario, "phase", str(exc)) from exc
    states = sorted(set(session.timeline.state))
    summary = {
        "out": str(args.out), "messages": count, "duration_s": session.timeline.duration,
        "samples": {name: int(series.t.size) for name, series in session.channels.items()},
        "states": states,
        "alarms": [{"t": a.t, "kind": a.kind} for a in session.alarms],
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{args.out}: {count} messages, {session.timeline.duration / 60:.1f} min of rig "
              f"time from {_utc(scenario.start)}; states: {', '.join(states)}; "
              f"expected alarms: {', '.join(a.kind for a in session.alarms) or 'none'}")
    return 0


def _report(result: Any, as_json: bool) -> int:
    summary = {"out": str(result.path), "rows": result.rows, "messages": result.messages,
               "per_channel": result.per_channel, "first_t": result.first_t,
               "last_t": result.last_t}
    if as_json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{result.path}: {result.messages} messages from {result.rows} rows, "
              f"{_utc(result.first_t)} to {_utc(result.last_t)}")
    return 0


def _import_volve(args: argparse.Namespace) -> int:
    from tdmon.replay.importers import import_volve

    result = import_volve(args.csv, args.out, prefix=args.prefix, progress=sys.stderr.isatty())
    return _report(result, args.json)


def _import_generic(args: argparse.Namespace) -> int:
    from tdmon.replay.importers import import_csv, load_column_map

    layout, map_prefix = load_column_map(args.map)
    prefix = args.prefix or map_prefix or "rig/import"
    result = import_csv(args.csv, layout, args.out, prefix=prefix,
                        progress=sys.stderr.isatty())
    return _report(result, args.json)
