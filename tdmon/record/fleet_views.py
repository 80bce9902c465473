"""The fleet in Rerun (``tdmon fleet --rerun`` / ``--rerun-file``): one friction series and one
event log per rig, on the wall-clock timeline of the operations centre.

Entities: ``fleet/<rig>/friction`` (the latest friction factor, with ``.../friction_high`` and
``.../friction_low`` at one standard deviation), ``fleet/<rig>/open_alarms`` (their number),
``fleet/<rig>/events`` (state changes and alarms as text). ``<rig>`` is the rig's prefix.
Served live on 127.0.0.1 (a viewer connects with ``rerun --connect``, a browser through
``tdmon fleet --web``) and/or written to an .rrd, with a blueprint on the ``time`` timeline:
the rigs' friction and open alarms, and their events.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tdmon.errors import RecordError

APPLICATION_ID = "tdmon_fleet"
TIMELINE = "time"

_LEVELS = {"info": "INFO", "warning": "WARN", "critical": "ERROR"}


class FleetViews:
    """Log the fleet board's changes to Rerun; ``close()`` ends the recording."""

    def __init__(self, rrd_path: Path | None = None, live_port: int | None = None) -> None:
        import rerun as rr

        if rrd_path is None and live_port is None:
            raise RecordError("the fleet's Rerun view needs an .rrd file or a live port")
        self._rr = rr
        self._rec = rr.RecordingStream(APPLICATION_ID)
        self._rec.set_log_time_enabled(False)
        self._rec.set_log_tick_enabled(False)
        sinks: list[Any] = []
        self.grpc_uri: str | None = None
        try:
            if rrd_path is not None:
                rrd_path.parent.mkdir(parents=True, exist_ok=True)
                sinks.append(rr.FileSink(str(rrd_path)))
            if live_port is not None:
                server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=live_port)
                self.grpc_uri = server.uri
                sinks.append(server)
            self._rec.set_sinks(*sinks, default_blueprint=blueprint())
        except OSError as exc:
            raise RecordError(f"cannot write {rrd_path}: {exc.strerror or exc}") from exc
        except Exception as exc:  # the bindings raise plain RuntimeError/ValueError
            raise RecordError(f"cannot start the Rerun sinks: {exc}") from exc
        self._closed = False

    def _at(self, seconds: float) -> None:
        self._rec.set_time(TIMELINE, timestamp=seconds)

    def friction(self, rig: str, now: float, mu: float, mu_std: float | None) -> None:
        """The rig's latest friction factor (and its band at one standard deviation)."""
        self._at(now)
        scalars = self._rr.Scalars
        self._rec.log(f"fleet/{rig}/friction", scalars(mu))
        if mu_std is not None:
            self._rec.log(f"fleet/{rig}/friction_high", scalars(mu + mu_std))
            self._rec.log(f"fleet/{rig}/friction_low", scalars(mu - mu_std))

    def open_alarms(self, rig: str, now: float, count: int) -> None:
        self._at(now)
        self._rec.log(f"fleet/{rig}/open_alarms", self._rr.Scalars(float(count)))

    def event(self, rig: str, now: float, text: str, severity: str = "info") -> None:
        """A state change or an alarm of the rig, as a line of its event log."""
        self._at(now)
        self._rec.log(f"fleet/{rig}/events",
                      self._rr.TextLog(text, level=_LEVELS.get(severity, "INFO")))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._rec.flush()
            self._rec.disconnect()


def blueprint() -> Any:
    """The fleet's layout on the ``time`` timeline: every rig's friction (with its band) and
    open alarms as series, and every rig's events as one log (rigs come and go: the views
    take whatever lies under ``/fleet``)."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Vertical(
            rrb.TimeSeriesView(origin="/fleet", name="Friction factor (± 1 sd) and open "
                                                    "alarms per rig"),
            rrb.TextLogView(origin="/fleet", name="Events: state changes and alarms"),
            row_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=TIMELINE),
        collapse_panels=False,
    )
