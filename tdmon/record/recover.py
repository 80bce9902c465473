"""Recovery of footer-less MCAP files left by a killed or failed recorder.

A killed writer leaves a file without summary and footer; mcap's seeking reader refuses it, but
every chunk written before the last ``flush()`` is complete. :func:`recover_file` reads those
records in file order and rewrites them into a valid file (same schemas, channels, messages and
metadata, plus a ``tdmon_recovery`` metadata record saying what happened), then replaces the
original atomically. :func:`recover_folder` does this for every unfinished file of a folder and
is what the daemon (through :class:`~tdmon.record.mcap_recorder.McapRecorder`) runs on start-up;
the recorder logs each file it recovered and raises a ``recording_recovered`` alarm
(:func:`recovery_alarm`) whose value is the estimated number of seconds lost
(:func:`seconds_lost`).
"""

from __future__ import annotations

import contextlib
import fcntl
import math
import os
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any, Literal

from mcap.records import Channel, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from tdmon.errors import RecordError
from tdmon.messages import alarm_message
from tdmon.record.reader import (
    MAGIC,
    TolerantScan,
    describe_os_error,
    has_footer,
    open_recording,
)
from tdmon.vocabulary import AlarmKind, Severity

RecoveryStatus = Literal["complete", "recovered", "in_use"]


@dataclass
class RecoveryResult:
    """What :func:`recover_file` found and did."""

    path: Path
    """The file examined."""
    status: RecoveryStatus
    """``complete``: had its footer, untouched; ``recovered``: rewritten; ``in_use``: another
    recorder holds it, untouched."""
    output: Path | None = None
    """Where the valid file now is (``path`` unless an output was given); None if untouched."""
    messages: int = 0
    """Messages recovered."""
    per_topic: dict[str, int] = field(default_factory=dict)
    first_log_time_ns: int | None = None
    last_log_time_ns: int | None = None
    bytes_read: int = 0
    """Size of the original file [bytes]."""
    stop_reason: str = ""
    """Why reading stopped before the end (the damaged tail), empty if it did not."""
    flush_interval_s: float | None = None
    """The writer's flush interval [s], from the file's ``tdmon`` metadata (None: not known)."""


def _locked_by_writer(stream: IO[bytes]) -> bool:
    # The recorder holds LOCK_EX on the file it writes; a shared lock we cannot get means live.
    try:
        fcntl.flock(stream.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    fcntl.flock(stream.fileno(), fcntl.LOCK_UN)
    return False


def _rewrite(stream: IO[bytes], target: Path, result: RecoveryResult) -> None:
    scan = TolerantScan(stream)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    topics: dict[int, str] = {}
    with open(target, "wb") as out:
        writer = Writer(out, compression=CompressionType.ZSTD)
        started = False
        try:
            for record in scan:
                if isinstance(record, Header):
                    writer.start(profile=record.profile, library=record.library)
                    started = True
                    continue
                if not started:
                    writer.start()
                    started = True
                if isinstance(record, Schema):
                    schema_ids[record.id] = writer.register_schema(
                        name=record.name, encoding=record.encoding, data=record.data
                    )
                elif isinstance(record, Channel):
                    channel_ids[record.id] = writer.register_channel(
                        topic=record.topic,
                        message_encoding=record.message_encoding,
                        schema_id=schema_ids.get(record.schema_id, 0),
                        metadata=dict(record.metadata),
                    )
                    topics[record.id] = record.topic
                elif isinstance(record, Message) and record.channel_id in channel_ids:
                    writer.add_message(
                        channel_id=channel_ids[record.channel_id],
                        log_time=record.log_time,
                        publish_time=record.publish_time,
                        data=record.data,
                        sequence=record.sequence,
                    )
                    _count(result, topics[record.channel_id], record.log_time)
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, dict(record.metadata))
                    if record.name == "tdmon":
                        result.flush_interval_s = _positive(
                            record.metadata.get("flush_interval_s"))
            if not started:
                writer.start()
            result.stop_reason = "" if scan.complete else scan.stop_reason
            writer.add_metadata(
                "tdmon_recovery",
                {
                    "source": result.path.name,
                    "recovered_utc": datetime.now(UTC).isoformat(),
                    "messages": str(result.messages),
                    "stop_reason": result.stop_reason,
                },
            )
        finally:
            # finish() even after an error so that no second footer-less file is left behind.
            writer.finish()
        out.flush()
        os.fsync(out.fileno())


def _positive(text: str | None) -> float | None:
    try:
        value = float(text) if text is not None else math.nan
    except ValueError:
        return None
    return value if math.isfinite(value) and value > 0 else None


def seconds_lost(result: RecoveryResult, flush_interval_s: float,
                 now: float | None = None) -> float:
    """Estimated seconds of messages a crashed recorder lost [s] (an upper bound).

    A recorder flushes at least every flush interval, so what a kill loses is what it held in
    memory: at most one interval (the file's own ``flush_interval_s`` metadata, else
    ``flush_interval_s``). When the last intact message's log time is known and closer to
    ``now`` (the restart, [Unix s]) than that, the crash cannot have been later than ``now``, so
    the smaller of the two is taken. Log times of a recording that replays old data are not
    wall-clock times; they then only ever lower the bound when they lie in the past.
    """
    window = result.flush_interval_s or flush_interval_s
    if result.last_log_time_ns is not None:
        since_last = (time.time() if now is None else now) - result.last_log_time_ns / 1e9
        if since_last >= 0:
            window = min(window, since_last)
    return round(window, 3)


def recovery_alarm(result: RecoveryResult, flush_interval_s: float,
                   now: float | None = None) -> dict[str, Any]:
    """The ``recording_recovered`` alarm (severity warning) for a file recovered at start-up.

    ``value`` is :func:`seconds_lost`; the message names the file, the messages kept, the last
    intact message's time and where reading stopped.
    """
    now = time.time() if now is None else now
    lost = seconds_lost(result, flush_interval_s, now)
    if result.last_log_time_ns is None:
        last = "no message was intact"
    else:
        stamp = datetime.fromtimestamp(result.last_log_time_ns / 1e9, UTC)
        last = f"last intact message at {stamp.isoformat(timespec='milliseconds')}"
    where = f"; reading stopped at: {result.stop_reason}" if result.stop_reason else ""
    return alarm_message(
        now, AlarmKind.RECORDING_RECOVERED, Severity.WARNING,
        f"recovered the unfinished recording {result.path} ({result.messages} messages kept, "
        f"{last}; up to {lost:g} s lost{where})",
        value=lost)


def _count(result: RecoveryResult, topic: str, log_time_ns: int) -> None:
    result.messages += 1
    result.per_topic[topic] = result.per_topic.get(topic, 0) + 1
    if result.first_log_time_ns is None or log_time_ns < result.first_log_time_ns:
        result.first_log_time_ns = log_time_ns
    if result.last_log_time_ns is None or log_time_ns > result.last_log_time_ns:
        result.last_log_time_ns = log_time_ns


def recover_file(
    path: str | os.PathLike[str], output: str | os.PathLike[str] | None = None
) -> RecoveryResult:
    """Rewrite a footer-less MCAP file into a valid one with everything up to its last flush.

    Parameters
    ----------
    path
        The file. A file with its footer is left as it is (status ``complete``); one a running
        recorder holds is skipped (status ``in_use``). An empty file (a writer killed before
        its first flush) becomes a valid file with no messages.
    output
        Write the recovered file here instead of replacing ``path``.

    Raises
    ------
    RecordError
        Missing, unreadable or non-MCAP file, or the recovered file cannot be written.
    """
    source = Path(path)
    target = Path(output) if output is not None else source
    try:
        size = source.stat().st_size
    except OSError as exc:
        raise RecordError(describe_os_error(source, exc)) from exc
    result = RecoveryResult(path=source, status="recovered", bytes_read=size)
    if size == 0:
        return _recover_empty(source, target, result)
    with open_recording(source) as stream:
        if _locked_by_writer(stream):
            result.status = "in_use"
            return result
        if has_footer(stream):
            result.status = "complete"
            return result
        temporary = target.with_name(target.name + ".recovering")
        try:
            _rewrite(stream, temporary, result)
            os.replace(temporary, target)
        except OSError as exc:
            with contextlib.suppress(OSError):
                temporary.unlink()
            reason = exc.strerror or exc
            raise RecordError(f"cannot write recovered file {target}: {reason}") from exc
    result.output = target
    return result


def _recover_empty(source: Path, target: Path, result: RecoveryResult) -> RecoveryResult:
    with open(source, "rb") as stream:
        if _locked_by_writer(stream):
            result.status = "in_use"
            return result
    temporary = target.with_name(target.name + ".recovering")
    try:
        with open(temporary, "wb") as out:
            writer = Writer(out)
            writer.start()
            writer.add_metadata(
                "tdmon_recovery",
                {"source": source.name, "messages": "0", "stop_reason": "empty file"},
            )
            writer.finish()
        os.replace(temporary, target)
    except OSError as exc:
        raise RecordError(f"cannot write recovered file {target}: {exc.strerror or exc}") from exc
    result.stop_reason = "empty file"
    result.output = target
    return result


def recover_folder(folder: str | os.PathLike[str]) -> list[RecoveryResult]:
    """Recover every unfinished ``*.mcap`` file in ``folder`` (not recursive).

    Finished files and files held by a running recorder are left alone and not reported. A file
    that is not MCAP at all is skipped (it is not ours to rewrite). Called by the recorder on
    start-up, which logs each result and raises its :func:`recovery_alarm`.
    """
    results: list[RecoveryResult] = []
    directory = Path(folder)
    if not directory.is_dir():
        return results
    for stale in directory.glob("*.mcap.recovering"):
        # A recovery interrupted before its atomic rename: the original is still there.
        with contextlib.suppress(OSError):
            stale.unlink()
    for candidate in sorted(directory.glob("*.mcap")):
        try:
            with open(candidate, "rb") as stream:
                head = stream.read(len(MAGIC))
                if head and head != MAGIC:
                    continue
                if head and has_footer(stream):
                    continue
        except OSError:
            continue
        result = recover_file(candidate)
        if result.status == "recovered":
            results.append(result)
    return results
