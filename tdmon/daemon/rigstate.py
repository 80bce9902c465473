"""A simple rig-state step: thresholds on hook load, bit-depth velocity, rotation and flow.

Deliberately plain (a later issue replaces it with a proper detector): the step only has to
set ``frame.state``/``frame.steady`` so the monitor knows which modelled curve applies.
"""

from __future__ import annotations

from dataclasses import dataclass

from tdmon.daemon.pipeline import Emit, Frame

STATES = ("in_slips", "pick_up", "slack_off", "rotating_off_bottom", "reaming", "back_reaming",
          "drilling", "circulating", "static", "unknown")


@dataclass(frozen=True, slots=True)
class RigStateThresholds:
    """Thresholds in SI: [N], [m/s], [rad/s], [m^3/s], [m]."""

    in_slips_hookload: float = 400e3
    moving_speed: float = 0.05
    rotating_rpm: float = 5 * 2 * 3.141592653589793 / 60
    circulating_flow: float = 100 / 60_000
    on_bottom: float = 0.5
    steady_frames: int = 3


def classify(
    hookload: float | None,
    velocity: float | None,
    rpm: float | None,
    flow: float | None,
    off_bottom: float | None,
    limits: RigStateThresholds,
) -> str:
    """Rig state from one frame's values (``velocity`` > 0 means the bit goes deeper)."""
    if hookload is None:
        return "unknown"
    if hookload < limits.in_slips_hookload:
        return "in_slips"
    moving_down = velocity is not None and velocity > limits.moving_speed
    moving_up = velocity is not None and velocity < -limits.moving_speed
    rotating = rpm is not None and rpm > limits.rotating_rpm
    on_bottom = off_bottom is not None and off_bottom <= limits.on_bottom
    if rotating:
        if moving_up:
            return "back_reaming"
        if on_bottom:
            return "drilling"
        return "reaming" if moving_down else "rotating_off_bottom"
    if moving_up:
        return "pick_up"
    if moving_down:
        return "slack_off"
    if flow is not None and flow > limits.circulating_flow:
        return "circulating"
    return "static"


class SimpleRigState:
    """Step: classify every frame; emit ``state`` on a change, or once per ``every`` seconds."""

    name = "rig_state"

    def __init__(self, limits: RigStateThresholds | None = None, every: float = 1.0) -> None:
        self.limits = limits or RigStateThresholds()
        self.every = every
        self._previous: tuple[float, float] | None = None  # (t, bit depth)
        self._state = "unknown"
        self._run = 0
        self._last_sent: tuple[str, bool] | None = None
        self._last_sent_t = float("-inf")

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        values = frame.values
        bit_depth = values.get("bit_depth")
        velocity = None
        if bit_depth is not None:
            if self._previous is not None and frame.t > self._previous[0]:
                velocity = (bit_depth - self._previous[1]) / (frame.t - self._previous[0])
            self._previous = (frame.t, bit_depth)
        hole_depth = values.get("hole_depth")
        off_bottom = None if bit_depth is None or hole_depth is None else hole_depth - bit_depth
        state = classify(values.get("hookload"), velocity, values.get("rpm"),
                         values.get("flow_in"), off_bottom, self.limits)
        self._run = self._run + 1 if state == self._state else 1
        self._state = state
        frame.state = state
        frame.steady = self._run >= self.limits.steady_frames
        key = (frame.state, frame.steady)
        if key != self._last_sent or frame.t - self._last_sent_t >= self.every:
            self._last_sent = key
            self._last_sent_t = frame.t
            emit("state", {"t": frame.t, "state": frame.state, "steady": frame.steady,
                           "bit_depth_m": bit_depth})

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""
