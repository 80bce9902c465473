"""The flight recorder on a second core: :class:`McapRecorder` in a child process.

:class:`RecorderProcess` is a :class:`~tdmon.record.sink.Recorder` like it whose
``write_batch`` only appends the batch to a parcel; parcels are pickled and sent over a pipe
to a child process, which runs an ordinary :class:`McapRecorder`. Encoding, framing,
compression and disk I/O then happen on the other core, and a slow disk never stalls the
event loop. A batch pickles as its rows (:meth:`~tdmon.record.batch.Batch.rows`: a burst's
raw input and samples as tuples of plain values), so their messages are made in the child
(docs/daemon.md, "Bursts"); ``durable_mark``, ``is_durable`` and ``request_flush`` let the
daemon acknowledge what is in the file without waiting for the child. ``tdmon run`` records
this way where it may use two cores (``[recorder] process``); figures in docs/benchmarks.md.

Behaviour kept from :class:`McapRecorder`:

* A message is in the file at most ``flush_interval_s`` after ``write_batch``: a parcel is
  sent when it is full or half a flush interval old (a background thread sends it when the
  pipeline is quiet), and the child flushes as the in-process recorder does.
* Nothing raises into the pipeline: a failure in the child is reported through ``on_alarm``
  (``recorder_failed`` / ``recorder_resumed``, on the caller's thread) and counted; if the
  child process itself dies, every message from then on is counted as lost and one
  ``recorder_failed`` alarm says so.
* Start-up problems (output folder missing, unwritable, full) raise
  :class:`~tdmon.errors.RecordError` from the constructor, with the child's message.
* The child ignores SIGINT (Ctrl-C in a terminal reaches the whole process group): it keeps
  writing until the parent closes it. If the parent dies, the child sees the pipe close and
  finishes the file (summary and footer) with everything it received.

Messages must not be changed after ``write_batch``: they are pickled when the parcel is sent.
The pipe is bounded, so a child that falls behind slows ``write`` down rather than letting
memory grow.
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import pickle
import signal
import socket
import subprocess
import sys
import threading
import time
import weakref
from collections.abc import Mapping
from multiprocessing.connection import Connection
from pathlib import Path
from types import TracebackType
from typing import Any, Final

import tdmon
from tdmon.errors import RecordError
from tdmon.messages import alarm_message
from tdmon.record.batch import Batch
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.sink import AlarmHook, Recorder, RecorderStats, call_alarm_hook
from tdmon.vocabulary import AlarmKind, Severity

__all__ = ["RecorderProcess"]

log = logging.getLogger(__name__)

#: Messages per parcel: large enough that pickling and the pipe cost little per message, small
#: enough (~100-250 kB pickled) that sending one is a short pause for the pipeline.
BATCH_SIZE = 512

#: Bytes in flight to the child [bytes]: ~40 parcels of raw input and samples.
PIPE_BUFFER = 4 * 1024 * 1024

_PICKLE = pickle.HIGHEST_PROTOCOL


class _Tag:
    """The first element of every tuple on the pipe between the parent and the child (a parcel
    of batches is a bare list, untagged). Plain strings on the wire: the pipe carries no
    class that both ends would have to import alike."""

    # parent -> child: a command; the child's reply carries the same tag
    STATS: Final = "stats"
    FLUSH: Final = "flush"
    RETRY: Final = "retry"
    REGISTER_TOPIC: Final = "register_topic"
    CLOSE: Final = "close"
    FLUSH_SOON: Final = "flush_soon"  # answered by DURABLE, not waited for
    # child -> parent: unasked events, and the answers to starting and to CLOSE
    READY: Final = "ready"
    ERROR: Final = "error"
    ALARM: Final = "alarm"
    STATE: Final = "state"
    CLOSED: Final = "closed"
    DURABLE: Final = "durable"  # every parcel up to this count is flushed into the file


class RecorderProcess(Recorder):
    """A :class:`McapRecorder` running in a child process (same parameters and interface).

    Parameters
    ----------
    folder, **options
        Passed to :class:`McapRecorder` in the child (``path``, ``overwrite``, ``prefix``,
        ``rotate_s``, ``flush_interval_s``, ``extra_topics``, ...).
    on_alarm
        As for :class:`McapRecorder`; called on the caller's thread from ``write``, ``flush``,
        ``retry`` and ``close``.
    batch_size
        Messages sent to the child at once (in one parcel).
    start_timeout_s, close_timeout_s
        How long to wait for the child to start (and open its first file) and to finish.
    """

    def __init__(
        self,
        folder: str | os.PathLike[str] | None = None,
        *,
        on_alarm: AlarmHook | None = None,
        batch_size: int = BATCH_SIZE,
        start_timeout_s: float = 60.0,
        close_timeout_s: float = 300.0,
        **options: Any,
    ) -> None:
        self.on_alarm = on_alarm
        self.folder = None if folder is None else Path(folder)  # as McapRecorder's
        self.flush_interval_s = float(options.get("flush_interval_s", 1.0))
        if not self.flush_interval_s > 0:
            raise RecordError(f"flush interval must be positive, got {self.flush_interval_s}")
        self.batch_size = max(1, int(batch_size))
        self.close_timeout_s = close_timeout_s
        self._send_every = self.flush_interval_s / 2
        self._lock = threading.RLock()
        # the parcel: batches to send, in order, and the messages they hold
        self._parcel: list[Batch] = []
        self._in_parcel = 0
        # parcels sent, parcels the child has flushed into its file (as it last said), and
        # the count a flush was last asked at (see durable_mark)
        self._sent = self._durable = self._flush_asked = 0
        self._send_at = time.monotonic() + self._send_every
        self._pending_alarms: list[dict[str, Any]] = []
        self._error: RecordError | None = None
        self._path: Path | None = None
        self._dead = False
        self._closed = False
        # counted here: what never reached the child (unpicklable, or the child was gone)
        self._lost_here = 0
        self._unencodable_here = 0
        self._last_stats = RecorderStats()
        self._final_stats: RecorderStats | None = None
        self.recovered: list[Any] = []

        try:
            self._conn, self._process = _start_child()
        except OSError as exc:
            raise RecordError(f"cannot start the recorder's process: {exc}") from exc
        try:
            self._conn.send((folder, options, logging.getLogger().level))
            ready = self._wait_for(_Tag.READY, start_timeout_s)
        except (RecordError, OSError) as exc:
            self._stop_child()
            if isinstance(exc, RecordError):
                raise
            raise RecordError(f"the recorder's process did not start: {exc}") from exc
        self._path = None if ready[0] is None else Path(ready[0])
        self.recovered = list(ready[1])
        self._pending_alarms.extend(ready[2])
        self._send_at = time.monotonic() + self._send_every  # from when the child took over
        _OPEN.add(self)

        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, name="tdmon-recorder-send",
                                         daemon=True)
        self._flusher.start()

    # -- the recorder's interface -----------------------------------------------------------

    @property
    def error(self) -> RecordError | None:
        """The failure the recorder is in (as last reported by the child)."""
        with self._lock:
            self._drain()
        return self._error

    @property
    def path(self) -> Path | None:
        """The file being written (as last reported by the child)."""
        return self._path

    @property
    def stats(self) -> RecorderStats:
        """Counters of the child's recorder plus what was lost on the way to it."""
        with self._lock:
            if self._final_stats is None and not self._dead:
                self._send_parcel()
                reply = self._request(_Tag.STATS)
                if reply is not None:
                    self._last_stats = reply
            snapshot = (self._final_stats or self._last_stats).copy()
            snapshot.lost += self._lost_here
            snapshot.unencodable += self._unencodable_here
            return snapshot

    def write_batch(self, batch: Batch) -> None:
        """Queue a batch for the child; never raises for recording problems. The parcel is
        sent when it holds ``batch_size`` messages or is due."""
        count = len(batch)
        with self._lock:
            if self._closed or self._dead:
                self._lost_here += count
                return
            self._parcel.append(batch)
            self._in_parcel += count
            if self._in_parcel >= self.batch_size or time.monotonic() >= self._send_at:
                self._send_parcel()
        if self._pending_alarms:
            self._fire_alarms()

    # -- acknowledging what is in the file, without waiting for the child ---------------------

    def durable_mark(self) -> int:
        """A mark of everything written so far: :meth:`is_durable` of it says when all of it
        is flushed into the file. For the daemon's acknowledgements (``AckWindow``), which
        must not wait on the child as ``flush`` and ``stats`` do."""
        with self._lock:
            return self._sent + (1 if self._parcel else 0)

    def is_durable(self, mark: int) -> bool:
        """Whether what was written before ``durable_mark`` gave ``mark`` is flushed into the
        file, as the child last said; also true once the recorder has failed or its process is
        gone (that loss is alarmed and counted, and monitoring goes on, as with ``flush``)."""
        with self._lock:
            self._drain()
            return self._durable >= mark or self._dead or self._error is not None

    def request_flush(self) -> None:
        """Send what is batched and have the child flush its file, without waiting: its answer
        moves :meth:`is_durable` on. One such request at a time."""
        with self._lock:
            self._send_parcel()
            if (self._dead or self._closed or self._durable >= self._sent
                    or self._durable < self._flush_asked):  # nothing new, or one on its way
                return
            self._flush_asked = self._sent
            try:
                self._conn.send((_Tag.FLUSH_SOON,))
            except (OSError, ValueError) as exc:
                self._child_gone(f"the recorder process could not be reached: {exc}")

    def register_topic(self, topic: str, schema: Mapping[str, Any]) -> None:
        """Add a topic with its JSON Schema (see :meth:`McapRecorder.register_topic`)."""
        with self._lock:
            self._send_parcel()
            problem = self._request(_Tag.REGISTER_TOPIC, topic, dict(schema))
        self._fire_alarms()
        if problem:
            raise RecordError(problem)

    def flush(self) -> None:
        """Send what is queued and have the child flush its file."""
        with self._lock:
            self._send_parcel()
            self._request(_Tag.FLUSH)
        self._fire_alarms()

    def retry(self) -> bool:
        """In the failure state, have the child try a new file now; whether it records."""
        with self._lock:
            self._send_parcel()
            recording = bool(self._request(_Tag.RETRY))
        self._fire_alarms()
        return recording

    def close(self) -> None:
        """Send what is queued and let the child finish its file; idempotent. Returns once the
        file is finished (the child's own exit, ~30 ms of interpreter shutdown, is waited for
        by a background thread)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._stop.set()
        if threading.current_thread() is not self._flusher:
            self._flusher.join()
        finished = False
        with self._lock:
            self._send_parcel()
            if not self._dead:
                try:
                    self._conn.send((_Tag.CLOSE,))
                    final = self._wait_for(_Tag.CLOSED, self.close_timeout_s)
                    self._final_stats = final[0]
                    finished = True
                except RecordError as exc:
                    self._child_gone(str(exc))
                except (OSError, ValueError) as exc:
                    self._child_gone(f"the recorder process could not be reached: {exc}")
            self._stop_child(wait=not finished)
            self._path = None
        _OPEN.discard(self)
        self._fire_alarms()

    def __enter__(self) -> RecorderProcess:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- internals (call with the lock held) ----------------------------------------------

    def _send_parcel(self) -> None:
        parcel = self._parcel
        self._send_at = time.monotonic() + self._send_every
        if not parcel:
            self._drain()
            return
        count, self._parcel, self._in_parcel = self._in_parcel, [], 0
        if self._dead:
            self._lost_here += count
            return
        try:
            payload = pickle.dumps(parcel, protocol=_PICKLE)
        except Exception:
            payload, count = self._picklable(parcel)
        try:
            self._conn.send_bytes(payload)
            self._sent += 1
        except (OSError, ValueError) as exc:
            self._lost_here += count
            self._child_gone(f"the recorder process stopped taking messages ({exc})")
            return
        self._drain()

    def _picklable(self, parcel: list[Batch]) -> tuple[bytes, int]:
        """The parcel without the batches that are not data at all, pickled, and the number
        of messages kept; the others counted."""
        kept, count = [], 0
        for batch in parcel:
            size = len(batch)
            try:
                pickle.dumps(batch, protocol=_PICKLE)
            except Exception as exc:
                self._unencodable_here += size
                self._lost_here += size
                log.error("%d message(s) on %s cannot be recorded: %s", size, batch.topic, exc)
            else:
                kept.append(batch)
                count += size
        return pickle.dumps(kept, protocol=_PICKLE), count

    def _drain(self) -> None:
        """Take in the events the child sent (alarms, file and error changes)."""
        if self._dead or self._conn.closed:
            return
        try:
            while self._conn.poll():
                self._handle(self._conn.recv())
        except (EOFError, OSError) as exc:
            self._child_gone(f"the recorder process stopped ({exc or 'pipe closed'})")

    def _handle(self, event: tuple[Any, ...]) -> tuple[Any, ...] | None:
        tag = event[0]
        if tag == _Tag.DURABLE:
            self._durable = max(self._durable, event[1])
        elif tag == _Tag.ALARM:
            self._pending_alarms.append(event[1])
        elif tag == _Tag.STATE:
            error, path = event[1], event[2]
            self._error = None if error is None else RecordError(error)
            self._path = None if path is None else Path(path)
        else:
            return event
        return None

    def _wait_for(self, tag: str, timeout: float) -> tuple[Any, ...]:
        """Handle events until the child's ``tag`` reply arrives; its fields."""
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            try:
                if remaining <= 0 or not self._conn.poll(remaining):
                    raise RecordError(f"the recorder process did not answer within {timeout:g} s")
                event = self._conn.recv()
            except (EOFError, OSError) as exc:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self._process.wait(timeout=1.0)
                code = self._process.returncode
                raise RecordError(
                    f"the recorder process exited (code {code}) before answering: "
                    f"{exc or 'pipe closed'}"
                ) from None
            other = self._handle(event)
            if other is None:
                continue
            if other[0] == _Tag.ERROR:
                raise RecordError(other[1])
            if other[0] == tag:
                return other[1:]
            log.debug("unexpected message from the recorder process: %r", other[0])

    def _request(self, command: str, *args: Any) -> Any:
        """Ask the child something and wait for the answer (None when it is gone)."""
        if self._dead:
            return None
        try:
            self._conn.send((command, *args))
            return self._wait_for(command, self.close_timeout_s)[0]
        except RecordError as exc:
            self._child_gone(str(exc))
        except (OSError, ValueError) as exc:
            self._child_gone(f"the recorder process could not be reached: {exc}")
        return None

    def _child_gone(self, why: str) -> None:
        if self._dead:
            return
        self._dead = True
        self._lost_here += self._in_parcel
        self._parcel, self._in_parcel = [], 0
        error = RecordError(f"{why}; messages are counted as lost from now on")
        first = self._error is None
        self._error = error
        log.error("%s", error)
        if first:
            self._pending_alarms.append(alarm_message(
                time.time(), AlarmKind.RECORDER_FAILED, Severity.CRITICAL, str(error),
                value=self._lost_here))

    def _stop_child(self, wait: bool = True) -> None:
        with contextlib.suppress(OSError):
            self._conn.close()
        if wait:
            _reap(self._process, self.close_timeout_s)
        else:
            threading.Thread(target=_reap, args=(self._process, self.close_timeout_s),
                             name="tdmon-recorder-reap", daemon=True).start()

    def _fire_alarms(self) -> None:
        with self._lock:
            alarms, self._pending_alarms = self._pending_alarms, []
        call_alarm_hook(self.on_alarm, alarms)

    def _flush_loop(self) -> None:
        # a quiet pipeline: what waits in the parcel still reaches the file in time
        tick = min(self._send_every / 2, 0.25)
        while not self._stop.wait(tick):
            with self._lock:
                if self._closed:
                    return
                if self._parcel and time.monotonic() >= self._send_at:
                    self._send_parcel()


def _reap(process: subprocess.Popen[bytes], timeout: float) -> None:
    """Wait for the recorder's process to exit; terminate it after ``timeout`` [s]."""
    try:
        process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        log.error("the recorder process did not stop; terminating it")
        process.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            process.wait(timeout=5.0)


#: recorders not closed yet: closed at interpreter exit (the child then finishes its file)
_OPEN: weakref.WeakSet[RecorderProcess] = weakref.WeakSet()


@atexit.register
def _close_open_recorders() -> None:
    for recorder in list(_OPEN):
        with contextlib.suppress(Exception):
            recorder.close()


# -- the child --------------------------------------------------------------------------------

def _start_child() -> tuple[Connection, subprocess.Popen[bytes]]:
    """A fresh interpreter running :func:`child_main` on one end of a socket pair.

    Not multiprocessing's "spawn": that re-imports the parent's ``__main__`` script in the
    child, which fails (or runs the script again) for any script without an
    ``if __name__ == "__main__"`` guard. Its own session: Ctrl-C in the terminal does not
    reach it.
    """
    ours, theirs = socket.socketpair()
    with ours, theirs:
        # room for bursts: while the child compresses a chunk (tens of ms) the parent goes on
        # sending instead of waiting (the kernel caps this at net.core.wmem_max)
        ours.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, PIPE_BUFFER)
        env = dict(os.environ)
        # the same tdmon as this process, whatever the child's working directory
        package_root = str(Path(tdmon.__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join(
            [package_root, *filter(None, [env.get("PYTHONPATH")])])
        fd = theirs.fileno()
        process = subprocess.Popen(
            [sys.executable, "-c",
             f"from tdmon.record.writer_process import child_main; child_main({fd})"],
            pass_fds=[fd], stdin=subprocess.DEVNULL, env=env, start_new_session=True,
        )
        return Connection(ours.detach()), process


def child_main(fd: int) -> None:
    """Entry point of the recorder's process: ``fd`` is its end of the socket pair."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    conn = Connection(fd)
    try:
        folder, options, log_level = conn.recv()
    except (EOFError, OSError):
        return
    _serve(conn, folder, options, log_level)


def _serve(conn: Connection, folder: Any, options: dict[str, Any], log_level: int) -> None:  # noqa: C901  (complex today; simplify when next touched)
    """The child's main loop: a McapRecorder fed from the pipe until ``close`` or EOF."""
    logging.basicConfig(level=log_level or logging.WARNING,
                        format="%(levelname)s tdmon-recorder: %(message)s")
    alarms: list[dict[str, Any]] = []
    try:
        recorder = McapRecorder(folder, on_alarm=alarms.append, **options)
    except Exception as exc:  # RecordError, or options the recorder refuses
        with contextlib.suppress(OSError):
            conn.send((_Tag.ERROR, str(exc) if isinstance(exc, RecordError)
                       else f"cannot start the recorder: {exc}"))
        conn.close()
        return
    path = recorder.path
    # the recovery alarms go with the answer: the parent fires them at its first write, as the
    # recorder in its own process would
    recorder.send_alarms()
    conn.send((_Tag.READY, None if path is None else str(path), recorder.recovered,
               list(alarms)))
    alarms.clear()
    state: tuple[str | None, str | None] = (None, None if path is None else str(path))

    def report() -> None:
        """Send the recorder's alarms and, when they changed, its error and file."""
        nonlocal state
        for alarm in alarms:
            conn.send((_Tag.ALARM, alarm))
        alarms.clear()
        error, path = recorder.error, recorder.path
        now = (None if error is None else str(error), None if path is None else str(path))
        if now != state:
            state = now
            conn.send((_Tag.STATE, *now))

    # What is flushed into the file, for the parent's acknowledgements: ``marked`` parcels had
    # been written when the recorder had made ``flushes`` flushes; a flush counted later came
    # after them (the recorder writes everything it holds before it flushes), so they are in
    # the file: DURABLE says so.
    parcels = marked = 0
    flushes = recorder.stats.flushes
    idle_s = min(float(options.get("flush_interval_s", 1.0)) / 4, 0.25)

    def durable(now_marked: int) -> None:
        nonlocal marked, flushes
        done = recorder.stats.flushes
        if done > flushes:
            conn.send((_Tag.DURABLE, marked))
        marked, flushes = now_marked, done

    try:
        while True:
            try:
                if not conn.poll(idle_s):
                    durable(parcels)  # a quiet parent: the recorder's own flush covers all
                    continue
                data = conn.recv_bytes()
            except (EOFError, OSError):
                break  # the parent is gone: finish the file with what arrived
            item = pickle.loads(data)
            if type(item) is list:  # a parcel of batches
                for batch in item:
                    recorder.write_batch(batch)
                parcels += 1
                report()
                durable(parcels)
            elif item[0] == _Tag.CLOSE:
                break
            elif item[0] == _Tag.FLUSH_SOON:
                recorder.flush()
                report()
                conn.send((_Tag.DURABLE, parcels))
                marked, flushes = parcels, recorder.stats.flushes
            else:
                reply = _command(recorder, item)
                report()  # before the reply: the parent sees the command's effects with it
                conn.send((item[0], reply))
    finally:
        recorder.close()
        with contextlib.suppress(OSError, ValueError):
            report()
            conn.send((_Tag.CLOSED, recorder.stats))
        conn.close()


def _command(recorder: McapRecorder, item: tuple[Any, ...]) -> Any:
    command = item[0]
    if command == _Tag.STATS:
        return recorder.stats
    if command == _Tag.FLUSH:
        recorder.flush()
        return True
    if command == _Tag.RETRY:
        return recorder.retry()
    if command == _Tag.REGISTER_TOPIC:
        try:
            recorder.register_topic(item[1], item[2])
        except RecordError as exc:
            return str(exc)
        return None
    return None
