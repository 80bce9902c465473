"""``tdmon batch``: many recordings through the daemon's pipeline on Dask, and a fleet summary
(docs/replays.md, "Batch re-analysis")."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.errors import ConfigError

if TYPE_CHECKING:
    from tdmon.replay.batch_summary import RecordingOutcome


def register(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Add ``batch``."""
    batch = subparsers.add_parser(
        "batch",
        help="re-analyse many recordings on a Dask cluster, with a fleet summary",
        description=(
            "Replay every recording through the daemon built from --config (the same pipeline "
            "as `tdmon replay`) on Dask distributed: a local cluster of worker processes, or "
            "the scheduler at --scheduler. Writes DIR/recordings/<name>.mcap, the summary "
            "tables DIR/summary/*.parquet and DIR/summary.html (friction per operation and "
            "per hole section, rig-state shares, alarms, per well and recording). A broken "
            "recording is reported with its reason and the others finish; exit code 1 when "
            "any failed. Needs `pip install 'tdmon[batch]'`. See docs/replays.md."
        ),
    )
    batch.add_argument("recordings", nargs="+", type=Path, metavar="X.mcap",
                       help="replays or flight recordings (paths as the workers see them)")
    batch.add_argument("--config", type=Path, metavar="D.toml",
                       help="daemon TOML for every recording (default: the one each replay's "
                            "expectations name, replays/expectations/<name>.toml)")
    batch.add_argument("--out", required=True, type=Path, metavar="DIR",
                       help="output folder (recordings, summary tables, summary.html)")
    batch.add_argument("--scheduler", metavar="ADDRESS",
                       help="a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a "
                            "local cluster on 127.0.0.1, closed at the end)")
    batch.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local cluster (default: one per core, at "
                            "most one per recording)")
    batch.add_argument("--no-progress", action="store_true", help="no progress output")
    batch.add_argument("--json", action="store_true",
                       help="print the outcome per recording as JSON")
    batch.set_defaults(func=_batch)


def _line(outcome: RecordingOutcome, done: int, total: int) -> str:
    name = Path(outcome.recording).name
    if outcome.ok:
        return (f"[{done}/{total}] {name}: {outcome.messages_in} messages, "
                f"{len(outcome.windows)} windows, {sum(outcome.alarms.values())} alarms, "
                f"{outcome.wall_s:.1f} s")
    error = outcome.error or ""
    # most reasons start with the path already (TdmonError lines name their file)
    reason = error[len(outcome.recording):].lstrip(": ") if error.startswith(outcome.recording) \
        else error
    return f"[{done}/{total}] {name}: FAILED: {reason}"


def _batch(args: argparse.Namespace) -> int:  # noqa: C901  (complex today; simplify when next touched)
    from tdmon.replay.batch import run_batch

    if args.workers is not None and args.scheduler is not None:
        raise ConfigError("--workers", "", "applies to the local cluster; with --scheduler the "
                                           "cluster's own workers run the batch")
    if args.config is not None and not args.config.is_file():
        raise ConfigError(str(args.config), "--config", "no such file")
    show = not args.no_progress
    bar: Any = None
    if show and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=len(args.recordings), unit="recording", file=sys.stderr)

    def progress(outcome: RecordingOutcome, done: int, total: int) -> None:
        if bar is not None:
            bar.update(1)
            if not outcome.ok:
                bar.write(_line(outcome, done, total), file=sys.stderr)
        elif show:
            print(_line(outcome, done, total), file=sys.stderr, flush=True)

    try:
        result = run_batch(args.recordings, args.out, config=args.config,
                           scheduler=args.scheduler, workers=args.workers, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    failed = result.failed
    if args.json:
        print(json.dumps([{"recording": o.recording, "ok": o.ok, "error": o.error,
                           "out": o.out, "well": o.well, "messages_in": o.messages_in,
                           "windows": len(o.windows), "alarms": sum(o.alarms.values()),
                           "wall_s": round(o.wall_s, 3)} for o in result.outcomes], indent=2))
    else:
        print(f"{len(result.outcomes) - len(failed)}/{len(result.outcomes)} recordings replayed"
              f"{f', {len(failed)} FAILED' if failed else ''}; summary: "
              f"{args.out / 'summary.html'}, tables in {args.out / 'summary'}")
        for outcome in failed:
            error = outcome.error or ""
            named = error.startswith(outcome.recording)
            print(f"  {error if named else f'{outcome.recording}: {error}'}")
    return 1 if failed else 0
