"""The hook-load measurement in the estimates: what the rig's sensor reads of the modelled load,
and the load a reading stands for (docs/hookload.md).

The model gives the load on the hook; the rig's hook-load channel reads

    reading = f(motion, e) (B + F) + o

with ``F`` the string's top force, ``B`` the travelling equipment as the sensor weighs it, ``o``
the sensor's zero offset and ``f`` the sensor's factor for the block's motion (a deadline
sensor's sheave factor at efficiency ``e``, :mod:`tdmon.model.hookload_sensor`; 1 for a load pin
or a load cell, and for any sensor with the block still). The joint estimate learns ``B``,
``o`` and ``e`` with the friction and the weight factor (:mod:`tdmon.calib.joint`); the
per-window friction, the profile and mu(T) read each window through their current values
(:func:`corrected_window`), so that friction is what is left after every known force.

Whether a window can resolve friction at all is a comparison (:func:`resolution`): the change
of its load between two friction factors (0.1 and 0.3) against the sensor's uncertainty there
(the window's noise, an unmodelled hysteresis between hoisting and lowering, and what is not
known of the offset, the block weight and the sheave efficiency). In a near-vertical or shallow
hole the drag friction causes is often smaller than that, and no friction is published.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Final

from tdmon.calib.windows import Window
from tdmon.errors import ModelError
from tdmon.model.hookload_sensor import HookloadSensor
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import OPERATION_FOR_STATE, Operation, RigState

__all__ = [
    "MOTION_OF_STATE",
    "RESOLUTION_FRICTION",
    "Resolution",
    "SensorEstimate",
    "corrected_window",
    "factor_slope",
    "resolution",
]

MOTION_OF_STATE: Final[dict[str, int]] = {
    RigState.PICK_UP: 1, RigState.BACK_REAMING: 1,
    RigState.SLACK_OFF: -1, RigState.REAMING: -1, RigState.DRILLING: -1,
}
"""The travelling block's motion in each rig state with the string on the hook: +1 hoisting,
-1 lowering (drilling lowers the block at the rate of penetration); every other state holds the
block still (0)."""

#: The two friction factors whose loads a window must tell apart to resolve friction [-].
RESOLUTION_FRICTION: Final = (0.1, 0.3)

_SLOPE_STEP = 1e-4


def factor_slope(sensor: HookloadSensor, motion: int, efficiency: float) -> float:
    """d f / d e: how the sensor's factor for ``motion`` changes with the sheave efficiency
    [-] (0 for a sensor that reads no sheave friction or a still block; a central difference,
    one sided at e = 1)."""
    if motion == 0 or not sensor.reads_sheave_friction:
        return 0.0
    high = min(efficiency + _SLOPE_STEP, 1.0)
    low = high - 2.0 * _SLOPE_STEP
    return (sensor.factor(motion, high) - sensor.factor(motion, low)) / (high - low)


@dataclass(frozen=True)
class SensorEstimate:
    """What the calibration knows now of the hook-load measurement (SI).

    Attributes
    ----------
    sensor : where the sensor sits and its rigging
    block_weight, block_weight_std : the travelling equipment as the sensor weighs it [N]
    offset, offset_std : the sensor's zero offset [N]
    efficiency, efficiency_std : efficiency per turning sheave [-] (std 0 when not estimated)
    hysteresis : unmodelled difference of readings hoisting and lowering, relative to the
        load [-] (sensor hysteresis, sheave friction beyond the model)
    """

    sensor: HookloadSensor
    block_weight: float
    block_weight_std: float
    offset: float = 0.0
    offset_std: float = 0.0
    efficiency: float = 1.0
    efficiency_std: float = 0.0
    hysteresis: float = 0.0

    @cached_property
    def _factors(self) -> tuple[float, float, float]:
        """The factors lowering, still and hoisting (worked out once: the monitor reads every
        frame's curves through them)."""
        return (self.sensor.factor(-1, self.efficiency), self.sensor.factor(0, self.efficiency),
                self.sensor.factor(1, self.efficiency))

    def factor(self, motion: int) -> float:
        """The sensor's factor for ``motion`` (-1, 0, +1) at the estimated efficiency [-]."""
        return self._factors[motion + 1]

    def reading(self, string_load: float, motion: int) -> float:
        """What the sensor reads [N] of a string top force ``string_load`` [N]."""
        return self.factor(motion) * (self.block_weight + string_load) + self.offset

    def string_load(self, reading: float, motion: int) -> float:
        """The string top force [N] a reading [N] stands for (the inverse of `reading`)."""
        return (reading - self.offset) / self.factor(motion) - self.block_weight

    def uncertainty(self, string_load: float, motion: int, *, paired: bool = False) -> float:
        """The standard deviation of a reading [N] from what is not known of the measurement:
        the offset, the block weight, the sheave efficiency and the hysteresis (``paired``:
        of the difference of a pick-up and a slack-off at the same depth, where the offset and
        a still block's weight cancel)."""
        load = self.block_weight + string_load
        factor = self.factor(motion)
        sheave = factor_slope(self.sensor, motion, self.efficiency) * self.efficiency_std * load
        hysteresis = self.hysteresis * load
        if paired:
            return math.hypot(sheave, hysteresis)
        return math.sqrt(self.offset_std**2 + (factor * self.block_weight_std) ** 2
                         + sheave**2 + hysteresis**2)


def corrected_window(window: Window, estimate: SensorEstimate, model_block_weight: float
                     ) -> Window:
    """``window`` with its hook load as the model's own hook load (its string top force plus
    the model's block weight ``model_block_weight`` [N]), read through the sensor's estimate,
    and the standard error widened by the sensor's uncertainty (`SensorEstimate.uncertainty`),
    so that a friction solved from it carries what is not known of the measurement."""
    motion = MOTION_OF_STATE.get(window.state, 0)
    if not math.isfinite(window.hookload):
        return window
    string = estimate.string_load(window.hookload, motion)
    factor = estimate.factor(motion)
    se = math.hypot(window.hookload_se / factor,
                    estimate.uncertainty(string, motion) / factor)
    return replace(window, hookload=string + model_block_weight, hookload_se=se)


@dataclass(frozen=True)
class Resolution:
    """Whether a window (or the joint estimate at its depth) can resolve friction.

    Attributes
    ----------
    resolvable : the load change between the two friction factors of
        :data:`RESOLUTION_FRICTION` is at least twice the uncertainty
    signal : that change [N, or N m for torque]
    drag : the drag friction causes at the model's friction, as the sensor would read it
        [N or N m] (what a person compares with the uncertainty)
    uncertainty : one standard deviation of the reading (or the pick-up/slack-off split)
        [N or N m]
    statement : the verdict in words
    """

    resolvable: bool
    signal: float
    drag: float
    uncertainty: float
    statement: str


def resolution(model: WellModel, state: str, bit_depth: float, estimate: SensorEstimate, *,
               mu: float, hookload_se: float = 0.0, torque_se: float = 0.0,
               torque_uncertainty: float = 0.0, method: str = "soft-string",
               paired: bool = False) -> Resolution:
    """Can a window of rig state ``state`` at ``bit_depth`` [m] resolve friction?

    Parameters
    ----------
    model : the prepared well
    state : ``pick_up``, ``slack_off`` (the hook load) or ``rotating_off_bottom`` (the torque)
    bit_depth : [m]
    estimate : the measurement as known now
    mu : the friction the drag in the statement is worked out at [-]
    hookload_se, torque_se : the window's standard errors [N, N m]
    torque_uncertainty : the torque sensor's zero and scale uncertainty [N m]
    method : torque-and-drag method
    paired : judge the pick-up/slack-off split (the joint estimate's evidence: the offset and
        a still block's weight cancel in it) rather than one window's load

    Raises
    ------
    ModelError
        The model does not reach the depth, or a state without a friction solve.
    """
    low, high = RESOLUTION_FRICTION
    frictions = (low, high, mu)
    if state == RigState.ROTATING_OFF_BOTTOM:
        torque = [model.evaluate(Operation.ROTATING, bit_depth, m, method=method)[1]
                  for m in frictions]
        signal, drag = abs(torque[1] - torque[0]), abs(torque[2])
        sigma = math.hypot(torque_se, torque_uncertainty)
        what, unit = "torque", "kN m"
    elif state in (RigState.PICK_UP, RigState.SLACK_OFF):
        block = model.well.block_weight
        static = model.evaluate(Operation.STATIC, bit_depth, 0.0, method=method)[0] - block
        what, unit = "drag", "kN"
        if paired:
            split = [model.evaluate(Operation.PICK_UP, bit_depth, m, method=method)[0]
                     - model.evaluate(Operation.SLACK_OFF, bit_depth, m, method=method)[0]
                     for m in frictions]
            signal, drag = abs(split[1] - split[0]), abs(split[2]) / 2.0
            sigma = math.hypot(math.sqrt(2.0) * hookload_se,
                               estimate.uncertainty(static, 1, paired=True)
                               + estimate.uncertainty(static, -1, paired=True))
        else:
            operation = OPERATION_FOR_STATE[RigState(state)]
            motion = MOTION_OF_STATE[state]
            loads = [model.evaluate(operation, bit_depth, m, method=method)[0] - block
                     for m in frictions]
            factor = estimate.factor(motion)
            signal = factor * abs(loads[1] - loads[0])
            drag = factor * abs(loads[2] - static)
            sigma = math.hypot(hookload_se, estimate.uncertainty(static, motion))
    else:
        raise ModelError(f"no friction resolution for rig state '{state}'")
    resolvable = signal >= 2.0 * sigma
    statement = "resolvable" if resolvable else (
        f"friction not resolvable here: friction {low:g} and {high:g} change the {what} by "
        f"{signal / 1e3:.1f} {unit}, less than the sensor's uncertainty of "
        f"{2.0 * sigma / 1e3:.1f} {unit} (two standard deviations); the {what} at friction "
        f"{mu:.2f} is {drag / 1e3:.1f} {unit}")
    return Resolution(resolvable, signal, drag, sigma, statement)
