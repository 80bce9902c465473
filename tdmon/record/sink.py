"""The sink protocol every recorder and view implements (docs/architecture.md)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from typing import Any, Protocol, runtime_checkable

log = logging.getLogger(__name__)

#: A message as the daemon produces it: a JSON object (dict) of the shapes in schemas.py.
Message = Mapping[str, Any]

#: Called with an ``alarm``-shaped dict when a sink changes health (fails, resumes).
AlarmHook = Callable[[dict[str, Any]], None]


@runtime_checkable
class Sink(Protocol):
    """Synchronous sink: the daemon calls ``write`` for every message and ``close`` once."""

    def write(self, topic: str, log_time_ns: int, message: Message) -> None:
        """Take one message; must not raise into the caller's pipeline on I/O failure."""

    def close(self) -> None:
        """Flush and release everything; idempotent."""


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
