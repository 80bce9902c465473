"""The sink and recorder protocols every consumer of daemon messages implements
(docs/architecture.md).

:class:`Sink` is the one plug-in point of the pipeline's output (recorders, Rerun views,
publishers, test probes); :class:`Recorder` is what the daemon, the replay driver and the CLI
use of a flight recorder, whichever process it writes from
(:class:`~tdmon.record.mcap_recorder.McapRecorder` in this one,
:class:`~tdmon.record.writer_process.RecorderProcess` in a child).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from tdmon.errors import RecordError

if TYPE_CHECKING:  # mcap_recorder imports this module
    from tdmon.record.mcap_recorder import RecorderStats

log = logging.getLogger(__name__)

#: A message as the daemon produces it: a JSON object (dict) of the shapes in schemas.py.
#: Sinks that only read a message may accept any Mapping.
Message = Mapping[str, Any]


class FiniteMessage(dict[str, Any]):
    """A message whose maker found every number in it finite: a plain dict in every other
    respect (the same JSON, the same comparisons).

    A recorder writes NaN and infinities as ``null`` and counts each message that had one, so
    it searches every message whose JSON holds a ``null`` for them; the monitor's ``model``
    message, made once per frame, holds one almost always (a residual off its curve), and its
    numbers are checked where they are made at a fraction of that search's cost (the
    in-process recorder: ~2 us less per message). Pickled as itself, from a plain dict's copy
    (the default for a dict subclass takes twice as long); the recorder in a child process is
    handed a plain dict's copy instead, which pickles faster still.
    """

    __slots__ = ()

    def __reduce__(self) -> tuple[type[FiniteMessage], tuple[dict[str, Any]]]:
        return FiniteMessage, (dict(self),)


#: Called with an ``alarm``-shaped dict when a sink changes health (fails, resumes).
AlarmHook = Callable[[dict[str, Any]], None]


@runtime_checkable
class Sink(Protocol):
    """Synchronous sink: the daemon calls ``write`` for every message and ``close`` once.

    The pipeline hands each sink the dict it built (a fresh one per message); a sink that does
    network I/O queues inside ``write``. A sink that only wants some topics may say so with a
    ``topics`` attribute (a collection of topics): messages nobody wants are then not built.
    A sink may also have ``write_many(topic, log_times_ns, messages)`` for several messages of
    one topic at once; the daemon then hands it a burst's raw input and samples that way
    (docs/daemon.md, "Bursts"), and one ``write`` per message otherwise. A sink with
    ``write_rows(topic, log_times_ns, make, rows)`` gets those two as rows of plain values
    instead, with ``make`` (a picklable function) that makes each row's message (the recorder
    in a child process makes them there). A sink with ``write_encoded_many(topic,
    log_times_ns, datas)`` gets a replay's raw input as the JSON bytes its recording held,
    when they are there for the whole burst, and a burst's samples as JSON bytes (the
    in-process recorder writes them as they are).
    """

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        """Take one message; must not raise into the caller's pipeline on I/O failure."""

    def close(self) -> None:
        """Flush and release everything; idempotent."""


class Recorder(Sink, Protocol):
    """A flight recorder: a sink writing MCAP that reports its health instead of raising.

    Failures while recording put it in a failure state (``error``) and are reported through
    its alarm hook; messages it could not record are counted in ``stats.lost``.
    """

    @property
    def error(self) -> RecordError | None:
        """The failure the recorder is in (None while recording works)."""

    @property
    def path(self) -> Path | None:
        """The file being written (None while failed or after close)."""

    @property
    def stats(self) -> RecorderStats:
        """Counters since the recorder was created (a snapshot)."""

    def register_topic(self, topic: str, schema: Mapping[str, Any]) -> None:
        """Add a topic with its JSON Schema (raises RecordError for a conflicting schema)."""

    def flush(self) -> None:
        """Get what was written into the file now."""

    def retry(self) -> bool:
        """In the failure state, try a new file now; whether it records."""


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
