"""The status line of ``tdmon run``: now and then, on stderr, what the daemon is doing.

``tdmon: 23:01:12 | 36.0 samples/s | pick_up at 2450.3 m | mu pick_up 0.276 ± 0.002 |
alarms 2 (last: warning friction_jump)``. On a terminal one line is rewritten in place; into
a file or a pipe each status is a plain line. :class:`StatusLine` is a daemon sink (it reads
the ``state``, ``estimate``, ``alarm`` and ``status`` messages) plus a coroutine that prints.
"""

from __future__ import annotations

import asyncio
import math
import sys
import time
from datetime import datetime
from typing import Any, Final, TextIO

from tdmon.record.sink import MessageSink

__all__ = ["StatusLine"]

_SEVERE: Final = ("warning", "critical")


class StatusLine(MessageSink):
    """Collects the latest daemon results and prints one status every ``every`` seconds.

    Parameters
    ----------
    every : seconds between two statuses [s] (> 0)
    stream : where to print (stderr by default); a terminal gets one line rewritten in place
    """

    topics = frozenset({"/tdmon/state", "/tdmon/estimate", "/tdmon/alarm", "/tdmon/status"})

    def __init__(self, every: float, stream: TextIO | None = None) -> None:
        self.every = every
        self.stream = stream if stream is not None else sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.printed = 0
        self._state: str | None = None
        self._depth = math.nan
        self._friction: tuple[str, float, float] | None = None
        self._alarms = 0
        self._severe = 0
        self._last_alarm: tuple[str, str] | None = None
        self._samples = 0
        self._rate_from: tuple[float, int] = (time.monotonic(), 0)
        self._width = 0

    # -- the sink protocol ---------------------------------------------------------------

    def write(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        """Keep what the next status shows (cheap: the pipeline calls this per message)."""
        if topic == "/tdmon/state":
            self._state = str(message.get("state"))
            depth = message.get("bit_depth_m")
            self._depth = float(depth) if isinstance(depth, int | float) else math.nan
        elif topic == "/tdmon/estimate":
            if message.get("kind") == "window":
                mu = message.get("mu")  # None: friction not resolvable there
                self._friction = (str(message.get("operation")),
                                  float(mu) if isinstance(mu, int | float) else math.nan,
                                  float(message.get("mu_std") or math.nan))
        elif topic == "/tdmon/alarm":
            self._alarms += 1
            severity = str(message.get("severity"))
            self._severe += severity in _SEVERE
            self._last_alarm = (severity, str(message.get("kind")))
        elif topic == "/tdmon/status":
            samples = message.get("samples_in")
            if isinstance(samples, int):
                self._samples = samples

    def close(self) -> None:
        """End a rewritten terminal line with a newline."""
        if self.tty and self._width:
            self.stream.write("\n")
            self.stream.flush()
            self._width = 0

    # -- printing --------------------------------------------------------------------------

    def line(self, now: float | None = None) -> str:
        """The status now (``now``: monotonic time [s], for the sample rate)."""
        now = time.monotonic() if now is None else now
        since, samples = self._rate_from
        rate = (self._samples - samples) / (now - since) if now > since else 0.0
        self._rate_from = (now, self._samples)
        parts = [f"tdmon: {datetime.now().strftime('%H:%M:%S')}", f"{rate:.1f} samples/s"]
        if self._samples == 0 and self._state is None:
            parts.append("waiting for data")
        if self._state is not None:
            where = f" at {self._depth:.1f} m" if math.isfinite(self._depth) else ""
            parts.append(f"{self._state}{where}")
        if self._friction is not None:
            operation, mu, std = self._friction
            spread = f" ± {std:.3f}" if math.isfinite(std) else ""
            parts.append(f"mu {operation} {mu:.3f}{spread}" if math.isfinite(mu)
                         else f"mu {operation} not resolvable")
        if self._alarms:
            severity, kind = self._last_alarm or ("", "")
            parts.append(f"alarms {self._alarms}, {self._severe} warning or critical "
                         f"(last: {severity} {kind})")
        else:
            parts.append("no alarm")
        return " | ".join(parts)

    def show(self, now: float | None = None) -> None:
        """Print one status: rewrite the terminal line, or append a line."""
        text = self.line(now)
        if self.tty:
            padding = " " * max(0, self._width - len(text))
            self.stream.write("\r" + text + padding)
            self._width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
        self.printed += 1

    async def run(self) -> None:
        """Print a status every ``every`` seconds until cancelled."""
        while True:
            await asyncio.sleep(self.every)
            self.show()
