"""A flight recording as pandas DataFrames, one per topic (:func:`read_recording`).

Each message becomes one row; nested objects are flattened with dotted column names
(``hookload_N.pick_up``, ``connections.mqtt``) and lists stay lists in one cell (a profile's
``md_m``). Every frame keeps ``log_time_ns`` (the recorder's log time [ns]); frames whose
messages carry a rig time ``t`` [Unix s] also get ``time`` (the same instant as a UTC
timestamp, to the microsecond). pandas is imported when a recording is read, not with the
module.
"""

from __future__ import annotations

import os
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tdmon.errors import RecordError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["TOPIC_ATTRIBUTES", "Recording", "read_recording"]

#: The daemon's topics and the :class:`Recording` attribute holding each.
TOPIC_ATTRIBUTES: Mapping[str, str] = {
    "/tdmon/raw": "raw",
    "/tdmon/sample": "samples",
    "/tdmon/rejected": "rejected",
    "/tdmon/state": "states",
    "/tdmon/model": "model",
    "/tdmon/estimate": "estimates",
    "/tdmon/alarm": "alarms",
    "/tdmon/status": "status",
    "/tdmon/well": "well",
    "/tdmon/profile": "profile",
}


@dataclass(frozen=True)
class Recording:
    """One recording's messages as DataFrames (an empty frame for a topic it does not hold).

    Attributes
    ----------
    path : the MCAP file
    raw, samples, rejected, states, model, estimates, alarms, status, well, profile : one row
        per message of ``/tdmon/<name>`` (docs/architecture.md lists the fields; values SI)
    other : the other topics by name, e.g. a simulation's ``/truth/friction``
    counts : messages per topic in the file (also of topics not read)
    """

    path: Path
    raw: pd.DataFrame
    samples: pd.DataFrame
    rejected: pd.DataFrame
    states: pd.DataFrame
    model: pd.DataFrame
    estimates: pd.DataFrame
    alarms: pd.DataFrame
    status: pd.DataFrame
    well: pd.DataFrame
    profile: pd.DataFrame
    other: Mapping[str, pd.DataFrame] = field(default_factory=dict)
    counts: Mapping[str, int] = field(default_factory=dict)

    @property
    def topics(self) -> tuple[str, ...]:
        """The topics read that hold at least one message, sorted."""
        held = [topic for topic, name in TOPIC_ATTRIBUTES.items()
                if not getattr(self, name).empty]
        held += [topic for topic, frame in self.other.items() if not frame.empty]
        return tuple(sorted(held))

    def __repr__(self) -> str:
        # the frames would print whole (thousands of lines): the file and its messages per
        # topic, the topics not read marked
        held = set(self.topics)
        counts = ", ".join(f"{topic} {count}" + ("" if topic in held else " (not read)")
                           for topic, count in sorted(self.counts.items()) if count)
        return f"Recording({str(self.path)!r}, messages: {counts or 'none'})"

    def __getitem__(self, topic: str) -> pd.DataFrame:
        """The frame of a topic by its name (``"/tdmon/estimate"``) or attribute
        (``"estimates"``)."""
        if topic in TOPIC_ATTRIBUTES:
            return getattr(self, TOPIC_ATTRIBUTES[topic])
        if topic in TOPIC_ATTRIBUTES.values():
            return getattr(self, topic)
        if topic in self.other:
            return self.other[topic]
        raise KeyError(f"{self.path}: no topic {topic!r} (topics: {', '.join(self.topics)})")


def _frame(rows: list[dict[str, Any]], log_times: list[int]) -> pd.DataFrame:
    import pandas as pd

    frame = pd.json_normalize(rows) if rows else pd.DataFrame()
    frame.insert(0, "log_time_ns", pd.Series(log_times, dtype="int64"))
    if "t" in frame.columns:
        # a float64 Unix time resolves ~0.2 us: rounded, 06:05:00.988 does not show as .98799991
        time = pd.to_datetime(frame["t"], unit="s", utc=True, errors="coerce").dt.round("us")
        frame.insert(1, "time", time)
    return frame


def read_recording(
    path: str | os.PathLike[str],
    topics: Collection[str] | None = None,
    *,
    allow_unfinished: bool = False,
) -> Recording:
    """Read a flight recording (or a replay) into DataFrames, one per topic.

    Parameters
    ----------
    path : the MCAP file
    topics : read only these topics (names such as ``"/tdmon/estimate"``); None: all. The
        frames of topics not read are empty; ``counts`` still counts every topic.
    allow_unfinished : read a file without footer (a killed writer) up to its last flush

    Raises
    ------
    RecordError
        Missing, unreadable, non-MCAP or damaged file; an unfinished one unless
        ``allow_unfinished``.
    """
    from tdmon.record.reader import read_messages, topic_counts

    source = Path(path)
    if topics is not None and isinstance(topics, str):
        raise RecordError(f"{source}: give the topics as a list, not the string {topics!r}")
    rows: dict[str, list[dict[str, Any]]] = {}
    times: dict[str, list[int]] = {}
    for item in read_messages(source, topics, allow_unfinished=allow_unfinished):
        rows.setdefault(item.topic, []).append(item.message)
        times.setdefault(item.topic, []).append(item.log_time_ns)
    frames = {topic: _frame(rows[topic], times[topic]) for topic in rows}
    known = {name: frames.pop(topic, None) for topic, name in TOPIC_ATTRIBUTES.items()}
    return Recording(
        path=source,
        **{name: _frame([], []) if frame is None else frame for name, frame in known.items()},
        other=dict(sorted(frames.items())),
        counts=topic_counts(source, allow_unfinished=allow_unfinished),
    )
