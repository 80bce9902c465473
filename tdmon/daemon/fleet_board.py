"""What an operations centre sees of a fleet: each rig's state, latest friction and open
alarms, kept from the results the rigs' daemons publish on ``<rig>/tdmon/<name>``.

Pure and synchronous: :class:`FleetBoard` takes ``(key, message, received)`` and
:func:`render_table` makes the text ``tdmon fleet`` prints; the transport (Zenoh) and the
refreshing are the command's (``tdmon/cli/fleet.py``, docs/fleet.md).

An alarm is an event, not a condition with an end: the board counts an alarm as **open**
while it is the rig's latest of its kind, of severity warning or critical, and raised less than
``hold`` seconds (rig time: replays show the same as live runs) before the rig's newest result.
``recorder_resumed`` closes ``recorder_failed``.

The friction shown is the newest window estimate's; before the first one, a profile estimate's
only when the windows informed some of its bins (one whose every bin holds the well file's
prior is no result). A lag over :data:`OLD_DATA_LAG_S` is not a delay but data from another
day (a replay put live): the table gives the data's date instead.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from tdmon.vocabulary import AlarmKind, Severity

#: The result names the board reads; the others are skipped.
NAMES = frozenset({"state", "estimate", "alarm", "status"})

#: An alarm kind that closes another (the later message says the condition is over).
CLOSES = {AlarmKind.RECORDER_RESUMED.value: AlarmKind.RECORDER_FAILED.value}

_OPEN_SEVERITIES = frozenset({Severity.WARNING.value, Severity.CRITICAL.value})

#: A rig's lag above this [s] means its data are from another day (a replay put live, a
#: rig clock far off), not a slow feed: the LAG cell shows the data's date.
OLD_DATA_LAG_S = 86_400.0


def split_key(key: str) -> tuple[str, str] | None:
    """``"rig/A/tdmon/state"`` -> ``("rig/A", "state")``; None for a key of no rig result."""
    prefix, sep, name = key.rpartition("/tdmon/")
    if not sep or not prefix or not name or "/" in name:
        return None
    return prefix, name


@dataclass
class RigView:
    """The board's row of one rig: the latest of each result it reads."""

    prefix: str
    received: float = 0.0  # when its newest result arrived (the board's clock) [s]
    rig_t: float | None = None  # the newest ``t`` of its results but status (rig time) [s]
    state: str | None = None
    steady: bool = False
    bit_depth_m: float | None = None
    mu: float | None = None
    mu_std: float | None = None
    operation: str | None = None
    friction_t: float | None = None
    informed: tuple[int, int] | None = None  # a profile's (informed bins, bins)
    lag_s: float | None = None
    samples_in: int | None = None
    dropped: int | None = None
    alarms: dict[str, dict[str, Any]] = field(default_factory=dict)

    def open_alarms(self, hold: float) -> list[dict[str, Any]]:
        """The open alarms, most severe first, then newest first."""
        newest = self.rig_t
        found = [alarm for alarm in self.alarms.values()
                 if alarm.get("severity") in _OPEN_SEVERITIES
                 and (newest is None or newest - float(alarm.get("t", newest)) <= hold)]
        return sorted(found, key=lambda a: (a.get("severity") != Severity.CRITICAL.value,
                                            -float(a.get("t", 0.0))))


class FleetBoard:
    """Every rig seen on the subscribed key expression, by prefix."""

    def __init__(self, hold: float = 600.0, stale: float = 10.0) -> None:
        self.hold = hold
        self.stale = stale
        self.rigs: dict[str, RigView] = {}
        self.messages = 0
        self.skipped = 0

    def update(self, key: str, message: Any, received: float) -> RigView | None:
        """Take one published result; the rig's view, or None when it is not one read here."""
        parts = split_key(key)
        if parts is None or parts[1] not in NAMES or not isinstance(message, dict):
            self.skipped += 1
            return None
        prefix, name = parts
        rig = self.rigs.get(prefix)
        if rig is None:
            rig = self.rigs[prefix] = RigView(prefix)
        self.messages += 1
        rig.received = max(rig.received, received)
        t = _number(message.get("t"))
        # a status is stamped with the daemon's clock, the other results with the rig's
        if t is not None and name != "status":
            rig.rig_t = t if rig.rig_t is None else max(rig.rig_t, t)
        if name == "state":
            rig.state = str(message.get("state"))
            rig.steady = bool(message.get("steady"))
            rig.bit_depth_m = _number(message.get("bit_depth_m"))
        elif name == "estimate":
            self._estimate(rig, message, t)
        elif name == "alarm":
            kind = str(message.get("kind"))
            rig.alarms[kind] = message
            closed = CLOSES.get(kind)
            if closed is not None:
                rig.alarms.pop(closed, None)
        elif name == "status":
            rig.lag_s = _number(message.get("lag_s"))
            rig.samples_in = _integer(message.get("samples_in"))
            rig.dropped = _integer(message.get("dropped"))
        return rig

    @staticmethod
    def _estimate(rig: RigView, message: dict[str, Any], t: float | None) -> None:
        """The newest window estimate is the rig's friction; a profile or mu(T) estimate only
        until a window estimate comes (they describe the whole hole, not the last stand), and
        a profile only when the windows informed some of its bins."""
        mu = _number(message.get("mu"))
        if mu is None:
            return
        window = message.get("kind") == "window"
        if not window and rig.operation is not None:
            return
        if rig.friction_t is not None and t is not None and t < rig.friction_t:
            return
        flags = message.get("informed")
        informed = None
        if message.get("kind") == "profile" and isinstance(flags, list) and flags:
            informed = (sum(bool(flag) for flag in flags), len(flags))
            if informed[0] == 0:
                return  # every bin is the prior: nothing learned yet
        rig.mu = mu
        rig.mu_std = _number(message.get("mu_std"))
        rig.operation = str(message.get("operation")) if window else None
        rig.informed = informed
        rig.friction_t = t

    def rows(self) -> list[RigView]:
        return [self.rigs[prefix] for prefix in sorted(self.rigs)]

    def is_silent(self, rig: RigView, now: float) -> bool:
        """No result from the rig for longer than ``stale`` seconds."""
        return now - rig.received > self.stale


HEADER = ("RIG", "STATE", "BIT DEPTH", "FRICTION", "ALARMS", "LAG", "SEEN")


def row_cells(board: FleetBoard, rig: RigView, now: float) -> tuple[str, ...]:
    """The table's cells of one rig (SI: metres; friction factor with its 1-sigma)."""
    state = rig.state or "-"
    if rig.state is not None and rig.steady:
        state += " (steady)"
    if board.is_silent(rig, now):
        state = f"silent ({state})"
    depth = "-" if rig.bit_depth_m is None else f"{rig.bit_depth_m:,.1f} m"
    if rig.mu is None:
        friction = "-"
    else:
        friction = f"{rig.mu:.3f}"
        if rig.mu_std is not None:
            friction += f" ± {rig.mu_std:.3f}"
        if rig.operation:
            friction += f" {rig.operation}"
        elif rig.informed is not None:
            friction += f" profile, {rig.informed[0]}/{rig.informed[1]} bins informed"
    alarms = rig.open_alarms(board.hold)
    alarm_cell = "-" if not alarms else f"{len(alarms)}: " + ", ".join(
        f"{a.get('kind')}{'!' if a.get('severity') == Severity.CRITICAL.value else ''}"
        for a in alarms)
    lag = lag_text(rig)
    seen = duration_text(max(0.0, now - rig.received), decimals=0) + " ago"
    return (rig.prefix, state, depth, friction, alarm_cell, lag, seen)


def lag_text(rig: RigView) -> str:
    """The LAG cell: how old the rig's newest sample is, or the data's date (UTC) when that
    is over :data:`OLD_DATA_LAG_S` (not a delay: data of another day)."""
    if rig.lag_s is None:
        return "-"
    if rig.lag_s <= OLD_DATA_LAG_S or rig.rig_t is None:
        return duration_text(rig.lag_s)
    day = datetime.fromtimestamp(rig.rig_t, UTC).strftime("%Y-%m-%d")
    return f"data of {day}"


def duration_text(seconds: float, decimals: int = 1) -> str:
    """``seconds`` in the unit that keeps it short: s, min, h or d (a replayed session's lag
    is the age of its data)."""
    for limit, unit, size in ((120.0, "s", 1.0), (7200.0, "min", 60.0),
                              (172_800.0, "h", 3600.0)):
        if seconds < limit:
            return f"{seconds / size:.{decimals}f} {unit}"
    return f"{seconds / 86_400.0:.{decimals}f} d"


def render_table(board: FleetBoard, now: float, width: int | None = None) -> str:
    """The fleet as a plain-text table, one line per rig (cells cut to ``width`` columns)."""
    lines: list[tuple[str, ...]] = [HEADER]
    lines.extend(row_cells(board, rig, now) for rig in board.rows())
    widths = [max(len(cells[i]) for cells in lines) for i in range(len(HEADER))]
    text = [_line(cells, widths, width) for cells in lines]
    if len(lines) == 1:
        text.append("(no rig yet)")
    return "\n".join(text)


def _line(cells: Iterable[str], widths: list[int], width: int | None) -> str:
    line = "  ".join(cell.ljust(w) for cell, w in zip(cells, widths, strict=True)).rstrip()
    return line if width is None or len(line) <= width else line[:max(1, width - 1)] + "…"


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def _integer(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None
