"""Commands of the flight-recorder area: ``recover``, ``view`` and ``report`` of MCAP files."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from tdmon.cli.arguments import add_units_option, display_units, output_file


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``tdmon recover``, ``tdmon view`` and ``tdmon report``."""
    recover = subparsers.add_parser(
        "recover",
        help="rewrite unfinished (footer-less) MCAP recordings into valid files",
        description=(
            "Rewrite MCAP files left without a footer by a killed recorder: everything up to "
            "the last flush is kept. Finished files are left as they are."
        ),
    )
    recover.add_argument("files", nargs="+", type=Path, metavar="X.mcap")
    recover.add_argument(
        "--out", type=Path, help="write the recovered file here (one input only) instead of "
        "replacing the input"
    )
    recover.set_defaults(func=_recover)

    view = subparsers.add_parser(
        "view",
        help="build the Rerun views (.rrd with a blueprint) of flight recordings",
        description="Build the Rerun recording of one or more MCAP flight recordings.",
    )
    view.add_argument("files", nargs="+", type=Path, metavar="X.mcap")
    view.add_argument("--rrd", type=Path, required=True, metavar="Z.rrd", help="output .rrd")
    view.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_units_option(view, "the views' series and labels (entity names carry the unit)")
    view.set_defaults(func=_view)

    report = subparsers.add_parser(
        "report",
        help="post-well report (HTML with figures, CSV of estimates) of flight recordings",
        description=(
            "Write report.html (figures embedded, PNGs beside it) and estimates.csv for one or "
            "more MCAP flight recordings."
        ),
    )
    report.add_argument("files", nargs="+", type=Path, metavar="X.mcap")
    report.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    report.add_argument("--title", help="report title (default: the first file's name)")
    add_units_option(report, "the figures and tables (estimates.csv stays SI)")
    report.set_defaults(func=_report)


def _recover(args: argparse.Namespace) -> int:
    from tdmon.errors import RecordError
    from tdmon.record.recover import recover_file

    if args.out is not None and len(args.files) != 1:
        raise RecordError("--out needs exactly one input file")
    if args.out is not None:
        output_file(args.out, "--out")
    for path in args.files:
        result = recover_file(path, args.out)
        if result.status == "complete":
            print(f"{path}: complete (has its footer), nothing to do")
        elif result.status == "in_use":
            print(f"{path}: in use by a running recorder, left alone")
        else:
            topics = ", ".join(f"{topic} {n}" for topic, n in sorted(result.per_topic.items()))
            stop = f"; damaged tail dropped ({result.stop_reason})" if result.stop_reason else ""
            print(
                f"{path}: recovered {result.messages} messages into {result.output}"
                f"{' (' + topics + ')' if topics else ''}{stop}"
            )
    return 0


def _view(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tdmon.record.reader import read_messages, topic_counts
    from tdmon.record.rerun_views import RerunViews

    # Counting first also checks every file before the .rrd is created.
    total = sum(sum(topic_counts(path).values()) for path in args.files)
    with (
        RerunViews(args.rrd, units=display_units(args)) as views,
        tqdm(total=total, unit="msg", disable=True if args.no_progress else None) as bar,
    ):
        for path in args.files:
            for topic, log_time_ns, message in read_messages(path):
                views.write(topic, log_time_ns, message)
                bar.update()
    stats = views.stats
    print(
        f"{args.rrd}: {stats.messages} messages, {stats.scalar_rows} scalar rows, "
        f"{stats.logged} other rows, {len(stats.entities)} entities"
    )
    return 0


def _report(args: argparse.Namespace) -> int:
    from tdmon.record.report import write_report

    result = write_report(args.files, args.out, title=args.title, units=display_units(args))
    print(f"{result.html} ({len(result.figures)} figures), {result.csv}")
    return 0
