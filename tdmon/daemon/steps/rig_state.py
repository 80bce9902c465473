"""The rig-state step: `tdmon.calib.rigstate`'s detector on every frame.

Sets ``frame.state`` and ``frame.steady`` for the steps after it and emits ``state`` on a
change, or once per ``every`` seconds. It is the daemon's only rig-state detector: with the
calibration on, its thresholds come from the well's block weight and ``[calibration]``
(:func:`calibration_thresholds`); without, from ``[rig_state]`` alone
(:func:`rig_state_thresholds`, which maps the plain threshold settings onto the detector).

With the well model (the calibration on), each sample carries the modelled buoyed weight of
the string hanging at its bit depth (:class:`StringWeight`), so that the in-slips margin scales
with it (`tdmon.calib.rigstate.in_slips_limit`): a light string hanging on the hook is not "in
slips".

Frame fields read: ``values["hookload"]`` [N], ``values["bit_depth"]`` [m], and when present
``values["block_position"]`` [m], ``values["rpm"]`` [rad/s], ``values["flow_in"]`` [m3/s],
``values["spp"]`` [Pa], ``values["hole_depth"]`` [m], ``values["torque"]`` [N m],
``values["wob"]`` [N]; ``frame.ages`` (when each channel was sampled: velocities, the torque
level and the frozen-channel check use the channel's own times).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import replace
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
    from tdmon.model.torque_drag import WellModel

__all__ = ["RigStateStep", "StringWeight", "calibration_thresholds", "rig_sample",
           "rig_state_thresholds"]

#: bit-depth spacing of the string-weight table [m]: the weight is nearly linear in depth
#: between survey stations, and the in-slips margin needs it to a few per cent
STRING_WEIGHT_STEP = 30.0


class StringWeight:
    """The modelled buoyed weight of the string hanging at a bit depth [N]: the static hook
    load with no friction less the block weight (as `tdmon.calib.mismatch.weight_difference`
    reads it), tabulated every :data:`STRING_WEIGHT_STEP` down to the deepest bit depth the
    model takes, linear in between; beyond the table its last value.

    Parameters
    ----------
    model : the prepared well
    """

    def __init__(self, model: WellModel) -> None:
        from tdmon.errors import ModelError
        from tdmon.vocabulary import Operation

        bottom = min(float(model.node_md[-1]), float(model.well.string.length))
        top = float(model.node_md[0])
        count = max(math.ceil((bottom - top) / STRING_WEIGHT_STEP), 1)
        depths: list[float] = []
        weights: list[float] = []
        for k in range(1, count + 1):
            depth = top + (bottom - top) * k / count
            try:
                hook = model.evaluate(Operation.STATIC, depth, 0.0)[0]
            except ModelError:
                continue
            depths.append(depth)
            weights.append(hook - model.well.block_weight)
        self.depths, self.weights = depths, weights

    def __call__(self, bit_depth: float | None) -> float | None:
        """The weight at ``bit_depth`` [m] (None: no bit depth, or no table)."""
        depths, weights = self.depths, self.weights
        if bit_depth is None or not depths or not math.isfinite(bit_depth):
            return None
        k = bisect.bisect_left(depths, bit_depth)
        if k == 0:
            # above the first node: the string's weight falls to zero at surface
            return weights[0] * max(bit_depth, 0.0) / depths[0] if depths[0] > 0 else weights[0]
        if k == len(depths):
            return weights[-1]
        d0, d1 = depths[k - 1], depths[k]
        return weights[k - 1] + (weights[k] - weights[k - 1]) * (bit_depth - d0) / (d1 - d0)


def _sampled_at(frame: Frame, channel: str) -> float | None:
    age = frame.ages.get(channel)
    return frame.t - age if age is not None and math.isfinite(age) else None


#: Frame channels of a RigSample, in the order of its fields after ``t`` (the MWD's two come
#: last, after ``ages``).
_SAMPLE_CHANNELS = ("hookload", "bit_depth", "block_position", "rpm", "flow_in", "spp",
                    "hole_depth", "torque", "wob", "downhole_wob", "downhole_torque")


def rig_sample(frame: Frame, string_weight: StringWeight | None = None) -> RigSample:
    """The detector's sample of one frame (non-finite values are missing), with the string's
    modelled weight at its bit depth when ``string_weight`` is given."""
    # once per frame: one comprehension and positional arguments rather than a helper call
    # and a keyword per channel
    (hookload, bit_depth, block_position, rpm, flow, spp, hole_depth, torque, wob,
     downhole_wob, downhole_torque) = [
        float(x) if x is not None and math.isfinite(x) else None
        for x in map(frame.values.get, _SAMPLE_CHANNELS)]
    weight = string_weight(bit_depth) if string_weight is not None else None
    return RigSample(frame.t, hookload, bit_depth, block_position, rpm, flow, spp, hole_depth,
                     torque, wob, _sampled_at(frame, "block_position"),
                     _sampled_at(frame, "bit_depth"), weight, frame.ages, downhole_wob,
                     downhole_torque)


class RigStateStep:
    """Step: rig state and steadiness of every frame; ``state`` on a change or every ``every`` s.

    The last sample and detection stay readable (``last_sample``, ``last_detection``) for the
    calibration and alarm steps, which run after it on the same frame; the calibration step
    may replace ``thresholds`` (the block weight it learns in slips) and ``string_weight`` (a
    new run's string, :meth:`use_model`).
    """

    name = "rig_state"

    def __init__(self, thresholds: RigStateThresholds | None = None, every: float = 1.0,
                 string_weight: StringWeight | None = None) -> None:
        self.thresholds = thresholds or RigStateThresholds()
        self.every = every
        self.string_weight = string_weight
        self.detector = DetectorState()
        self.last_sample: RigSample | None = None
        self.last_detection: Detection | None = None
        self._last_sent: tuple[str, bool] | None = None
        self._last_sent_t = -math.inf

    def use_model(self, model: WellModel) -> None:
        """Weigh the string of a new well model (a new run's well file, a reload)."""
        self.string_weight = StringWeight(model)

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        sample = rig_sample(frame, self.string_weight)
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


def _with_sensor_checks(thresholds: RigStateThresholds, rs: RigStateConfig
                        ) -> RigStateThresholds:
    """``thresholds`` with ``[rig_state]``'s torque-evidence and frozen-channel settings."""
    from tdmon.calib.frozen import FROZEN_RESOLUTION

    return replace(thresholds, rotating_torque=rs.rotating_torque,
                   torque_average=rs.torque_average, frozen_time=rs.frozen_time,
                   frozen_samples=rs.frozen_samples,
                   frozen_resolution={**FROZEN_RESOLUTION, **rs.frozen_resolution},
                   drilling_ahead_time=rs.drilling_ahead_time)


def calibration_thresholds(config: DaemonConfig, block_weight: float) -> RigStateThresholds:
    """Thresholds with the calibration on: in slips up to the well's block weight [N] plus
    ``[calibration] in_slips_margin``, or less for a light string (``in_slips_fraction`` of
    its modelled weight at the bit depth, at least ``in_slips_min_margin``); the detector's own
    settling and glitch checks."""
    rs, cal = config.rig_state, config.calibration
    return _with_sensor_checks(RigStateThresholds(
        block_weight=block_weight, in_slips_margin=cal.in_slips_margin,
        in_slips_fraction=cal.in_slips_fraction, in_slips_min_margin=cal.in_slips_min_margin,
        moving_speed=rs.moving_speed, rotating_speed=rs.rotating_rpm,
        circulating_flow=rs.circulating_flow, on_bottom=rs.on_bottom), rs)


def rig_state_thresholds(rs: RigStateConfig) -> RigStateThresholds:
    """Thresholds with the calibration off: ``[rig_state]`` as plain thresholds.

    ``in_slips_hookload`` is the in-slips margin over a zero block weight; ``steady_frames``
    the samples a state must have lasted (no settling time). The detector's checks that the
    plain thresholds never had are switched off: no glitch speed, gap, acceleration,
    hook-load step or settled-hang limit, no standpipe pressure standing in for flow, and
    weight on bit does not widen "on bottom". What stays different is listed in
    docs/daemon.md (``[rig_state]``). Rotation needs the torque's evidence and frozen channels
    are judged as with the calibration on (``[rig_state]``'s ``rotating_torque``,
    ``torque_average`` and ``frozen_*``); without a well model the in-slips margin is fixed.
    """
    return _with_sensor_checks(RigStateThresholds(
        block_weight=0.0, in_slips_margin=rs.in_slips_hookload, moving_speed=rs.moving_speed,
        rotating_speed=rs.rotating_rpm, circulating_flow=rs.circulating_flow,
        circulating_pressure=math.inf, on_bottom=rs.on_bottom, settle_time=0.0,
        settle_samples=rs.steady_frames, max_acceleration=math.inf,
        max_hookload_step=math.inf, hang_tolerance=math.inf, max_gap=math.inf,
        max_speed=math.inf,
        velocity_disagreement=math.inf, drilling_wob=-math.inf,
        on_bottom_with_wob=rs.on_bottom), rs)
