"""``tdmon import witsml``: WITSML 1.4.1.1 and 1.3.1.1 time logs to a replay (every curve of the
log listed with what became of it), and a well file drafted from
trajectory, tubular and wbGeometry objects (the object kinds are told apart by their root
element, so the files may be given in any order). Registered by :mod:`tdmon.cli.replay` beside
the CSV importers."""

from __future__ import annotations

import argparse
import json
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tdmon.cli.arguments import output_file
from tdmon.errors import ConfigError, IngestError


def register_import_witsml(kinds: argparse._SubParsersAction[Any]) -> None:
    """Add ``import witsml`` to the ``import`` command's layouts."""
    parser = kinds.add_parser(
        "witsml", help="WITSML 1.4.1.1 / 1.3.1.1 time logs (and a drafted well file)",
        description=(
            "Import WITSML files. Time logs (<logs>, 1.4.1.1 or 1.3.1.1; several files or "
            "chunks of one log, the same log name whatever their uids, are joined in time "
            "order, duplicates dropped and counted) go to --out as input messages, curves found "
            "by classWitsml or mnemonic (docs/witsml.md) and converted from their uom to SI, "
            "nullValue sending nothing; the summary lists every curve and what became of it. "
            "Trajectory, tubular, wbGeometry, rig and fluidsReport files (1.4.1.1) draft a "
            "well file (--well-out) listing what WITSML lacks."),
    )
    parser.add_argument("files", nargs="+", metavar="FILE.xml", help="WITSML object files")
    parser.add_argument("--out", metavar="X.mcap", help="MCAP file for the log(s)")
    parser.add_argument("--well-out", metavar="DRAFT.toml",
                        help="well file to draft from trajectory, tubular and wbGeometry")
    parser.add_argument("--prefix", default=None,
                        help="topic prefix (default: the --map's, else rig/import)")
    parser.add_argument("--curve", action="append", default=[], metavar="CHANNEL=MNEMONIC[:UNIT]",
                        help="the curve feeding a channel (repeatable), e.g. hookload=HKLD or "
                             "torque=TQ:kN*m (the unit replaces the curve's uom)")
    parser.add_argument("--map", metavar="MAP.toml",
                        help="curve map: [curves.<channel>] mnemonic, unit; prefix")
    parser.add_argument("--source-note", default=None,
                        help="free text carried on /reference/source")
    parser.add_argument("--licence", default=None,
                        help="the data's licence (default: Equinor's for a Volve well)")
    parser.add_argument("--attribution", default=None, help="the data's attribution")
    parser.add_argument("--tubular", metavar="UID", default=None,
                        help="the tubular (uid or name) in the hole, when several are given")
    parser.add_argument("--block-weight", default=None, metavar="QUANTITY",
                        help='block weight for the draft, e.g. "655 kN" (WITSML rarely has it)')
    parser.add_argument("--fluid-density", default=None, metavar="QUANTITY",
                        help='fluid density for the draft, e.g. "1.08 sg"')
    parser.add_argument("--json", action="store_true", help="print a summary as JSON")
    parser.set_defaults(func=import_witsml_command)


def _overrides(args: argparse.Namespace) -> tuple[dict[str, tuple[str, str | None]],
                                                   str | None]:
    from tdmon.channels import CHANNEL_UNITS
    from tdmon.config.witsml_map import load_curve_map

    overrides: dict[str, tuple[str, str | None]] = {}
    prefix = None
    if args.map:
        config = load_curve_map(args.map)
        overrides.update(config.overrides())
        prefix = config.prefix
    for text in args.curve:
        channel, sep, rest = text.partition("=")
        mnemonic, _, unit = rest.partition(":")
        channel, mnemonic, unit = channel.strip(), mnemonic.strip(), unit.strip()
        if not sep or not mnemonic:
            raise ConfigError("--curve", text, "expected CHANNEL=MNEMONIC[:UNIT], e.g. "
                                               "hookload=HKLD")
        if channel not in CHANNEL_UNITS:
            raise ConfigError("--curve", text, f"unknown channel '{channel}' (one of "
                                               f"{', '.join(CHANNEL_UNITS)})")
        overrides[channel] = (mnemonic, unit or None)
    return overrides, prefix


def _quantity(flag: str, text: str | None, target: str) -> str | None:
    if text is None:
        return None
    from tdmon.units import parse_quantity

    try:
        value = parse_quantity(text, target)
    except ValueError as exc:
        raise ConfigError(flag, "", f"'{text}': {exc}") from None
    if not value > 0:
        raise ConfigError(flag, "", f"'{text}' must be positive")
    return text.strip()


def _utc(t: float | None) -> str:
    return "-" if t is None else datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def import_witsml_command(args: argparse.Namespace) -> int:
    from tdmon.ingest.witsml import detect_object

    logs: list[Path] = []
    others: list[Path] = []
    for name in args.files:
        path = Path(name)
        try:
            with path.open("rb") as handle:
                kind = detect_object(handle, str(path))
        except OSError as exc:
            raise IngestError(f"cannot read {path}: {exc.strerror or exc}") from exc
        (logs if kind == "log" else others).append(path)
    if logs and not args.out:
        raise ConfigError("--out", "", f"the files hold time logs ({', '.join(map(str, logs))}); "
                                       "give --out X.mcap")
    if others and not args.well_out:
        raise ConfigError("--well-out", "", "the files hold trajectory/tubular/wbGeometry "
                                            f"objects ({', '.join(map(str, others))}); give "
                                            "--well-out DRAFT.toml")
    if args.out and not logs:
        raise ConfigError("--out", "", "no time log (<logs>) among the files")
    if args.well_out and not others:
        raise ConfigError("--well-out", "", "no trajectory, tubular or wbGeometry among the "
                                            "files")
    summary: dict[str, Any] = {}
    if logs:
        summary["log"] = _import_logs(args, logs)
    if others:
        summary["well"] = _draft(args, others)
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0


def _import_logs(args: argparse.Namespace, logs: list[Path]) -> dict[str, Any]:
    from tdmon.replay.witsml_import import import_witsml

    overrides, map_prefix = _overrides(args)
    result = import_witsml(logs, args.out, prefix=args.prefix or map_prefix or "rig/import",
                           overrides=overrides, licence=args.licence,
                           attribution=args.attribution, note=args.source_note,
                           progress=sys.stderr.isatty())
    if not args.json:
        extra = ""
        if len(logs) > 1 or len(result.log_uids) > 1:
            extra = (f"; {len(logs)} file(s), {len(result.log_uids)} chunk(s) (uids "
                     f"{', '.join(result.log_uids)}) joined")
        if extra or result.duplicates or result.out_of_order:
            extra += (f"; dropped {result.duplicates} duplicate and {result.out_of_order} "
                      "out-of-order rows")
        print(f"{result.path}: {result.messages} messages from {result.rows} rows, "
              f"{_utc(result.first_t)} to {_utc(result.last_t)}{extra}")
        print(f"  curves of the log (WITSML {result.version}), {len(result.curve_report)}:")
        width = max((len(f"{fate.mnemonic} [{fate.unit}]") for fate in result.curve_report),
                    default=0)
        for fate in result.curve_report:
            label = f"{fate.mnemonic} [{fate.unit}]"
            print(f"    {label:<{width}}  {fate.note}")
    return {"out": str(result.path), "rows": result.rows, "messages": result.messages,
            "per_channel": result.per_channel, "first_t": result.first_t,
            "last_t": result.last_t, "duplicates": result.duplicates,
            "out_of_order": result.out_of_order, "curves": result.curves,
            "log_uids": list(result.log_uids), "version": result.version,
            "curve_report": [{"mnemonic": fate.mnemonic, "unit": fate.unit,
                              "channel": fate.channel, "note": fate.note}
                             for fate in result.curve_report]}


def _draft(args: argparse.Namespace, files: list[Path]) -> dict[str, Any]:
    from contextlib import ExitStack

    from tdmon.ingest.witsml_well import choose_tubular, draft_well, read_objects
    from tdmon.replay.importers import VOLVE_ATTRIBUTION, VOLVE_LICENCE
    from tdmon.replay.witsml_import import is_volve_well

    block_weight = _quantity("--block-weight", args.block_weight, "N")
    fluid_density = _quantity("--fluid-density", args.fluid_density, "kg/m**3")
    with ExitStack() as stack:
        handles = [(stack.enter_context(path.open("rb")), str(path)) for path in files]
        objects = read_objects(handles)
    tubular = choose_tubular(objects, args.tubular) if args.tubular else None
    note = args.licence and f"Licence: {args.licence}" + (
        f"; attribution: {args.attribution}" if args.attribution else "")
    if not note and is_volve_well(objects.well):
        note = f"Licence: {VOLVE_LICENCE}; attribution: \"{VOLVE_ATTRIBUTION}\""
    draft = draft_well(objects, tubular=tubular, block_weight=block_weight,
                       fluid_density=fluid_density, licence_note=note or None)
    out = output_file(Path(args.well_out), "--well-out")
    try:
        out.write_text(draft.text, encoding="utf-8")
    except OSError as exc:
        raise ConfigError("--well-out", "", f"cannot write {out}: {exc.strerror or exc}") from exc
    if not args.json:
        print(f"{out}: well file drafted; fill in or check:", file=sys.stderr)
        for item in draft.missing:
            print(f"  - {item}", file=sys.stderr)
    return {"well_out": str(out), "missing": list(draft.missing), "notes": list(draft.notes)}
