"""Replay commands: ``tdmon replay`` (a recording through the daemon's pipeline, checked
against its expectations), ``tdmon simulate`` and ``tdmon import`` (make replay files)."""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tdmon.cli.arguments import add_units_option, display_units
from tdmon.errors import ConfigError, ModelError


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``replay``, ``simulate`` and ``import``."""
    replay = subparsers.add_parser(
        "replay",
        help="run a recording through the daemon's pipeline",
        description=(
            "Feed a replay (MCAP with /tdmon/raw input, e.g. a flight recording, a simulated "
            "session or an imported log) to the daemon built from --config, as fast as "
            "possible or paced, and write the full flight recording to --out (and a Rerun "
            ".rrd). With --check, compare the results with the replay's expectations and exit "
            "1 when one fails. See docs/replays.md."
        ),
    )
    replay.add_argument("replay", type=Path, metavar="X.mcap", help="the replay")
    replay.add_argument("--config", type=Path, metavar="D.toml",
                        help="daemon TOML (default: the expectations' config)")
    replay.add_argument("--out", required=True, type=Path, metavar="Y.mcap",
                        help="flight recording to write (replaced if present)")
    replay.add_argument("--rrd", type=Path, metavar="Z.rrd", help="Rerun recording to write")
    add_units_option(replay, "the Rerun recording (default: $TDMON_UNITS, else the daemon "
                     "file's [display] units)")
    replay.add_argument("--speed", default="max",
                        help="real time x N, or 'max' (default: as fast as possible)")
    replay.add_argument("--check", nargs="?", const="", default=None, metavar="E.toml",
                        help="check expectations (default file: found beside the replay by "
                             "name, replays/expectations/<name>.toml)")
    replay.add_argument("--no-progress", action="store_true", help="no progress bar")
    replay.add_argument("--json", action="store_true", help="print the summary as JSON")
    replay.add_argument("--recorder", choices=("process", "inline"), default="inline",
                        help="where the MCAP recorder runs: 'inline' (default) in this "
                             "process; 'process' in a child process, on a second core (at "
                             "most ~5 %% faster on a long replay when a core is idle, more "
                             "CPU in all)")
    replay.set_defaults(func=_replay)

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
        help="real rig data (CSV, WITSML) to MCAP input messages",
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

    from tdmon.cli.witsml import register_import_witsml

    register_import_witsml(kinds)


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


def _speed(text: str) -> float | None:
    if text == "max":
        return None
    try:
        speed = float(text)
    except ValueError:
        speed = -1.0
    if not speed > 0 or speed == float("inf"):
        raise ConfigError("--speed", "", f"'{text}' is not 'max' or a positive number")
    return speed


def _replay(args: argparse.Namespace) -> int:  # noqa: C901  (complex today; simplify when next touched)
    from tdmon.config.daemon import load_daemon_config
    from tdmon.config.expectations import load_expectations
    from tdmon.display import using
    from tdmon.record.digest import DigestSink
    from tdmon.record.reader import topic_counts
    from tdmon.replay.driver import check_replay_file, raw_message_count, replay
    from tdmon.replay.expectations import check_replay, find_expectations

    # the replay first: a CSV or a killed recording is named as such, before any config is read
    check_replay_file(args.replay)
    speed = _speed(args.speed)
    expectations = None
    if args.check is not None:
        path = Path(args.check) if args.check else find_expectations(args.replay)
        if path is None:
            raise ConfigError(str(args.replay), "--check",
                              "no expectations beside the replay (expectations/<name>.toml); "
                              "give the file")
        expectations = load_expectations(path)
    if args.config is not None:
        config_path = args.config
    elif expectations is not None:
        config_path = expectations.config_path
    else:
        raise ConfigError(str(args.replay), "--config", "give the daemon configuration")
    config = load_daemon_config(config_path)

    show = not args.no_progress and sys.stderr.isatty()
    bar: Any = None
    if show:
        from tqdm import tqdm

        bar = tqdm(total=raw_message_count(args.replay), unit="msg", file=sys.stderr,
                   desc=args.replay.name)
    # the engineer's numbers (well, run, friction, alarms, mu(T) verdict) gathered as the replay
    # makes them: the recording is not read again for them
    digest = DigestSink()
    try:
        # the Rerun views are built inside the daemon: they read the units from tdmon.display
        with using(display_units(args, config.display.units)):
            result = asyncio.run(replay(args.replay, config, args.out, rrd=args.rrd, speed=speed,
                                        progress=bar.update if bar is not None else None,
                                        extra_sinks=[digest],
                                        separate_writer=args.recorder == "process"))
    finally:
        if bar is not None:
            bar.close()
    summary = result.summary()
    # the message count per topic from the recording's summary section (not its messages)
    summary.update(digest.digester.digest([str(args.out)], topic_counts(args.out)))
    if result.interrupted:
        # the recording is finished but partial: expectations about the whole file do not apply
        expectations = None
    checks = [] if expectations is None else check_replay(
        expectations, args.out, replay=args.replay, non_finite_published=result.non_finite)
    failures = [c for c in checks if c.fails]
    if args.json:
        summary["checks"] = [{"name": c.name, "passed": c.passed, "measured": c.measured,
                              "expected": c.expected, "detail": c.detail,
                              "known_issue": c.known_issue} for c in checks]
        print(json.dumps(summary, indent=2))
    else:
        _print_summary(summary)
        for check in checks:
            print(check.line())
        if checks:
            met = sum(c.passed for c in checks)
            known = sum(1 for c in checks if not c.passed and not c.fails)
            print(f"{met}/{len(checks)} expectations met"
                  + (f", {known} known issues" if known else "")
                  + (f", {len(failures)} FAILED" if failures else ""))
    if result.interrupted:
        print(f"tdmon: replay interrupted after {result.messages_in} input messages; "
              f"{args.out} is a finished recording of those (expectations not checked)",
              file=sys.stderr)
        return 130
    return 1 if failures else 0


def _print_summary(s: dict[str, Any]) -> None:
    def counts(d: dict[str, Any]) -> str:
        return ", ".join(f"{k} {v}" for k, v in d.items()) or "none"

    shares = ", ".join(f"{k} {100 * v:.0f} %" for k, v in
                       sorted(s["state_shares"].items(), key=lambda kv: -kv[1])) or "none"
    print(f"{s['input']} -> {s['out']}" + (f" + {s['rrd']}" if s["rrd"] else ""))
    print(f"  messages in {s['messages_in']}, samples {s['samples']}, rejected {s['rejected']}, "
          f"dropped {s['dropped']}, frames {s['frames']}")
    print(f"  windows {s['windows']} (+{s['windows_rejected']} rejected); estimates: "
          f"{counts(s['estimates'])}")
    print(f"  alarms: {counts(s['alarms'])}")
    print(f"  rig states: {shares}")
    if s.get("well", {}).get("name"):
        print(f"  well: {s['well']['name']}")
    friction = ", ".join(
        f"{r['operation']} {r['section_words']} not resolvable ({r['unresolved']} windows)"
        if r["mu_median"] is None else
        f"{r['operation']} {r['section_words']} {r['mu_median']:.3f}"
        + (f" (sd {r['mu_sd']:.3f}, {r['windows']} windows)" if r["mu_sd"] is not None
           else f" ({r['windows']} window)")
        for r in s.get("friction", []))
    if friction:
        print(f"  friction (median): {friction}")
    if s.get("mu_t", {}).get("status", "none") != "none":
        print(f"  {s['mu_t']['words']}")
    print(f"  wall time {s['wall_s']:.2f} s, {s['rate_msg_per_s']:.0f} messages/s"
          + (f"; {s['non_finite']} results with NaN/inf" if s["non_finite"] else ""))
