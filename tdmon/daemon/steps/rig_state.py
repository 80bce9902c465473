"""The rig-state step: `tdmon.calib.rigstate`'s detector on every frame.

Sets ``frame.state`` and ``frame.steady`` for the steps after it and emits ``state`` on a
change, or once per ``every`` seconds. It is the daemon's only rig-state detector: with the
calibration on, its thresholds come from the well's block weight and ``[calibration]``
(:func:`calibration_thresholds`); without, from ``[rig_state]`` alone
(:func:`rig_state_thresholds`, which maps the plain threshold settings onto the detector).

Frame fields read: ``values["hookload"]`` [N], ``values["bit_depth"]`` [m], and when present
``values["block_position"]`` [m], ``values["rpm"]`` [rad/s], ``values["flow_in"]`` [m3/s],
``values["spp"]`` [Pa], ``values["hole_depth"]`` [m], ``values["torque"]`` [N m],
``values["wob"]`` [N]; ``frame.ages`` (when each channel was sampled: velocities use the
channel's own times).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from tdmon.calib.rigstate import (
    Detection,
    DetectorState,
    RigSample,
    RigStateThresholds,
    detect,
)
from tdmon.daemon.pipeline import Emit, Frame

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig, RigStateConfig

__all__ = ["RigStateStep", "calibration_thresholds", "rig_sample", "rig_state_thresholds"]


def _sampled_at(frame: Frame, channel: str) -> float | None:
    age = frame.ages.get(channel)
    return frame.t - age if age is not None and math.isfinite(age) else None


#: Frame channels of a RigSample, in the order of its fields after ``t``.
_SAMPLE_CHANNELS = ("hookload", "bit_depth", "block_position", "rpm", "flow_in", "spp",
                    "hole_depth", "torque", "wob")


def rig_sample(frame: Frame) -> RigSample:
    """The detector's sample of one frame (non-finite values are missing)."""
    # once per frame: one comprehension and positional arguments rather than a helper call
    # and a keyword per channel
    hookload, bit_depth, block_position, rpm, flow, spp, hole_depth, torque, wob = [
        float(x) if x is not None and math.isfinite(x) else None
        for x in map(frame.values.get, _SAMPLE_CHANNELS)]
    return RigSample(frame.t, hookload, bit_depth, block_position, rpm, flow, spp, hole_depth,
                     torque, wob, _sampled_at(frame, "block_position"),
                     _sampled_at(frame, "bit_depth"))


class RigStateStep:
    """Step: rig state and steadiness of every frame; ``state`` on a change or every ``every`` s.

    The last sample and detection stay readable (``last_sample``, ``last_detection``) for the
    calibration step, which runs after it on the same frame and may replace ``thresholds``
    (the block weight it learns in slips).
    """

    name = "rig_state"

    def __init__(self, thresholds: RigStateThresholds | None = None, every: float = 1.0) -> None:
        self.thresholds = thresholds or RigStateThresholds()
        self.every = every
        self.detector = DetectorState()
        self.last_sample: RigSample | None = None
        self.last_detection: Detection | None = None
        self._last_sent: tuple[str, bool] | None = None
        self._last_sent_t = -math.inf

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        sample = rig_sample(frame)
        self.detector, detection = detect(self.detector, sample, self.thresholds)
        self.last_sample, self.last_detection = sample, detection
        frame.state, frame.steady = detection.state, detection.steady
        key = (detection.state, detection.steady)
        if key != self._last_sent or frame.t - self._last_sent_t >= self.every:
            self._last_sent, self._last_sent_t = key, frame.t
            emit("state", {"t": frame.t, "state": detection.state,
                           "steady": bool(detection.steady), "bit_depth_m": sample.bit_depth})

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""


def calibration_thresholds(config: DaemonConfig, block_weight: float) -> RigStateThresholds:
    """Thresholds with the calibration on: in slips up to the well's block weight [N] plus
    ``[calibration] in_slips_margin``; the detector's own settling and glitch checks."""
    rs = config.rig_state
    return RigStateThresholds(
        block_weight=block_weight, in_slips_margin=config.calibration.in_slips_margin,
        moving_speed=rs.moving_speed, rotating_speed=rs.rotating_rpm,
        circulating_flow=rs.circulating_flow, on_bottom=rs.on_bottom)


def rig_state_thresholds(rs: RigStateConfig) -> RigStateThresholds:
    """Thresholds with the calibration off: ``[rig_state]`` as plain thresholds.

    ``in_slips_hookload`` is the in-slips margin over a zero block weight; ``steady_frames``
    the samples a state must have lasted (no settling time). The detector's checks that the
    plain thresholds never had are switched off: no glitch speed, gap, acceleration,
    hook-load step or settled-hang limit, no standpipe pressure standing in for flow, and
    weight on bit does not widen "on bottom". What stays different is listed in
    docs/daemon.md (``[rig_state]``).
    """
    return RigStateThresholds(
        block_weight=0.0, in_slips_margin=rs.in_slips_hookload, moving_speed=rs.moving_speed,
        rotating_speed=rs.rotating_rpm, circulating_flow=rs.circulating_flow,
        circulating_pressure=math.inf, on_bottom=rs.on_bottom, settle_time=0.0,
        settle_samples=rs.steady_frames, max_acceleration=math.inf,
        max_hookload_step=math.inf, hang_tolerance=math.inf, max_gap=math.inf,
        max_speed=math.inf,
        velocity_disagreement=math.inf, drilling_wob=-math.inf,
        on_bottom_with_wob=rs.on_bottom)
