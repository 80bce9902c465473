"""The per-frame alarm step: hook load trending out of the monitor's band, stale, implausible
and frozen sensors (the window-level alarms come from the estimator, `steps.calibrate`).

Frame fields read: ``values`` (``hookload`` [N] and what the sensor checks look at),
``frame.stale``, ``frame.gap``, ``frame.state``/``frame.steady`` (from the rig-state step) and
``frame.results["model"]`` (the monitor's band); the rig-state step's detection of the frame
(the channels it judges frozen, `tdmon.calib.rigstate.Detection.frozen`).
"""

from __future__ import annotations

import math

from tdmon.calib.alarms import (
    BandSettings,
    BandTrendState,
    SensorSettings,
    SensorState,
    sensor_alarms,
    update_band_trend,
)
from tdmon.calib.windows import WindowSettings
from tdmon.daemon.pipeline import Emit, Frame
from tdmon.daemon.steps.rig_state import RigStateStep
from tdmon.vocabulary import RigState

__all__ = ["AlarmStep"]


#: What the band-trend alarm names, per state in which it is checked (the pick-up and
#: slack-off hook loads against their band): made once, not on every steady frame.
_BAND_SUBJECTS: dict[str, str] = {state: f"{state} hook load"
                                  for state in (RigState.PICK_UP, RigState.SLACK_OFF)}


def _value(values: dict[str, float], name: str) -> float | None:
    value = values.get(name)
    return float(value) if value is not None and math.isfinite(value) else None


class AlarmStep:
    """Step: per-frame alarms (band trend from the monitor's ``model`` message, sensors; the
    frozen channels of ``rig_state``'s detection of the same frame)."""

    name = "alarms"

    def __init__(self, band: BandSettings | None = None, sensors: SensorSettings | None = None,
                 windows: WindowSettings | None = None, *,
                 rig_state: RigStateStep | None = None) -> None:
        self.band = band or BandSettings()
        self.sensors = sensors or SensorSettings()
        self.windows = windows or WindowSettings()
        self.rig_state = rig_state
        self.trend: dict[str, BandTrendState] = {}
        self.sensor_state = SensorState()

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        rig_state = frame.state
        detection = self.rig_state.last_detection if self.rig_state is not None else None
        sample = self.rig_state.last_sample if self.rig_state is not None else None
        frozen = (detection.frozen if detection is not None and sample is not None
                  and sample.t == frame.t else ())
        self.sensor_state, alarms = sensor_alarms(
            self.sensor_state, frame.t, frame.values, frame.stale, frozen, self.sensors,
            frame.gap, frame.gap_reported)
        for sensor_alarm in alarms:
            emit("alarm", sensor_alarm.to_message())
        subject = _BAND_SUBJECTS.get(rig_state)
        if not frame.steady or subject is None:
            return
        model = frame.results.get("model")
        hookload = _value(frame.values, "hookload")
        if model is None or hookload is None:
            return
        band = model.get("band", {})
        curve = band.get("pick_up_N" if rig_state == RigState.PICK_UP else "slack_off_N") or []
        values = [float(x) for x in curve if x is not None and math.isfinite(x)]
        if not values:
            return
        noise = max(self.windows.noise_floor, self.windows.noise_floor_fraction * hookload)
        state = self.trend.get(rig_state)
        if state is None:
            state = BandTrendState()
        state, alarm = update_band_trend(state, frame.t, hookload, min(values), max(values),
                                         noise, self.band, what=subject)
        self.trend[rig_state] = state
        if alarm is not None:
            emit("alarm", alarm.to_message())

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""
