"""Rerun views of the daemon's messages: a sink that builds a recording with a blueprint.

The same :class:`RerunViews` serves the live daemon (optionally streaming to a viewer over
gRPC bound to 127.0.0.1) and ``tdmon view X.mcap --rrd Z.rrd`` (fed from a flight recording).
``rerun`` is imported when a :class:`RerunViews` is created, not with this module: it takes
about half a second and most tdmon commands never need it.

Timelines: ``time`` (timestamp, from each message's ``t``) for everything that evolves, and
``bit_depth_cm`` (sequence, integer centimetres; ``bit_depth_in``, integer inches, in field
units) for the "against bit depth" entities under ``vs_depth/``. Those are logged on that
timeline only so that each tab of the blueprint shows its own abscissa once the matching
timeline is selected in the viewer's time panel.

Entities, in the display units of :mod:`tdmon.display` (SI by default: kN, kN m, m, degC;
field: klbf, kft lbf, ft, degF), the unit in the entity's name; the messages stay SI:

* ``hookload_kN/{measured,model/*,band/*}``, ``torque_kNm/{measured,model/rotating}``,
  ``residual/*``: scalars on ``time``; the same under ``vs_depth/`` on ``bit_depth_cm``
  (field: ``hookload_klbf``, ``torque_kftlbf``, ``bit_depth_in``).
* ``friction/<operation>``: window estimates of mu; ``friction/joint`` and ``weight_factor``:
  the joint estimate of friction and string weight (every parameter estimated beside the
  friction has its entity and view, :func:`joint_entity`); ``friction_mu_T/<param>``.
* ``rig_state``: state changes (state timeline view); ``bit_depth_m`` (``bit_depth_ft``).
* ``profile/friction``, ``profile/temperature_C`` (``_F``): bar charts against MD; friction
  only in the bins the windows informed, ``profile/note`` (text) says why the others are out.
* ``well/trajectory`` (LineStrips3D, east/north/up in metres whatever the units: a picture),
  ``well/friction`` (the same path coloured by local friction), ``well/string`` and
  ``well/bit`` (string position).
* ``alarms`` and ``rejected``: text logs; ``status/*``: scalars; ``samples/<channel>``: the
  decoded samples, in SI (``--units si``) or in field units, the unit in the series name.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Final

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.parameters import JOINT_PARAMETERS, EstimatedParameter
from tdmon.channels import CHANNEL_UNITS
from tdmon.display import UnitSystem, current
from tdmon.errors import RecordError
from tdmon.record.sink import Message, MessageSink
from tdmon.vocabulary import EstimateKind, Operation, Severity

log = logging.getLogger(__name__)

APPLICATION_ID: Final = "tdmon"
TIME: Final = "time"
BIT_DEPTH: Final = "bit_depth_cm"
# The "against bit depth" timeline per unit system: its name and its steps per metre.
_DEPTH_TIMELINES: Final[dict[str, tuple[str, float]]] = {"si": (BIT_DEPTH, 100.0),
                                                         "field": ("bit_depth_in", 1 / 0.0254)}
_SEVERITY_LEVEL: Final[dict[str, str]] = {Severity.INFO: "INFO", Severity.WARNING: "WARN",
                                          Severity.CRITICAL: "ERROR"}
# Rebuild the string position only when the bit has moved this much [cm]: a trip logs one
# message per second, and a new 3D polyline for every centimetre would dominate the file.
_STRING_STEP_CM: Final = 100


def _finite(value: Any) -> float | None:
    if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value):
        return float(value)
    return None


def _mu_key(mu: float) -> str:
    return f"mu_{mu:.2f}".replace(".", "_")


@dataclass
class _Series:
    """Rows of one scalar entity waiting for ``send_columns`` (one timeline each)."""

    timeline: str
    index: list[int] = field(default_factory=list)
    values: list[float] = field(default_factory=list)


@dataclass
class ViewStats:
    """What a :class:`RerunViews` has logged."""

    messages: int = 0
    scalar_rows: int = 0
    logged: int = 0
    skipped: int = 0
    entities: set[str] = field(default_factory=set)


def _colour(mu: float, low: float = 0.1, high: float = 0.4) -> tuple[int, int, int]:
    # Blue (low friction) to red (high): readable on the viewer's dark background.
    x = min(1.0, max(0.0, (mu - low) / (high - low)))
    return (int(40 + 215 * x), int(120 * (1 - abs(2 * x - 1)) + 40), int(255 - 215 * x))


class RerunViews(MessageSink):
    """A :class:`~tdmon.record.sink.Sink` building the tdmon Rerun recording.

    Parameters
    ----------
    rrd_path
        Write the recording (with its default blueprint) to this ``.rrd`` file.
    live_port
        Also host a gRPC server on ``127.0.0.1:live_port`` for a viewer
        (``rerun rerun+http://127.0.0.1:PORT/proxy``); off (None) by default.
    recording_id
        Rerun recording id (default: a fresh one).
    batch_rows
        Scalars are sent in columns of up to this many rows (per entity) for speed.
    flush_interval_s
        With a live viewer, pending scalars are sent at least this often [s].
    units
        Display units of the scalars, labels and entity names (default:
        :func:`tdmon.display.current`, i.e. what the running command set, else SI).
    """

    def __init__(
        self,
        rrd_path: str | Path | None = None,
        *,
        live_port: int | None = None,
        recording_id: str | None = None,
        batch_rows: int = 5000,
        flush_interval_s: float = 0.5,
        units: UnitSystem | None = None,
    ) -> None:
        if rrd_path is None and live_port is None:
            raise RecordError("Rerun views need an .rrd path, a live port, or both")
        import rerun as rr  # lazily: ~0.45 s

        self._rr = rr
        self.units = units if units is not None else current()
        self.names = _Names.of(self.units)
        self.rrd_path = Path(rrd_path) if rrd_path is not None else None
        self.live_port = live_port
        self.batch_rows = batch_rows
        self.flush_interval_s = flush_interval_s
        self.stats = ViewStats()
        self._series: dict[str, _Series] = {}
        self._styled: set[str] = set()
        self._pending_rows = 0
        self._last_send = time.monotonic()
        self._bit_depth_cm: int | None = None
        self._depth_index: int | None = None  # on the "against bit depth" timeline
        self._string_cm: int | None = None
        self._well: dict[str, NDArray[np.float64]] | None = None
        self._last_state: str | None = None
        self._closed = False
        self.grpc_uri: str | None = None

        self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        # Data times come from the messages; the wall-clock "log_time"/"log_tick" timelines
        # would only clutter the time panel.
        self._rec.set_log_time_enabled(False)
        self._rec.set_log_tick_enabled(False)
        sinks: list[Any] = []
        if self.rrd_path is not None:
            try:
                self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
                self.rrd_path.touch()
            except OSError as exc:
                raise RecordError(f"cannot write {self.rrd_path}: {exc.strerror or exc}") from exc
            sinks.append(rr.FileSink(str(self.rrd_path)))
        # No `rerun analytics disable` here: that changes the user's own Rerun settings, and
        # this process only serves data (it starts no viewer, whose analytics the user decides)
        try:
            if live_port is not None:
                # Never rerun's default 0.0.0.0: a rig network is not a place for an open port.
                server = rr.GrpcServerSink(bind_ip="127.0.0.1", port=live_port)
                self.grpc_uri = server.uri
                sinks.append(server)
            self._rec.set_sinks(*sinks, default_blueprint=blueprint(self.units))
        except Exception as exc:  # the bindings raise plain RuntimeError/ValueError
            raise RecordError(f"cannot start the Rerun sinks: {exc}") from exc

    # -- the sink protocol ---------------------------------------------------------------

    def write(self, topic: str, log_time_ns: int, message: Message) -> None:
        """Turn one daemon message into Rerun data; a bad message is logged, never raised."""
        if self._closed:
            return
        self.stats.messages += 1
        handler = self._handlers.get(topic.removeprefix("/tdmon/")
                                     if topic.startswith("/tdmon/") else "")
        if handler is None:
            self.stats.skipped += 1
            return
        t_ns = _time_ns(message, log_time_ns)
        try:
            handler(self, t_ns, message)
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            # A malformed message must not stop the daemon; the MCAP recording still has it.
            self.stats.skipped += 1
            log.warning("Rerun view skipped a %s message: %s", topic, exc)
        if self.live_port is not None and (
            time.monotonic() - self._last_send >= self.flush_interval_s
        ):
            self._send_scalars()

    def close(self) -> None:
        """Send what is pending and close the file sink; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self._send_scalars()
        self._rec.flush()
        self._rec.disconnect()

    def __enter__(self) -> RerunViews:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- scalars, batched ------------------------------------------------------------------

    def _scalar(self, entity: str, timeline: str, index: int, value: float | None) -> None:
        if value is None:
            return
        series = self._series.get(entity)
        if series is None:
            series = self._series[entity] = _Series(timeline)
        series.index.append(index)
        series.values.append(value)
        self._pending_rows += 1
        if len(series.values) >= self.batch_rows:
            self._send_series(entity, series)

    def _both(self, entity: str, t_ns: int, value: float | None) -> None:
        """One scalar against time and, when the bit depth is known, against bit depth."""
        self._scalar(entity, TIME, t_ns, value)
        if self._depth_index is not None:
            self._scalar(f"vs_depth/{entity}", self.names.depth_timeline, self._depth_index,
                         value)

    def _set_bit_depth(self, bit_depth: float) -> None:
        self._bit_depth_cm = round(bit_depth * 100)
        self._depth_index = self.names.depth_index(bit_depth)

    def _force(self, value: Any) -> float | None:
        finite = _finite(value)
        return None if finite is None else self.units.force(finite)

    def _torque(self, value: Any) -> float | None:
        finite = _finite(value)
        return None if finite is None else self.units.torque(finite)

    def _shown(self, parameter: EstimatedParameter, value: Any) -> float | None:
        """An estimated parameter's value as it is shown: as it is, in percent, or a force
        in the display unit."""
        finite = _finite(value)
        if finite is None or parameter.shown == "factor":
            return finite
        return 100.0 * finite if parameter.shown == "percent" else self.units.force(finite)

    def _send_series(self, entity: str, series: _Series) -> None:
        rr = self._rr
        if not series.values:
            return
        if series.timeline == TIME:
            index = rr.TimeColumn(TIME, timestamp=np.asarray(series.index, dtype="datetime64[ns]"))
        else:
            index = rr.TimeColumn(series.timeline, sequence=np.asarray(series.index, np.int64))
        self._style(entity)
        self._rec.send_columns(
            entity,
            indexes=[index],
            columns=rr.Scalars.columns(scalars=np.asarray(series.values, np.float64)),
        )
        self.stats.scalar_rows += len(series.values)
        self.stats.entities.add(entity)
        self._pending_rows -= len(series.values)
        series.index.clear()
        series.values.clear()

    def _send_scalars(self) -> None:
        for entity, series in self._series.items():
            self._send_series(entity, series)
        self._last_send = time.monotonic()

    def _style(self, entity: str) -> None:
        if entity in self._styled:
            return
        self._styled.add(entity)
        rr = self._rr
        name = entity.rsplit("/", 1)[-1]
        if entity.startswith("samples/"):
            name = f"{name} [{self._sample_unit(name)[0]}]"
        if entity.startswith("vs_depth/") and entity.endswith("/measured"):
            # Measurements against depth are a scatter (pick-up and slack-off overlap).
            style: Any = rr.SeriesPoints(names=name, marker_sizes=1.5)
        elif "/band/" in entity:
            style = rr.SeriesLines(names=name, widths=1.0, colors=[150, 150, 150])
        else:
            style = rr.SeriesLines(names=name, widths=1.5)
        self._rec.log(entity, style, static=True)

    # -- other archetypes ----------------------------------------------------------------

    def _log_at(self, t_ns: int, entity: str, archetype: Any) -> None:
        self._rec.reset_time()
        self._rec.set_time(TIME, timestamp=np.datetime64(t_ns, "ns"))
        self._rec.log(entity, archetype)
        self.stats.logged += 1
        self.stats.entities.add(entity)

    def _log_static(self, entity: str, archetype: Any) -> None:
        self._rec.log(entity, archetype, static=True)
        self.stats.logged += 1
        self.stats.entities.add(entity)

    # -- handlers, one per topic ------------------------------------------------------------

    def _on_model(self, t_ns: int, message: Message) -> None:
        bit_depth = _finite(message.get("bit_depth_m"))
        if bit_depth is not None:
            self._set_bit_depth(bit_depth)
        hookload, torque = self.names.hookload, self.names.torque
        measured = message.get("measured") or {}
        self._both(f"{hookload}/measured", t_ns, self._force(measured.get("hookload_N")))
        self._both(f"{torque}/measured", t_ns, self._torque(measured.get("torque_Nm")))
        for operation, value in (message.get("hookload_N") or {}).items():
            self._both(f"{hookload}/model/{operation}", t_ns, self._force(value))
        for operation, value in (message.get("torque_Nm") or {}).items():
            self._both(f"{torque}/model/{operation}", t_ns, self._torque(value))
        band = message.get("band") or {}
        for column, label in (("pick_up_N", Operation.PICK_UP),
                              ("slack_off_N", Operation.SLACK_OFF)):
            for mu, value in zip(band.get("mu", []), band.get(column, []), strict=False):
                self._both(f"{hookload}/band/{label}_{_mu_key(mu)}", t_ns, self._force(value))
        residual = message.get("residual") or {}
        self._scalar(f"residual/{hookload}", TIME, t_ns, self._force(residual.get("hookload_N")))
        self._scalar(f"residual/{torque}", TIME, t_ns, self._torque(residual.get("torque_Nm")))
        drilling = message.get("drilling")
        if drilling:
            self._on_drilling(t_ns, drilling)
        self._update_string(t_ns)

    def _on_drilling(self, t_ns: int, drilling: Message) -> None:
        """A drilling frame's weights on bit and bit torque (docs/drilling.md), against time
        and bit depth: the drilling page."""
        wob = self.names.drilling_wob
        for key, name in (("wob_surface_N", "surface"), ("wob_estimated_N", "estimated"),
                          ("wob_downhole_N", "downhole")):
            self._both(f"{wob}/{name}", t_ns, self._force(drilling.get(key)))
        estimated, std = _finite(drilling.get("wob_estimated_N")), _finite(
            drilling.get("wob_estimated_std_N"))
        if estimated is not None and std is not None:
            self._both(f"{wob}/estimated_low", t_ns, self._force(estimated - std))
            self._both(f"{wob}/estimated_high", t_ns, self._force(estimated + std))
        self._both(f"{self.names.drilling_bit_torque}", t_ns,
                   self._torque(drilling.get("bit_torque_Nm")))

    def _on_state(self, t_ns: int, message: Message) -> None:
        bit_depth = _finite(message.get("bit_depth_m"))
        if bit_depth is not None:
            self._set_bit_depth(bit_depth)
            self._scalar(self.names.bit_depth, TIME, t_ns, self.units.depth(bit_depth))
        state = str(message["state"])
        if state != self._last_state:
            self._last_state = state
            self._log_at(t_ns, "rig_state", self._rr.StateChange(state=state))
        self._update_string(t_ns)

    def _on_estimate(self, t_ns: int, message: Message) -> None:
        kind = message["kind"]
        if kind == EstimateKind.WINDOW:
            operation = str(message.get("operation", "unknown"))
            depth = _finite(message.get("bit_depth_m"))
            mu = _finite(message.get("mu"))
            self._scalar(f"friction/{operation}", TIME, t_ns, mu)
            index = self.names.depth_index(depth) if depth is not None else self._depth_index
            if index is not None:
                self._scalar(f"vs_depth/friction/{operation}", self.names.depth_timeline, index,
                             mu)
        elif kind == EstimateKind.PROFILE and "md_m" in message and "mu_profile" in message:
            self._friction_profile(t_ns, message["md_m"], message["mu_profile"],
                                   message.get("informed"), message.get("uninformed_reason"))
        elif kind == EstimateKind.MU_T:
            for name, value in (message.get("params") or {}).items():
                self._scalar(f"friction_mu_T/{name}", TIME, t_ns, _finite(value))
        elif kind == EstimateKind.JOINT:
            # friction with the parameters estimated beside it (docs/back-calculation.md),
            # each as its declaration shows it (tdmon.calib.parameters)
            for parameter in JOINT_PARAMETERS:
                self._scalar(joint_entity(parameter, self.units), TIME, t_ns,
                             self._shown(parameter, message.get(parameter.name)))

    def _on_profile(self, t_ns: int, message: Message) -> None:
        md = message["md_m"]
        if "temperature_C" in message:
            self._log_at(t_ns, self.names.temperature_profile, self._rr.BarChart(
                self.units.temperature(np.asarray(message["temperature_C"], np.float64)),
                abscissa=self.units.depth(np.asarray(md, np.float64))))
        if "mu" in message:
            self._friction_profile(t_ns, md, message["mu"], message.get("informed"),
                                   message.get("uninformed_reason"))

    def _friction_profile(self, t_ns: int, md: Sequence[float], mu: Sequence[Any],
                          informed: Sequence[bool] | None = None,
                          reasons: Sequence[str | None] | None = None) -> None:
        md_array = np.asarray(md, np.float64)
        mu_array = np.asarray([np.nan if v is None else v for v in mu], np.float64)
        if informed is not None and len(informed) == len(mu_array):
            # an uninformed bin shows the prior, not the rig: left out of the bars, grey in
            # 3D, and the note says why
            from tdmon.calib.profile import describe_information

            mu_array[~np.asarray(informed, dtype=bool)] = np.nan
            self._log_at(t_ns, "profile/note", self._rr.TextDocument(
                "Local friction: " + describe_information(md, informed, reasons)))
        self._log_at(t_ns, "profile/friction", self._rr.BarChart(
            np.nan_to_num(mu_array), abscissa=self.units.depth(md_array)))
        if self._well is None or len(md_array) < 2:
            return
        points = self._positions(md_array)
        colours = [_colour(v) if math.isfinite(v) else (128, 128, 128) for v in mu_array[:-1]]
        segments = [points[i : i + 2] for i in range(len(points) - 1)]
        self._log_at(t_ns, "well/friction", self._rr.LineStrips3D(
            segments, colors=colours, radii=6.0))

    def _on_well(self, t_ns: int, message: Message) -> None:
        well = {key: np.asarray(message[key], np.float64)
                for key in ("md_m", "tvd_m", "north_m", "east_m")}
        self._well = well
        path = np.column_stack([well["east_m"], well["north_m"], -well["tvd_m"]])
        self._log_static("well", self._rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        self._log_static("well/trajectory", self._rr.LineStrips3D(
            [path], colors=[[200, 200, 200]], radii=2.0, labels=[message.get("name", "well")]))
        self._string_cm = None
        self._update_string(t_ns)

    def _on_alarm(self, t_ns: int, message: Message) -> None:
        level = _SEVERITY_LEVEL.get(str(message.get("severity")), "INFO")
        self._log_at(t_ns, "alarms", self._rr.TextLog(
            f"[{message['kind']}] {message['message']}", level=level))

    def _on_rejected(self, t_ns: int, message: Message) -> None:
        self._log_at(t_ns, "rejected", self._rr.TextLog(
            f"{message['topic']}: {message['reason']}", level="WARN"))

    def _on_sample(self, t_ns: int, message: Message) -> None:
        channel = str(message["channel"])
        value = _finite(message["value"])
        if value is not None:
            value = self._sample_unit(channel)[1](value)
        self._scalar(f"samples/{channel}", TIME, t_ns, value)

    def _sample_unit(self, channel: str) -> tuple[str, Any]:
        """(label, conversion) of a channel's samples: SI as decoded with ``si``, else the
        display unit of its kind of quantity."""
        internal, label = CHANNEL_UNITS.get(channel, ("", "SI"))
        quantity = self.units.quantity_of(internal)
        if self.units.name == "si" or quantity is None:
            return label, _same
        unit = self.units.unit(quantity)
        return unit.label, unit

    def _on_status(self, t_ns: int, message: Message) -> None:
        for key in ("samples_in", "rejected", "dropped", "lag_s"):
            self._scalar(f"status/{key}", TIME, t_ns, _finite(message.get(key)))

    #: the handler of each topic's messages (``/tdmon/<name>``)
    _handlers: ClassVar[dict[str, Callable[[RerunViews, int, Message], None]]] = {
        "model": _on_model, "state": _on_state, "estimate": _on_estimate,
        "profile": _on_profile, "well": _on_well, "alarm": _on_alarm,
        "rejected": _on_rejected, "sample": _on_sample, "status": _on_status,
    }

    def _positions(self, md: NDArray[np.float64]) -> NDArray[np.float64]:
        assert self._well is not None
        well = self._well
        return np.column_stack([
            np.interp(md, well["md_m"], well["east_m"]),
            np.interp(md, well["md_m"], well["north_m"]),
            -np.interp(md, well["md_m"], well["tvd_m"]),
        ])

    def _update_string(self, t_ns: int) -> None:
        cm = self._bit_depth_cm
        if self._well is None or cm is None:
            return
        if self._string_cm is not None and abs(cm - self._string_cm) < _STRING_STEP_CM:
            return
        self._string_cm = cm
        bit_md = cm / 100.0
        md = self._well["md_m"]
        stations = np.concatenate([md[md < bit_md], [bit_md]])
        points = self._positions(stations)
        self._log_at(t_ns, "well/string", self._rr.LineStrips3D(
            [points], colors=[[255, 200, 0]], radii=4.0))
        self._log_at(t_ns, "well/bit", self._rr.Points3D(
            points[-1:], colors=[[255, 80, 0]], radii=15.0,
            labels=[f"bit {self.units.depth(bit_md):.1f} {self.units.label('depth')}"]))


def _same(value: float) -> float:
    return value


def joint_entity(parameter: EstimatedParameter, units: UnitSystem) -> str:
    """The entity of a joint estimate's parameter: ``friction/joint`` for the friction (beside
    the window frictions), else the parameter's name with its shown unit (``weight_factor``,
    ``<name>_percent``, ``<name>_kN``)."""
    if parameter.name == JOINT_PARAMETERS.friction.name:
        return "friction/joint"
    suffix = {"factor": "", "percent": "_percent", "force": f"_{units.key('force')}"}
    return parameter.name + suffix[parameter.shown]


@dataclass(frozen=True)
class _Names:
    """Entity and timeline names carrying the display unit (``hookload_kN``/``_klbf``)."""

    hookload: str
    torque: str
    bit_depth: str
    temperature_profile: str
    depth_timeline: str
    depth_steps_per_m: float
    drilling_wob: str = "drilling/wob_kN"
    drilling_bit_torque: str = "drilling/bit_torque_kNm"

    @classmethod
    def of(cls, units: UnitSystem) -> _Names:
        timeline, steps = _DEPTH_TIMELINES[units.name]
        return cls(hookload=f"hookload_{units.key('force')}",
                   torque=f"torque_{units.key('torque')}",
                   bit_depth=f"bit_depth_{units.key('depth')}",
                   temperature_profile=f"profile/temperature_{units.key('temperature')}",
                   depth_timeline=timeline, depth_steps_per_m=steps,
                   drilling_wob=f"drilling/wob_{units.key('force')}",
                   drilling_bit_torque=f"drilling/bit_torque_{units.key('torque')}")

    def depth_index(self, bit_depth_m: float) -> int:
        """The bit depth [m] as a step of the "against bit depth" timeline."""
        return round(bit_depth_m * self.depth_steps_per_m)


def _time_ns(message: Message, log_time_ns: int) -> int:
    t = message.get("t", message.get("receive_time"))
    if isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t):
        return round(t * 1e9)
    return int(log_time_ns)


def blueprint(units: UnitSystem | None = None) -> Any:
    """The default layout: tabs against time, against bit depth, the well, and the inputs."""
    import rerun.blueprint as rrb

    units = units if units is not None else current()
    names = _Names.of(units)
    force, torque = units.label("force"), units.label("torque")
    depth, degrees = units.label("depth"), units.label("temperature")
    against_time = rrb.Vertical(
        rrb.Horizontal(
            rrb.TimeSeriesView(origin=f"/{names.hookload}", name=f"Hook load [{force}]"),
            rrb.TimeSeriesView(origin=f"/{names.torque}", name=f"Torque [{torque}]"),
        ),
        rrb.Horizontal(
            rrb.TimeSeriesView(origin="/friction", name="Friction factor per operation"),
            # every parameter estimated beside the friction (tdmon.calib.parameters)
            *(rrb.TimeSeriesView(origin=f"/{joint_entity(p, units)}",
                                 name=f"{p.label.capitalize()} [{p.display_unit(force)}] "
                                      f"(joint estimate; {p.words})")
              for p in JOINT_PARAMETERS.others),
            rrb.TimeSeriesView(origin="/residual", name=f"Residuals [{force}, {torque}]"),
        ),
        rrb.Horizontal(
            rrb.StateTimelineView(origin="/rig_state", name="Rig state"),
            rrb.TimeSeriesView(origin=f"/{names.bit_depth}", name=f"Bit depth [{depth}]"),
            rrb.TimeSeriesView(origin="/friction_mu_T",
                               name="mu(T) law's coefficients (live calibration)"),
        ),
        rrb.TextLogView(origin="/alarms", name="Alarms"),
        name="Against time",
        row_shares=[3, 2, 1, 1],
    )
    against_depth = rrb.Vertical(
        rrb.TimeSeriesView(origin=f"/vs_depth/{names.hookload}",
                           name=f"Hook load vs bit depth [{force}]"),
        rrb.Horizontal(
            rrb.TimeSeriesView(origin=f"/vs_depth/{names.torque}",
                               name=f"Torque vs bit depth [{torque}]"),
            rrb.TimeSeriesView(origin="/vs_depth/friction", name="Friction vs bit depth"),
        ),
        name=f"Against bit depth (select timeline {names.depth_timeline})",
    )
    well = rrb.Horizontal(
        rrb.Spatial3DView(origin="/well", name="Trajectory, string, local friction"),
        rrb.Vertical(
            rrb.BarChartView(origin="/profile/friction",
                             name=f"Local friction vs MD [{depth}] (informed bins)"),
            rrb.TextDocumentView(origin="/profile/note", name="What the profile knows"),
            rrb.BarChartView(origin=f"/{names.temperature_profile}",
                             name=f"Temperature [{degrees}] vs MD [{depth}]"),
        ),
        name="Well",
        column_shares=[3, 2],
    )
    drilling = rrb.Vertical(
        rrb.TimeSeriesView(origin=f"/vs_depth/{names.drilling_wob}",
                           name=f"Weight on bit vs bit depth [{force}]: surface, from the hook "
                                "load (+/- 1 sd), downhole (MWD)"),
        rrb.Horizontal(
            rrb.TimeSeriesView(origin=f"/vs_depth/{names.torque}",
                               name=f"Torque vs bit depth [{torque}]: measured, model/drilling"),
            rrb.TimeSeriesView(origin="/vs_depth/friction",
                               name="Friction vs bit depth (drilling: from the drilling torque)"),
        ),
        rrb.TimeSeriesView(origin=f"/{names.drilling_wob}",
                           name=f"Weight on bit [{force}] against time"),
        name=f"Drilling (select timeline {names.depth_timeline})",
        row_shares=[3, 2, 2],
    )
    samples = "SI" if units.name == "si" else "field units"
    inputs = rrb.Vertical(
        rrb.TimeSeriesView(origin="/samples", name=f"Decoded samples ({samples})"),
        rrb.TimeSeriesView(origin="/status", name="Daemon status"),
        rrb.TextLogView(origin="/rejected", name="Rejected input"),
        name="Inputs",
    )
    return rrb.Blueprint(
        rrb.Tabs(against_time, against_depth, drilling, well, inputs),
        rrb.TimePanel(timeline=TIME),
        collapse_panels=False,
    )


def build_rrd(
    messages: Iterable[tuple[str, int, Mapping[str, Any]]],
    rrd_path: str | Path,
    *,
    recording_id: str | None = None,
    units: UnitSystem | None = None,
) -> ViewStats:
    """Write the views of a message stream (e.g. ``reader.read_messages(path)``) to ``.rrd``."""
    with RerunViews(rrd_path, recording_id=recording_id, units=units) as views:
        for topic, log_time_ns, message in messages:
            views.write(topic, log_time_ns, message)
    return views.stats
