"""The sink contract every consumer of daemon messages meets (docs/architecture.md).

A :class:`Sink` takes :class:`~tdmon.record.batch.Batch` es (``write_batch``) and is closed
once (``close``); it declares the topics it takes (``topics``). The pipeline knows nothing
else of it: a sink asks the batch for the form it needs (messages, JSON bytes, rows), and a
single message is a batch of one. :class:`MessageSink` is the base of the simple sinks that
take one message at a time; :class:`Recorder` is a flight recorder, whichever process it
writes from (:class:`~tdmon.record.mcap_recorder.McapRecorder` in this one,
:class:`~tdmon.record.writer_process.RecorderProcess` in a child), with the marks the daemon
acknowledges its input by; :class:`TestingSink` keeps what it is given.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass, field
from itertools import repeat
from pathlib import Path
from typing import Any

from tdmon.errors import RecordError
from tdmon.record.batch import Batch

__all__ = ["AlarmHook", "Message", "MessageSink", "Recorder", "RecorderStats", "Sink",
           "TestingSink", "call_alarm_hook"]

log = logging.getLogger(__name__)

#: A message as a sink reads it: a JSON object of the shapes in ``schemas.py`` (the daemon
#: makes dicts; a sink that only reads one may take any mapping).
Message = Mapping[str, Any]

#: Called with an ``alarm``-shaped dict when a sink changes health (fails, resumes).
AlarmHook = Callable[[dict[str, Any]], None]


class Sink(ABC):
    """Where the daemon's messages go: ``write_batch`` for every batch, ``close`` once.

    Synchronous: a sink that does network I/O queues inside ``write_batch``, and none raises
    into the pipeline for an I/O failure (a sink that raises is logged and counted in
    ``sink_errors``).
    """

    #: The topics this sink takes; None: every topic. The pipeline hands it no other, and a
    #: message that no sink takes is never made.
    topics: Collection[str] | None = None

    @abstractmethod
    def write_batch(self, batch: Batch) -> None:
        """Take a batch of messages of one topic."""

    def close(self) -> None:  # noqa: B027 - most sinks hold nothing to release
        """Flush and release everything; idempotent."""

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        """Take one message (a batch of one), e.g. when writing a recording directly."""
        self.write_batch(Batch.one(topic, log_time_ns, message))


class MessageSink(Sink):
    """A sink that takes its messages one at a time: a subclass defines ``write``."""

    @abstractmethod
    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        """Take one message (``log_time_ns`` [ns since the Unix epoch])."""

    def write_batch(self, batch: Batch) -> None:
        write, topic = self.write, batch.topic
        for log_time_ns, message in zip(batch.log_times_ns, batch.messages(), strict=True):
            write(topic, log_time_ns, message)


@dataclass
class RecorderStats:
    """Counters of a recorder since it was created (a snapshot: ``Recorder.stats``)."""

    written: int = 0
    """Messages handed to the MCAP writer and not later lost with a failed file."""
    lost: int = 0
    """Messages accepted but not recorded (failure state, or lost with a failed file)."""
    nonfinite_replaced: int = 0
    """Messages in which a NaN/inf was recorded as ``null``."""
    unencodable: int = 0
    """Messages that are not JSON at all (counted in ``lost`` too)."""
    untyped_topics: int = 0
    """Topics written without a registered schema (recorded with a permissive schema)."""
    files: list[Path] = field(default_factory=list)
    """Every file opened, in order (the last one is current unless the recorder failed)."""
    flushes: int = 0
    failures: int = 0
    per_topic: dict[str, int] = field(default_factory=dict)
    """Messages written per topic."""

    def copy(self) -> RecorderStats:
        """A snapshot that later counting does not change."""
        copied = RecorderStats(**vars(self))
        copied.files = list(self.files)
        copied.per_topic = dict(self.per_topic)
        return copied


class Recorder(Sink):
    """A flight recorder: a sink writing MCAP that reports its health instead of raising.

    Failures while recording put it in a failure state (``error``) and are reported through
    its alarm hook; messages it could not record are counted in ``stats.lost``.

    Durability marks: the daemon acknowledges an input message to its broker only once the
    recorder has it in its file (docs/daemon.md, "At-least-once delivery"), without waiting
    for the recorder: ``durable_mark()`` marks everything written so far, ``is_durable(mark)``
    says whether all of it is in the file, and ``request_flush()`` asks for a flush soon.
    """

    @property
    @abstractmethod
    def error(self) -> RecordError | None:
        """The failure the recorder is in (None while recording works)."""

    @property
    @abstractmethod
    def path(self) -> Path | None:
        """The file being written (None while failed or after close)."""

    @property
    @abstractmethod
    def stats(self) -> RecorderStats:
        """Counters since the recorder was created (a snapshot)."""

    @abstractmethod
    def register_topic(self, topic: str, schema: Mapping[str, Any]) -> None:
        """Add a topic with its JSON Schema (raises RecordError for a conflicting schema)."""

    @abstractmethod
    def flush(self) -> None:
        """Get what was written into the file now."""

    @abstractmethod
    def retry(self) -> bool:
        """In the failure state, try a new file now; whether it records."""

    @abstractmethod
    def durable_mark(self) -> int:
        """A mark of everything written so far (for :meth:`is_durable`)."""

    @abstractmethod
    def is_durable(self, mark: int) -> bool:
        """Whether everything written before ``durable_mark`` gave ``mark`` is in the file;
        also true once the recorder has failed (that loss is alarmed and counted, and
        monitoring goes on)."""

    @abstractmethod
    def request_flush(self) -> None:
        """Have what was written flushed into the file soon (without waiting, where the
        recorder can do that)."""


class TestingSink(Sink):
    """Keeps every message it is given, in order, as ``(topic, log_time_ns, message)``
    (tests and examples; ``topics`` as for any sink)."""

    __test__ = False  # not a pytest test class

    def __init__(self, topics: Collection[str] | None = None) -> None:
        self.topics = topics
        self.items: list[tuple[str, int, dict[str, Any]]] = []
        self.batches = 0
        self.closed = False

    def write_batch(self, batch: Batch) -> None:
        self.batches += 1
        self.items.extend(zip(repeat(batch.topic), batch.log_times_ns, batch.messages(),
                              strict=False))

    def of(self, topic: str) -> list[dict[str, Any]]:
        """The messages of ``topic``, in order."""
        return [message for item_topic, _, message in self.items if item_topic == topic]

    def close(self) -> None:
        self.closed = True


def call_alarm_hook(hook: AlarmHook | None, alarms: list[dict[str, Any]]) -> None:
    """Hand each alarm to ``hook`` in order; a hook that raises is logged, never propagated
    (a sink's health report must not break the pipeline that writes to it)."""
    if hook is None:
        return
    for alarm in alarms:
        try:
            hook(alarm)
        except Exception:
            log.exception("recorder alarm hook failed")
