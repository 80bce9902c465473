"""The MCAP flight recorder: a sink that writes every daemon message to rotating MCAP files.

Design points (docs/recording.md):

* JSON messages, one JSON Schema per channel, registered in a file with its first message;
  integer-nanosecond log times; zstd chunks.
* Fast path: ``write_batch`` only queues the batch; once ``BATCH_SIZE`` messages wait (and
  before any flush, statistics read or close) each queued batch's JSON bytes
  (:meth:`~tdmon.record.batch.Batch.encoded`: orjson, or the bytes a replayed recording held)
  are handed to the compiled MCAP writer of foxglove-sdk (docs/benchmarks.md: the recorder's
  share of the daemon).
* ``Writer.flush()`` at least every ``flush_interval_s`` (also from a background thread when
  the pipeline is quiet): a SIGKILLed writer then loses at most that much, and the footer-less
  file it leaves is rewritten by :func:`tdmon.record.recover.recover_folder` on the next start.
* ``finish()`` always runs: on ``close()``, on leaving the ``with`` block, on rotation, and at
  interpreter exit for a recorder nobody closed.
* A failure while running (disk full, file too large, folder removed) never raises into the
  daemon's pipeline: the recorder keeps the error, reports an ``alarm``-shaped message through
  ``on_alarm``, counts every message it could not keep, and retries a new file every
  ``retry_s`` seconds. Only start-up problems raise :class:`tdmon.errors.RecordError`.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import io
import logging
import os
import re
import shutil
import threading
import time
import weakref
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, Final

from foxglove import Channel, Context, Schema, open_mcap
from foxglove.mcap import MCAPCompression, MCAPWriteOptions, MCAPWriter

from tdmon import __version__
from tdmon.errors import RecordError
from tdmon.messages import alarm_message
from tdmon.record import schemas
from tdmon.record.batch import Batch
from tdmon.record.sink import AlarmHook, Recorder, RecorderStats, call_alarm_hook
from tdmon.vocabulary import AlarmKind, Severity

if TYPE_CHECKING:
    from tdmon.record.recover import RecoveryResult

log = logging.getLogger(__name__)

MIB: Final = 1024 * 1024
LIBRARY: Final = f"tdmon {__version__}"
FILE_PATTERN: Final = re.compile(r"^(?P<prefix>.+)_(?P<seq>\d{5,})_(?P<start>\d{8}T\d{6}Z)\.mcap$")

#: Messages queued by ``write_batch`` before they are encoded and written in one go: the lock,
#: the clock and the rotation check are paid per queue, not per message.
BATCH_SIZE: Final = 256

#: Uncompressed bytes per MCAP chunk by default. The writer fills a chunk, then compresses it:
#: at 1 MiB the chunk fits a core's second-level cache beside the pipeline (with another job
#: on the machine the recorder's share was 14-18 % against 17-25 % with 4 MiB chunks; on a
#: quiet machine the two are within the noise; files 1-2 % larger: docs/benchmarks.md).
CHUNK_SIZE: Final = 1 * MIB

#: zstd's level for the chunks. Level 1, its fastest, against foxglove-sdk's default: in the
#: daemon the recorder's writing took 6.0 instead of 6.9 us per input sample, and the files
#: came out 1-4 % *smaller* on the daemon's JSON (docs/benchmarks.md).
ZSTD_LEVEL: Final = 1

#: Chunk compression by name (``compression=`` of :class:`McapRecorder`).
COMPRESSIONS: Final[dict[str, MCAPCompression | None]] = {
    "zstd": MCAPCompression.Zstd, "lz4": MCAPCompression.Lz4, "none": None}

# foxglove-sdk logs every message it cannot write as a warning; the recorder reports the
# failure itself (one error line, one alarm, the lost count), so only errors pass.
logging.getLogger("foxglove").setLevel(logging.ERROR)


def file_name(prefix: str, sequence: int, start: datetime) -> str:
    """``<prefix>_<sequence:05d>_<UTC start YYYYmmddTHHMMSSZ>.mcap``: sorts in recording order."""
    return f"{prefix}_{sequence:05d}_{start.astimezone(UTC):%Y%m%dT%H%M%SZ}.mcap"


def next_sequence(folder: Path, prefix: str) -> int:
    """One more than the highest sequence number of ``prefix`` files already in ``folder``."""
    highest = -1
    for path in folder.glob(f"{prefix}_*.mcap"):
        match = FILE_PATTERN.match(path.name)
        if match and match["prefix"] == prefix:
            highest = max(highest, int(match["seq"]))
    return highest + 1


class _Output:
    """The open file as foxglove's writer sees it (``write``/``seek``/``flush``).

    The writer does not raise a failed write back to ``log``: it logs it and refuses every later
    write. Keeping the first ``OSError`` here lets the recorder see a full disk at the message
    that met it, as it did with an exception.
    """

    __slots__ = ("_stream", "error")

    def __init__(self, stream: io.BufferedWriter[Any]) -> None:
        self._stream = stream
        self.error: OSError | None = None

    def write(self, data: bytes | bytearray) -> int:
        try:
            return self._stream.write(data)
        except OSError as exc:
            self.error = self.error or exc
            raise

    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        try:
            return self._stream.seek(offset, whence)  # writes out the buffer first
        except OSError as exc:
            self.error = self.error or exc
            raise

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as exc:
            self.error = self.error or exc
            raise

    def tell(self) -> int:
        return self._stream.tell()

    def failure(self, exc: Exception) -> OSError:
        """The OSError behind a writer error (``RuntimeError`` from foxglove-sdk)."""
        if isinstance(exc, OSError):
            return exc
        return self.error or OSError(errno.EIO, str(exc))


class _McapFile:
    """One open MCAP file: foxglove-sdk's ``MCAPWriter`` on a locked file, and ``finish()``.

    The recorder's channels live in its own foxglove ``Context`` (not the process's default
    one) and outlast the file: each file gets a channel's schema and channel records with the
    channel's first message in it, and a channel's sequence numbers run on across files.
    """

    def __init__(
        self,
        path: Path,
        context: Context,
        options: MCAPWriteOptions,
        metadata: Mapping[str, str],
        lock: threading.RLock,
    ) -> None:
        self.path = path
        # "x": never overwrite a file another run left behind (it may need recovery).
        self._raw = open(path, "xb", buffering=0)  # noqa: SIM115 - closed in finish/abandon
        header_on_disk = False
        try:
            # An exclusive lock tells a recovery scan in another process that this file is live.
            fcntl.flock(self._raw.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            self._stream = io.BufferedWriter(self._raw, buffer_size=MIB)
            self.output = _Output(self._stream)
            self.unflushed = 0
            self.opened_at = time.monotonic()
            self.last_flush = self.opened_at
            try:
                self._writer: MCAPWriter = open_mcap(self.output, context=context,
                                                     writer_options=options)
                self._finalizer = weakref.finalize(
                    self, _finish_at_exit, self._writer, self._stream, lock
                )
                self._writer.write_metadata("tdmon", dict(metadata))
            except RuntimeError as exc:  # foxglove-sdk's error for a failed write
                raise self.output.failure(exc) from exc
            self.flush()
            header_on_disk = True
        except BaseException:
            self.abandon()
            if not header_on_disk:
                # We created this file and never got a valid header into it (a full disk at a
                # retry): it holds nothing, and a retry every few seconds must not leave a trail
                # of empty files behind.
                with contextlib.suppress(OSError):
                    path.unlink()
            raise

    def flush(self) -> None:
        try:
            self._writer.flush()
        except RuntimeError as exc:  # foxglove-sdk's error for a failed write
            raise self.output.failure(exc) from exc
        if self.output.error is not None:
            raise self.output.error
        self.unflushed = 0
        self.last_flush = time.monotonic()

    def size(self) -> int:
        return self._stream.tell()

    def finish(self) -> None:
        """Write the summary and footer, then close; the file is complete."""
        self._finalizer.detach()
        try:
            try:
                self._writer.close()
            except RuntimeError as exc:
                raise self.output.failure(exc) from exc
            self._stream.flush()
        finally:
            self._close_quietly()
        self.unflushed = 0

    def abandon(self) -> None:
        """Close without a footer (after a write error); recovery rewrites it later."""
        finalizer = getattr(self, "_finalizer", None)
        if finalizer is not None:
            finalizer.detach()
        writer = getattr(self, "_writer", None)
        if writer is not None:
            # the writer refuses every write after the failure; closing it frees it
            with contextlib.suppress(Exception):
                writer.close()
        self._close_quietly()

    def _close_quietly(self) -> None:
        stream = getattr(self, "_stream", None)
        if stream is not None:
            # Closing the buffer retries the failed write; the raw file is closed regardless.
            with contextlib.suppress(OSError, ValueError):
                stream.close()
        with contextlib.suppress(OSError):
            self._raw.close()


def _finish_at_exit(writer: MCAPWriter, stream: io.BufferedWriter[Any],
                    lock: threading.RLock) -> None:
    # A recorder that was never closed: finish its file at interpreter exit rather than leave
    # a footer-less one. The lock keeps the flusher thread (still alive at exit) out of the way;
    # errors cannot be reported anywhere useful this late.
    locked = lock.acquire(timeout=2.0)
    try:
        with contextlib.suppress(Exception):
            writer.close()
        with contextlib.suppress(OSError, ValueError):
            stream.close()
    finally:
        if locked:
            lock.release()


class McapRecorder(Recorder):
    """A :class:`~tdmon.record.sink.Recorder` writing MCAP files to ``folder``.

    Parameters
    ----------
    folder
        Output folder, created if missing. Files are named ``<prefix>_<seq>_<start>.mcap``
        (see :func:`file_name`); the sequence continues after the highest one present, so a
        restarted recorder always starts a new file.
    prefix
        File name prefix.
    rotate_s
        Start a new file after this many seconds of wall-clock time (``None``: never).
    rotate_bytes
        Start a new file once the current one reaches this size [bytes] (``None``: never).
    flush_interval_s
        Longest time [s] a written message stays in memory: bounds the loss on SIGKILL.
    chunk_size
        Uncompressed bytes per MCAP chunk [bytes] (:data:`CHUNK_SIZE`).
    compression
        Chunk compression: "zstd", "lz4" or "none".
    extra_topics
        Topics beyond ``schemas.TOPIC_SCHEMAS`` (e.g. ``/truth/...``), with their JSON Schema.
    on_alarm
        Called with an ``alarm`` message (``kind`` ``recorder_failed`` / ``recorder_resumed``)
        when recording fails or resumes, and ``recording_recovered`` for each unfinished file
        of an earlier run rewritten at start-up (``recover``). Always called from
        ``write_batch``/``flush``/``retry``/``close``, i.e. on the caller's thread (a failure the
        background flusher finds is reported on the next call), and without the recorder's
        lock held, so it may write the alarm back into the recorder.
    retry_s
        After a failure, try a new file at most this often [s].
    min_free_bytes
        Refuse to start when the folder's file system has less free space than this.
    recover
        Before opening the first file, rewrite footer-less files of earlier runs in ``folder``
        (:func:`tdmon.record.recover.recover_folder`); results in ``self.recovered``, each
        logged and alarmed (:func:`tdmon.record.recover.recovery_alarm`).
    background_flush
        Flush from a daemon thread so that data is flushed even when no message arrives.
    path
        Write exactly this file instead (no rotation, no sequence); ``folder``/``prefix`` are
        then taken from it. Used for replays with ``--out Y.mcap``.
    overwrite
        With ``path``: replace an existing file (otherwise that is a start-up error).
    """

    def __init__(
        self,
        folder: str | os.PathLike[str] | None = None,
        *,
        prefix: str = "tdmon",
        rotate_s: float | None = 3600.0,
        rotate_bytes: int | None = 512 * MIB,
        flush_interval_s: float = 1.0,
        chunk_size: int = CHUNK_SIZE,
        compression: str = "zstd",
        extra_topics: Mapping[str, Mapping[str, Any]] | None = None,
        on_alarm: AlarmHook | None = None,
        retry_s: float = 10.0,
        min_free_bytes: int = 16 * MIB,
        recover: bool = True,
        background_flush: bool = True,
        path: str | os.PathLike[str] | None = None,
        overwrite: bool = False,
    ) -> None:
        if (folder is None) == (path is None):
            raise RecordError("give the recorder either an output folder or a file path")
        if flush_interval_s <= 0:
            raise RecordError(f"flush interval must be positive, got {flush_interval_s}")
        self._fixed_path = Path(path) if path is not None else None
        self.folder = self._fixed_path.parent if self._fixed_path else Path(folder)  # type: ignore[arg-type]
        self.prefix = prefix
        self.rotate_s = rotate_s if self._fixed_path is None else None
        self.rotate_bytes = rotate_bytes if self._fixed_path is None else None
        self.flush_interval_s = flush_interval_s
        self.retry_s = retry_s
        self.on_alarm = on_alarm
        if compression.lower() not in COMPRESSIONS:
            raise RecordError(f"unknown MCAP compression {compression!r} "
                              f"(one of {', '.join(COMPRESSIONS)})")
        # no compression threads: zstd runs in the writing thread, as with the mcap package
        # (helper threads would compete with the pipeline for the second core)
        codec = COMPRESSIONS[compression.lower()]
        self._options = MCAPWriteOptions(
            compression=codec, chunk_size=chunk_size, profile="", compression_threads=0,
            compression_level=ZSTD_LEVEL if codec == MCAPCompression.Zstd else 0)
        self._context = Context()
        self._channels: dict[str, Any] = {}  # topic -> its channel's log(data, log_time)
        self._queue: list[Batch] = []
        self._queued = 0  # messages in the queue
        # durability marks: messages accepted so far, and how many of them a flush covered
        self._accepted = self._flushed = 0
        self._topics: dict[str, dict[str, Any]] = {
            topic: dict(schema) for topic, schema in schemas.TOPIC_SCHEMAS.items()
        }
        for topic, schema in (extra_topics or {}).items():
            self._topics[topic] = dict(schema)
        self._lock = threading.RLock()
        self._file: _McapFile | None = None
        self._error: RecordError | None = None
        self._retry_at = 0.0
        self._closed = False
        self._pending_alarms: list[dict[str, Any]] = []
        self._stats = RecorderStats()
        self._next_seq = 0

        self._prepare_folder(min_free_bytes)
        self.recovered: list[RecoveryResult] = []
        if recover and self._fixed_path is None:
            from tdmon.record.recover import recover_folder, recovery_alarm

            self.recovered = recover_folder(self.folder)
            for result in self.recovered:
                # Reported through on_alarm at the first write/flush (the daemon's first status
                # at the latest), when the pipeline that records and publishes alarms exists.
                alarm = recovery_alarm(result, flush_interval_s)
                log.warning("%s", alarm["message"])
                self._pending_alarms.append(alarm)
        self._next_seq = 0 if self._fixed_path else next_sequence(self.folder, prefix)
        try:
            if self._fixed_path is not None and overwrite:
                self._fixed_path.unlink(missing_ok=True)
            self._file = self._open_next()
        except OSError as exc:
            raise RecordError(
                f"cannot record to {exc.filename or self.folder}: {exc.strerror or exc}"
            ) from exc

        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        if background_flush:
            self._flusher = threading.Thread(
                target=self._flush_loop, name="tdmon-mcap-flush", daemon=True
            )
            self._flusher.start()

    # -- public ------------------------------------------------------------------------------

    @property
    def error(self) -> RecordError | None:
        """The failure the recorder is in (``None`` while recording works)."""
        return self._error

    @property
    def path(self) -> Path | None:
        """The file being written, ``None`` while failed or after close."""
        current = self._file
        return current.path if current else None

    @property
    def stats(self) -> RecorderStats:
        with self._lock:
            self._write_queued()
            return self._stats.copy()

    @property
    def registered_topics(self) -> dict[str, dict[str, Any]]:
        """Registered topics and their schemas."""
        return dict(self._topics)

    def register_topic(self, topic: str, schema: Mapping[str, Any]) -> None:
        """Add a topic (e.g. ``/truth/hookload``) with its JSON Schema; registered once per file."""
        with self._lock:
            if topic in self._topics:
                if self._topics[topic] != dict(schema):
                    raise RecordError(f"topic {topic} is already registered with another schema")
                return
            self._write_queued()
            self._topics[topic] = dict(schema)
        self._fire_alarms()

    def write_batch(self, batch: Batch) -> None:
        """Record a batch of messages at their log times [ns since the Unix epoch].

        The batch is queued and encoded with the next ones (at most ``BATCH_SIZE`` messages or
        ``flush_interval_s`` later): its messages must not be changed after this. Never raises
        for I/O problems: see ``error``/``stats``/``on_alarm``.
        """
        count = len(batch.items)
        with self._lock:
            self._queue.append(batch)
            self._queued += count
            self._accepted += count
            if self._queued >= BATCH_SIZE:
                self._write_queued()
        if self._pending_alarms:
            self._fire_alarms()

    def retry(self) -> bool:
        """In the failure state, try a new file now (not waiting for ``retry_s``).

        Returns whether the recorder is recording. For an operator who has freed space.
        """
        with self._lock:
            if self._file is None:
                self._retry_at = 0.0
                self._maybe_resume(time.monotonic())
            recording = self._file is not None
        self._fire_alarms()
        return recording

    def flush(self) -> None:
        """Flush the current file now (also done automatically every ``flush_interval_s``)."""
        with self._lock:
            self._write_queued()
            if self._file is not None:
                self._flush_file(self._file)
        self._fire_alarms()

    def durable_mark(self) -> int:
        """A mark of everything written so far: the messages accepted."""
        return self._accepted

    def is_durable(self, mark: int) -> bool:
        """Whether a flush covered the messages ``mark`` counts (or the recorder failed)."""
        return self._flushed >= mark or self._error is not None

    def request_flush(self) -> None:
        """Flush now: in this process a flush is as quick as a request for one."""
        self.flush()

    def close(self) -> None:
        """Finish the current file (summary, footer) and stop; safe to call twice."""
        with self._lock:
            if self._closed:
                return
            self._write_queued()
            self._closed = True
        self._stop.set()
        if self._flusher is not None:
            self._flusher.join()
        with self._lock:
            current, self._file = self._file, None
            if current is not None:
                try:
                    current.finish()
                    self._flushed = self._accepted
                except OSError as exc:
                    self._file = current
                    self._fail(exc)
                    self._file = None
        self._fire_alarms()

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- internals ---------------------------------------------------------------------------

    def _write_queued(self) -> None:
        """Encode the queued batches and hand them to the file (call with the lock held)."""
        queue = self._queue
        if not queue:
            return
        count = self._queued
        self._queue, self._queued = [], 0
        current, now = self._file_for(count)
        if current is None:
            return
        stats = self._stats
        channels = self._channels
        per_topic: dict[str, int] = {}
        written = 0
        # The writer reports a failed write (only ever when a chunk goes to disk) through the
        # output, and refuses every write after it: looked at once per queue, whose messages
        # are then all lost with what the file held unflushed.
        for batch in queue:
            datas, times, nonfinite, refused = batch.encoded()
            if nonfinite:
                stats.nonfinite_replaced += nonfinite
            for why in refused:
                self._count_unencodable(why)
            topic = batch.topic
            log_message = channels.get(topic) or self._channel(topic)
            for data, log_time_ns in zip(datas, times, strict=True):
                log_message(data, log_time_ns)
            per_topic[topic] = per_topic.get(topic, 0) + len(datas)
            written += len(datas)
        self._written(current, now, per_topic, written)

    def _count_unencodable(self, why: str) -> None:
        """One message that could not be recorded at all (``unencodable`` and ``lost``)."""
        self._stats.unencodable += 1
        self._stats.lost += 1
        log.error("%s; not recorded", why)

    def _flush_file(self, current: _McapFile) -> None:
        """Flush ``current`` (with the queue written): everything accepted is in the file
        (call with the lock held)."""
        try:
            current.flush()
        except OSError as exc:
            self._fail(exc)
            return
        self._stats.flushes += 1
        self._flushed = self._accepted

    def _file_for(self, count: int) -> tuple[_McapFile | None, float]:
        """The file the next ``count`` messages go to, rotated when due, and the clock; None
        (the messages counted as lost) while closed or failed."""
        stats = self._stats
        now = time.monotonic()
        if self._closed:
            stats.lost += count
            return None, now
        current = self._file
        if current is None:
            self._maybe_resume(now)
            current = self._file
        elif self._rotation_due(current, now):
            try:
                current = self._rotate()
            except OSError as exc:
                self._fail(exc)
                current = None
        if current is None:
            stats.lost += count
        return current, now

    def _written(self, current: _McapFile, now: float, per_topic: Mapping[str, int],
                 written: int) -> None:
        """The counters after a queue went to the writer, or its loss if the writer failed;
        the flush when the interval is over."""
        stats = self._stats
        output = current.output
        if output.error is not None:
            stats.lost += written
            self._fail(output.error)
            return
        counts = stats.per_topic
        for topic, count in per_topic.items():
            counts[topic] = counts.get(topic, 0) + count
        current.unflushed += written
        stats.written += written
        if now - current.last_flush >= self.flush_interval_s:
            self._flush_file(current)

    def _channel(self, topic: str) -> Any:
        """The channel of ``topic`` (its ``log``), created on its first message."""
        if topic not in self._topics:
            self._register_untyped(topic)
        schema = Schema(name=schemas.schema_name(topic), encoding="jsonschema",
                        data=schemas.schema_bytes(self._topics[topic]))
        channel = Channel(topic, schema=schema, message_encoding="json", context=self._context)
        self._channels[topic] = log_message = channel.base.log
        return log_message

    def _prepare_folder(self, min_free_bytes: int) -> None:
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise RecordError(
                f"cannot create output folder {self.folder}: {exc.strerror or exc}"
            ) from exc
        if not os.access(self.folder, os.W_OK | os.X_OK):
            raise RecordError(f"output folder {self.folder} is not writable")
        try:
            free = shutil.disk_usage(self.folder).free
        except OSError as exc:
            raise RecordError(f"cannot check free space in {self.folder}: {exc}") from exc
        if free < min_free_bytes:
            raise RecordError(
                f"output folder {self.folder} has only {free / MIB:.1f} MiB free "
                f"(need at least {min_free_bytes / MIB:.1f} MiB)"
            )

    def _open_next(self) -> _McapFile:
        if self._fixed_path is not None:
            path = self._fixed_path
            if self._stats.files:
                # A fixed path failed once; never overwrite it: continue beside it.
                path = path.with_name(f"{path.stem}_{len(self._stats.files):05d}{path.suffix}")
        else:
            while True:
                path = self.folder / file_name(self.prefix, self._next_seq, datetime.now(UTC))
                self._next_seq += 1
                if not path.exists():
                    break
        metadata = {
            "library": LIBRARY,
            "sequence": str(self._next_seq - 1),
            "started_utc": datetime.now(UTC).isoformat(),
            "flush_interval_s": repr(self.flush_interval_s),
        }
        opened = _McapFile(path, self._context, self._options, metadata, self._lock)
        self._stats.files.append(path)
        return opened

    def _rotation_due(self, current: _McapFile, now: float) -> bool:
        if self.rotate_s is not None and now - current.opened_at >= self.rotate_s:
            return True
        return self.rotate_bytes is not None and current.size() >= self.rotate_bytes

    def _rotate(self) -> _McapFile:
        current = self._file
        assert current is not None
        current.finish()
        self._file = None
        self._file = self._open_next()
        return self._file

    def _register_untyped(self, topic: str) -> None:
        # Better a message with a permissive schema than a lost one; say so once per topic.
        log.warning("topic %s has no registered schema; recording it as untyped JSON", topic)
        self._stats.untyped_topics += 1
        self._topics[topic] = dict(schemas.UNTYPED)

    def _fail(self, exc: OSError) -> None:
        """Enter the failure state: count what the file still held, alarm, retry later."""
        current, self._file = self._file, None
        where = current.path if current else self.folder
        if current is not None:
            self._stats.written -= current.unflushed
            self._stats.lost += current.unflushed
            current.abandon()
        first = self._error is None
        error = RecordError(
            f"recording to {where} failed: {exc.strerror or exc}; "
            f"messages are counted as lost until a new file can be written"
        )
        error.__cause__ = exc
        self._error = error
        self._stats.failures += 1
        self._retry_at = time.monotonic() + self.retry_s
        log.error("%s", error)
        if first:
            self._pending_alarms.append(alarm_message(
                time.time(), AlarmKind.RECORDER_FAILED, Severity.CRITICAL, str(error),
                value=self._stats.lost))

    def _maybe_resume(self, now: float) -> None:
        if self._closed or now < self._retry_at:
            return
        try:
            self._file = self._open_next()
        except OSError as exc:
            self._retry_at = now + self.retry_s
            log.debug("recorder still failing: %s", exc)
            return
        lost = self._stats.lost
        log.warning("recording resumed in %s after losing %d messages", self._file.path, lost)
        self._error = None
        self._pending_alarms.append(alarm_message(
            time.time(), AlarmKind.RECORDER_RESUMED, Severity.INFO,
            f"recording resumed in {self._file.path}; {lost} messages lost so far", value=lost))

    def send_alarms(self) -> None:
        """Hand the alarms waiting so far (e.g. ``recording_recovered`` from start-up) to
        ``on_alarm`` now rather than at the next write."""
        self._fire_alarms()

    def _fire_alarms(self) -> None:
        with self._lock:
            alarms, self._pending_alarms = self._pending_alarms, []
        call_alarm_hook(self.on_alarm, alarms)

    def _flush_loop(self) -> None:
        # Wakes several times per interval so that a quiet pipeline is still flushed on time.
        tick = min(self.flush_interval_s / 4, 0.25)
        while not self._stop.wait(tick):
            self._background_tick()

    def _background_tick(self) -> None:
        with self._lock:
            now = time.monotonic()
            current = self._file
            if current is None:
                self._maybe_resume(now)
            elif self._queue and now - current.last_flush >= self.flush_interval_s:
                self._write_queued()  # flushes: the interval is over
            elif current.unflushed and now - current.last_flush >= self.flush_interval_s:
                self._flush_file(current)
        # Alarms found here stay pending until the next write/flush/retry/close: the hook then
        # runs on the caller's thread (the daemon's event loop), never on the flusher's.


__all__ = [
    "FILE_PATTERN",
    "McapRecorder",
    "file_name",
    "next_sequence",
]
