"""Joint estimate of friction and a weight factor from windows near each other in depth and time.

A single window's friction absorbs every error of the weight model: a string 4 % lighter than
modelled reads as less pick-up friction and more slack-off friction. With no force at the bit
(every off-bottom window) the soft-string march is homogeneous of degree one in the buoyed weight
per metre (the effective force, the contact force and the torque all scale with it), so a weight
factor ``w`` multiplying the modelled buoyed weight gives exactly

    hook load = block + w F(mu, operation, bit depth),   torque = w T(mu, bit depth)

with ``F``, ``T`` the model's values at ``w = 1``. The state is ``x = [mu, w]``: ``w`` as a
factor (not an offset in N) because that is what the physics is linear in, and because a
fluid-density or mass-per-metre error is a fixed fraction of the string's weight at any depth,
so its prior (1 +/- 0.05 by default) carries from well to well. ``mu`` is one friction factor on
the whole string (the string's average; the per-window and profile estimates keep the
cased/open split).

What each window says (``H = [dh/dmu, dh/dw]``):

- static or circulating hang after rotation off bottom (drag released) or with the last motion
  unknown: ``[0, F_static]``, weight alone (with the drag it may hold as model error); a hang
  right after a pull or a run is not used: it holds an unknown share of that motion's drag,
  the same from hang to hang, which no number of hangs averages out;
- rotating off bottom: its hook load ``[0, F_static]`` (rotation frees the axial friction) and
  its torque ``[w dT/dmu, T]``, i.e. ``mu w``;
- pick-up ``[w dF_pu/dmu > 0, F_pu]`` and slack-off ``[w dF_so/dmu < 0, F_so]``: each alone is
  one equation in two unknowns; a pick-up and a slack-off near each other separate them, the
  way two lines with slopes of opposite sign cross.

The filter is the shared iterated EKF (:mod:`tdmon.calib.kalman`), one update per measurement,
with random-walk drift growing with the time and the depth between windows, which makes the set
of windows that count a sliding one. Each measurement's variance is its standard error, plus
the between-window friction scatter ``(tau dh/dmu)^2`` (:mod:`tdmon.calib.scatter`, estimated
online), plus a small model error of the string weight, so the published standard deviations are
the spread truth has about the estimate, not the window noise alone. See
docs/back-calculation.md, "Friction and weight together".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.kalman import KalmanState, Linearisation, iterated_update, predict
from tdmon.calib.measurement import MOTION_OF_STATE, Resolution, SensorEstimate, factor_slope
from tdmon.calib.parameters import (
    BLOCK_WEIGHT,
    FRICTION_AND_WEIGHT,
    HOOKLOAD_OFFSET,
    JOINT_PARAMETERS,
    SHEAVE_EFFICIENCY,
    WEIGHT_FACTOR,
    EstimatedParameters,
    join_words,
    rig_parameters,
)
from tdmon.calib.windows import Window
from tdmon.errors import ModelError
from tdmon.model.hookload_sensor import HookloadSensor
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well
from tdmon.vocabulary import Operation, RigState

__all__ = [
    "IN_SLIPS",
    "PAIR_CORRELATION",
    "JointSettings",
    "JointState",
    "Measurement",
    "drilling_measurements",
    "identifiability",
    "initial_joint",
    "mean_and_covariance",
    "measurements",
    "sensor_estimate",
    "slips_measurement",
    "update_joint",
    "update_joint_slips",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class JointSettings:
    """Settings of the joint estimate (SI).

    Attributes
    ----------
    parameters : what is estimated, with each parameter's prior, drift and bounds (by
        default the friction factor and the weight factor, whose prior is 1 +/- 0.05: the
        model is right; :func:`for_rig` adds the hook-load measurement's parameters of
        :data:`tdmon.calib.parameters.JOINT_PARAMETERS` that a rig's sensor calls for)
    scatter_prior : between-window friction scatter until it is estimated [-]
    scatter_windows : recent windows per operation the scatter is estimated from [-]
    weight_model_std : model error of the string weight per window, relative [-]
    released_drag_std : share of the drag a hang after rotation off bottom may still hold,
        standard deviation [-] (a hang with its last motion unknown holds a share uniform on
        -1..1; one right after a pull or a run is not used: it holds an unknown share of that
        motion's drag, which no number of such hangs averages out)
    iterations : linearisations per measurement [-]
    gate : a measurement further than this many predicted standard deviations is left out [-]
    identified_ratio : a parameter counts as identified when its posterior variance is below
        this fraction of its prior's [-]
    horizon, horizon_depth : windows this recent [s] and this near [m] are listed as the set
        the estimate rests on
    spread_mu : model error of a weight error that is not spread evenly along the string (an
        unfilled top weighs on the hook but presses on no wall), relative to ``mu |w - 1|``
        [-]: added to the published friction's standard deviation
    mismatch_tolerance : relative weight difference the mismatch alarm reports [-]
    mismatch_windows : consecutive estimates beyond it that raise the alarm [-]
    sensor : how the rig's hook-load channel reads the load on the hook (where the sensor
        sits, its lines; :class:`tdmon.model.hookload_sensor.HookloadSensor`)
    hysteresis : unmodelled difference between readings hoisting and lowering, relative to the
        load [-] (sensor hysteresis, sheave friction beyond the model): measurement noise of a
        moving window, and the floor of what friction must exceed to be resolved
    torque_uncertainty : the torque sensor's zero and scale uncertainty [N m]
    """

    parameters: EstimatedParameters = FRICTION_AND_WEIGHT
    scatter_prior: float = 0.02
    scatter_windows: int = 30
    weight_model_std: float = 0.002
    released_drag_std: float = 0.1
    iterations: int = 3
    gate: float = 5.0
    identified_ratio: float = 0.25
    horizon: float = 3600.0
    horizon_depth: float = 300.0
    spread_mu: float = 0.6
    mismatch_tolerance: float = 0.01
    mismatch_windows: int = 3
    sensor: HookloadSensor = field(default_factory=HookloadSensor)
    hysteresis: float = 0.01
    torque_uncertainty: float = 300.0

    def __post_init__(self) -> None:
        self.parameters.index(WEIGHT_FACTOR.name)  # the measurement model needs it

    def with_prior(self, name: str, prior: float, prior_std: float) -> JointSettings:
        """These settings with parameter ``name``'s prior replaced (ValueError: unknown)."""
        return replace(self, parameters=self.parameters.with_prior(name, prior, prior_std))

    @property
    def scales(self) -> Array:
        """What one unit of each state component is in SI: the filter keeps forces in kN, so
        that its covariance holds numbers of like size (a friction's 1e-2 beside a block
        weight's 1e8 N^2 would cost the Joseph form its digits)."""
        return np.array([1e3 if p.unit == "N" else 1.0 for p in self.parameters])

    @property
    def bounds(self) -> tuple[Array, Array]:
        """Lower and upper bounds of the state vector (in the filter's units)."""
        scales = self.scales
        return (np.array([p.bounds[0] for p in self.parameters]) / scales,
                np.array([p.bounds[1] for p in self.parameters]) / scales)

    def position(self, name: str) -> int | None:
        """Where parameter ``name`` sits in the state (None: not estimated)."""
        return self.parameters.index(name) if name in self.parameters.names else None


@dataclass(frozen=True)
class JointState(KalmanState):
    """The filter on the parameters (``[mu, w]``) and what the identifiability statement needs.

    Attributes
    ----------
    mean, covariance : of the parameters of the settings, in their order (friction first)
    t, bit_depth : time [s] and bit depth [m] of the last window used (None before)
    recent : ``(t, bit depth, kind, residual)`` of the measurements used within the horizon,
        the residual being measured minus predicted before the update [N or N m]
    gated : measurements left out by the gate [-]
    slips : in-slips readings used [-] (before the first, nothing has weighed the empty block:
        :func:`sensor_estimate` gives the priors' values)
    """

    t: float | None = None
    bit_depth: float | None = None
    recent: tuple[tuple[float, float, str, float], ...] = ()
    gated: int = 0
    slips: int = 0


def for_rig(settings: JointSettings, well: Well) -> JointSettings:
    """``settings`` for one rig: its hook-load sensor, and the parameters of
    :data:`~tdmon.calib.parameters.JOINT_PARAMETERS` as that sensor calls for them (the
    sheave efficiency for a deadline sensor only), the block weight's prior centred on the
    well's block weight as the sensor weighs it (wide where the well gives none: the first
    in-slips readings decide; :func:`tdmon.calib.parameters.rig_parameters`)."""
    sensor = well.hookload_sensor
    parameters = rig_parameters(reads_sheave_friction=sensor.reads_sheave_friction,
                                block_weight=well.block_weight - sensor.above_sensor,
                                efficiency=sensor.efficiency, parameters=JOINT_PARAMETERS)
    return replace(settings, parameters=parameters, sensor=sensor)


def initial_joint(settings: JointSettings) -> JointState:
    """The prior state: each parameter's prior, uncorrelated (forces in kN)."""
    parameters = settings.parameters
    scales = settings.scales
    return JointState(np.array([p.prior for p in parameters]) / scales,
                      np.diag([p.prior_std**2 for p in parameters]) / scales**2)


def mean_and_covariance(state: JointState, settings: JointSettings) -> tuple[Array, Array]:
    """The state's mean and covariance in SI (the filter keeps forces in kN)."""
    scales = settings.scales
    return state.mean * scales, state.covariance * np.outer(scales, scales)


def sensor_estimate(state: JointState, settings: JointSettings, block_weight: float
                    ) -> SensorEstimate:
    """What the joint state knows of the hook-load measurement now (the block weight
    ``block_weight`` [N], the sensor's efficiency and a zero offset of 0 where a parameter is
    not estimated).

    Until an in-slips reading has weighed the empty block, the values are the priors' (with
    the state's spreads): what pick-ups, slack-offs and hangs alone say of the block weight,
    the offset and the sheave efficiency is mixed with friction and the string weight, and a
    window read through it would be read through its own echo."""
    mean, covariance = mean_and_covariance(state, settings)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    weighed = state.slips > 0

    def value(name: str, default: float) -> tuple[float, float]:
        k = settings.position(name)
        if k is None:
            return default, 0.0
        centre = float(mean[k]) if weighed else settings.parameters.get(name).prior
        return centre, float(std[k])

    block = value(BLOCK_WEIGHT.name, block_weight)
    offset = value(HOOKLOAD_OFFSET.name, 0.0)
    sheave = value(SHEAVE_EFFICIENCY.name, settings.sensor.efficiency)
    if not settings.sensor.reads_sheave_friction:
        sheave = (settings.sensor.efficiency, 0.0)
    return SensorEstimate(settings.sensor, block[0], block[1], offset[0], offset[1],
                          min(max(sheave[0], 0.8), 1.0), sheave[1], settings.hysteresis)


class Measurement(NamedTuple):
    """One scalar a window offers: the model operation, the quantity (0 hook load [N], 1
    torque [N m]), the measured mean and its standard error, its kind (``pick_up``,
    ``slack_off``, ``static``, ``rotating_hookload``, ``rotating_torque``, and in slips
    ``in_slips``, ``in_slips_hoisting``, ``in_slips_lowering``) and the travelling block's
    motion (+1 hoisting, -1 lowering, 0 still). An in-slips reading's operation is
    ``in_slips``: the hook carries the travelling equipment alone. A drilling window's
    (``drilling_hookload``, ``drilling_torque``: its torque less the bit's) is ``on_bottom``
    with the weight on bit ``wob`` [N]."""

    operation: str
    quantity: int
    value: float
    se: float
    kind: str
    motion: int = 0
    wob: float = 0.0  # on bottom: the weight on the bit [N] (docs/drilling.md)


#: The operation of an in-slips reading (the hook carries no string).
IN_SLIPS = "in_slips"
_SLIPS_KIND = {0: "in_slips", 1: "in_slips_hoisting", -1: "in_slips_lowering"}


def slips_measurement(value: float, se: float, motion: int) -> Measurement:
    """An in-slips reading [N] (a run's mean, its standard error) with the block's motion."""
    return Measurement(IN_SLIPS, 0, value, se, _SLIPS_KIND[motion], motion)


def measurements(window: Window, last_motion: str | None = None) -> tuple[Measurement, ...]:
    """What one usable window offers the joint estimate (reaming windows: nothing, their
    friction split by the motion angle is a different load case).

    ``last_motion`` is the motion before a hang: ``pick_up`` or ``slack_off`` (the hang keeps
    an unknown share of its drag and is not used), ``rotating`` (rotation off bottom released
    the drag: kind ``static_released``) or None (unknown: kind ``static``)."""
    if window.rejected is not None or not (math.isfinite(window.hookload)
                                           and math.isfinite(window.hookload_se)):
        return ()
    state = window.state
    if state in (RigState.PICK_UP, RigState.SLACK_OFF):
        return (Measurement(str(state), 0, window.hookload, window.hookload_se, str(state),
                            MOTION_OF_STATE[state]),)
    if state in (RigState.STATIC, RigState.CIRCULATING):
        if last_motion in (RigState.PICK_UP, RigState.SLACK_OFF):
            return ()
        kind = "static" if last_motion is None else "static_released"
        return (Measurement(Operation.STATIC, 0, window.hookload, window.hookload_se, kind),)
    if state == RigState.DRILLING:
        return drilling_measurements(window)
    if state != RigState.ROTATING_OFF_BOTTOM:
        return ()
    out = [Measurement(Operation.STATIC, 0, window.hookload, window.hookload_se,
                       "rotating_hookload")]
    if (window.torque is not None and window.torque_se is not None
            and math.isfinite(window.torque) and "torque_stuck" not in window.flags):
        out.append(Measurement(Operation.ROTATING, 1, window.torque, window.torque_se,
                               "rotating_torque"))
    return tuple(out)


def drilling_measurements(window: Window) -> tuple[Measurement, ...]:
    """What a drilling window offers (docs/drilling.md, "Drilling windows"): its hook load on
    bottom with its weight on bit, the block lowering at the rate of penetration, and its
    surface torque less the bit torque (without a bit torque, the hook load alone; without a
    weight on bit, nothing)."""
    wob = window.wob
    if wob is None or not math.isfinite(wob):
        return ()
    out = [Measurement(Operation.ON_BOTTOM, 0, window.hookload, window.hookload_se,
                       "drilling_hookload", MOTION_OF_STATE[RigState.DRILLING], wob)]
    bit = window.bit_torque
    if (bit is not None and window.torque is not None and window.torque_se is not None
            and math.isfinite(window.torque) and "torque_stuck" not in window.flags):
        out.append(Measurement(Operation.ON_BOTTOM, 1, window.torque - bit, window.torque_se,
                               "drilling_torque", 0, wob))
    return tuple(out)


@dataclass(frozen=True)
class _Linear(Linearisation):
    model_value: float = 0.0  # F or T at w = 1 [N or N m]


class _Layout(NamedTuple):
    """Where each parameter of the measurement model sits in the state (None: not estimated,
    its fixed value taken instead) and the state's scales to SI."""

    mu: int
    weight: int
    block: int | None
    offset: int | None
    sheave: int | None
    scales: Array


def _layout(settings: JointSettings) -> _Layout:
    return _Layout(0, settings.parameters.index(WEIGHT_FACTOR.name),
                   settings.position(BLOCK_WEIGHT.name), settings.position(HOOKLOAD_OFFSET.name),
                   settings.position(SHEAVE_EFFICIENCY.name) if
                   settings.sensor.reads_sheave_friction else None, settings.scales)


def _linearise(model: WellModel, m: Measurement, bit_depth: float, block: float, tau: float,
               settings: JointSettings, method: str) -> Callable[[Array], _Linear]:
    """``x -> _Linear`` for one measurement (the closure `iterated_update` calls).

    The measurement model (a new parameter in ``settings.parameters`` enters here):

    - hook load ``f(motion, e) (B + w F(mu)) + o``: ``F`` the model's string top force (its
      hook load less its block weight), ``B`` the block weight as the sensor weighs it, ``o``
      the sensor's zero offset, ``f`` the sensor's factor for the block's motion at sheave
      efficiency ``e`` (:mod:`tdmon.calib.measurement`); in slips ``F = 0``;
    - torque ``w T(mu)``.

    ``B``, ``o`` and ``e`` not in the state take ``block``, 0 and the sensor's efficiency. A
    parameter the model does not use has a zero derivative and keeps its prior.
    """
    layout = _layout(settings)
    scales = layout.scales
    n = len(settings.parameters)
    sensor = settings.sensor
    model_block = model.well.block_weight
    torque = m.quantity == 1
    slips = m.operation == IN_SLIPS

    def fixed_or(x: Array, at: int | None, default: float) -> float:
        return default if at is None else float(x[at]) * scales[at]

    def linearise(x: Array) -> _Linear:
        mu = float(x[layout.mu].clip(0.0, 1.0))  # np.clip's own call, without its wrapper
        w = float(x[layout.weight])
        jacobian = np.zeros(n)
        if slips:
            value, slope = model_block, 0.0
        else:
            value, gradient = model.evaluate_gradient(m.operation, bit_depth, mu,
                                                      quantity_index=m.quantity, method=method,
                                                      wob=m.wob)
            slope = float(gradient.sum())  # uniform friction: the per-element gradient's sum
        if torque:
            f = value
            jacobian[layout.mu] = w * slope
            jacobian[layout.weight] = f
            variance = m.se**2 + (tau * w * slope) ** 2 + (settings.weight_model_std * w * f) ** 2
            return _Linear(w * f, jacobian, max(variance, 1.0), f)
        # the string's top force at w = 1; on bottom the weight on the bit is a force of its
        # own, which the weight factor does not scale (rotating: F = w F_0 - W)
        f = value - model_block + m.wob
        b = fixed_or(x, layout.block, block)
        o = fixed_or(x, layout.offset, 0.0)
        e = min(max(fixed_or(x, layout.sheave, sensor.efficiency), 0.8), 1.0)
        factor = sensor.factor(m.motion, e)
        load = b + w * f - m.wob
        jacobian[layout.mu] = factor * w * slope
        jacobian[layout.weight] = factor * f
        if layout.block is not None:
            jacobian[layout.block] = factor * scales[layout.block]
        if layout.offset is not None:
            jacobian[layout.offset] = scales[layout.offset]
        if layout.sheave is not None:
            jacobian[layout.sheave] = factor_slope(sensor, m.motion, e) * load
        variance = (m.se**2 + (tau * factor * w * slope) ** 2
                    + (settings.weight_model_std * w * f) ** 2)
        if m.motion != 0:
            variance += (settings.hysteresis * load) ** 2
        if m.kind in ("static", "static_released"):
            drag = model.evaluate(Operation.PICK_UP, bit_depth, mu, method=method)[0] - value
            # the drag share a hang may hold: uniform on -1..1 when the last motion is unknown
            share = (1.0 / math.sqrt(3.0) if m.kind == "static"
                     else settings.released_drag_std)
            variance += (share * w * drag) ** 2
        return _Linear(factor * load + o, jacobian, max(variance, 1.0), f)

    return linearise


def _predict(state: JointState, settings: JointSettings, t: float, depth: float) -> JointState:
    """Random-walk drift of every parameter since the last measurement."""
    if state.t is None or state.bit_depth is None:
        return state
    hours = max(t - state.t, 0.0) / 3600.0
    metres = abs(depth - state.bit_depth) / 100.0
    q = np.sqrt([p.drift_per_hour**2 * hours + p.drift_per_100m**2 * metres
                 for p in settings.parameters]) / settings.scales
    return predict(state, q)


def _apply(state: JointState, offered: tuple[Measurement, ...], model: WellModel, depth: float,
           t: float, block: float, scatter: Mapping[str, float], settings: JointSettings,
           method: str) -> JointState:
    """The measurements of one window or slips run, one update each."""
    state = _predict(state, settings, t, depth)
    recent = list(state.recent)
    gated = state.gated
    bounds = settings.bounds
    for m in offered:
        tau = scatter.get(m.kind, settings.scatter_prior)
        # a hook load is linear in the state but for friction (and a deadline sensor's
        # sheave factor): a hang or an in-slips reading is exact after one linearisation;
        # pick-up, slack-off and torque are relinearised
        linear = m.operation in (Operation.STATIC, IN_SLIPS) and m.motion == 0
        try:
            result = iterated_update(state, m.value, _linearise(model, m, depth, block, tau,
                                                                settings, method),
                                     iterations=1 if linear else settings.iterations,
                                     gate=settings.gate, bounds=bounds)
        except ModelError:
            continue
        if result.accepted:
            state = result.state
            recent.append((t, depth, m.kind, result.state.innovation))
        elif result.gated:
            gated += 1
    recent = [r for r in recent if t - r[0] <= settings.horizon
              and abs(depth - r[1]) <= settings.horizon_depth]
    return replace(state, t=t, bit_depth=depth, recent=tuple(recent), gated=gated)


def update_joint(state: JointState, model: WellModel, window: Window, block: float,
                 scatter: Mapping[str, float], settings: JointSettings,
                 method: str = "soft-string", *, last_motion: str | None = None) -> JointState:
    """The joint state after one window (``state`` itself when the window offers nothing).

    Parameters
    ----------
    state : the state so far
    model : the prepared well
    window : a closed window
    block : block weight where it is not estimated (learnt in slips, else configured) [N]
    scatter : between-window friction scatter per measurement kind [-] (missing: the prior)
    settings : joint settings
    method : torque-and-drag method
    last_motion : the motion before this window, for a hang (see `measurements`)
    """
    offered = measurements(window, last_motion)
    if not offered:
        return state
    depth = window.bit_depth
    try:
        model.check_bit_depth(depth)
    except ModelError:
        return state  # the model does not reach this depth (model coverage is alarmed apart)
    return _apply(state, offered, model, depth, window.t_end, block, scatter, settings,
                  method)


def update_joint_slips(state: JointState, model: WellModel, readings: tuple[Measurement, ...],
                       t: float, block: float, settings: JointSettings,
                       method: str = "soft-string") -> JointState:
    """The joint state after the in-slips readings of one connection (`slips_measurement`):
    the empty block's weight, the zero offset and, with the block moving, the sheave factor.
    The bit depth of the state stays (no string is read)."""
    if not readings:
        return state
    depth = state.bit_depth if state.bit_depth is not None else 0.0
    updated = _apply(state, readings, model, depth, t, block, {}, settings, method)
    return replace(updated, bit_depth=state.bit_depth,
                   slips=state.slips + (updated.updates - state.updates))


@dataclass(frozen=True)
class Identifiability:
    """Whether friction and the parameters beside it are separated now.

    Attributes
    ----------
    identifiable : friction is resolvable and every parameter beside it is known from the
        data, not its prior (the block weight and the hook-load offset by their sum: what an
        empty block reads)
    statement : the verdict in words
    variance_ratios : per parameter beside the friction, its posterior over prior variance [-]
    kinds : measurements per kind within the horizon [-]
    open : parameters held at their prior for the published friction
    resolvable : the well can resolve friction at the depth judged (True when not judged)
    """

    identifiable: bool
    statement: str
    variance_ratios: Mapping[str, float]
    kinds: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    open: tuple[str, ...] = ()
    resolvable: bool = True


def _sum_ratio(state: JointState, settings: JointSettings) -> float | None:
    """Posterior over prior variance of block weight plus offset (what an empty block reads),
    or None when the two are not both estimated."""
    b, o = settings.position(BLOCK_WEIGHT.name), settings.position(HOOKLOAD_OFFSET.name)
    if b is None or o is None:
        return None
    p = state.covariance
    prior = (settings.parameters[b].prior_std**2 / settings.scales[b] ** 2
             + settings.parameters[o].prior_std**2 / settings.scales[o] ** 2)
    return float(p[b, b] + p[o, o] + 2.0 * p[b, o]) / prior


def _weight_words(kinds: Mapping[str, int], friction: str) -> str | None:
    """What pick-up or slack-off alone leaves open for the weight factor."""
    moving = {k for k in kinds if k in ("pick_up", "slack_off")}
    weighing = {k for k in kinds if k not in moving and not k.startswith(IN_SLIPS)}
    if len(moving) != 1 or weighing:
        return None
    which = next(iter(moving)).replace("_", "-")
    what = WEIGHT_FACTOR.key
    return (f"{which} only: {what} and {friction} not separable, {friction} given at the "
            f"prior {what} (rotation off bottom or "
            f"{'slack-off' if which == 'pick-up' else 'pick-up'} nearby separates them)")


def identifiability(state: JointState, settings: JointSettings,
                    resolution: Resolution | None = None) -> Identifiability:
    """The verdict on the current joint estimate.

    Friction is judged first, by ``resolution`` (:func:`tdmon.calib.measurement.resolution`
    of the pick-up/slack-off split at the last depth: whether the well can show friction
    above the sensor's uncertainty there). A parameter beside it is identified when its
    variance fell below ``identified_ratio`` of its prior's; the block weight and the
    hook-load offset together, by the variance of their sum (only the sheave factor of a moving
    block and the string's weight in the hangs tell them apart: when their correlation is
    strong the verdict says that only the sum is known). The verdict names what is missing.
    """
    parameters = settings.parameters
    kinds: dict[str, int] = {}
    for _, _, kind, _ in state.recent:
        kinds[kind] = kinds.get(kind, 0) + 1
    scales = settings.scales
    ratios = {p.name: float(state.covariance[k, k]) * scales[k] ** 2 / p.prior_std**2
              for k, p in enumerate(parameters) if k > 0}
    frozen = MappingProxyType(kinds)
    limit = settings.identified_ratio
    pair = {BLOCK_WEIGHT.name, HOOKLOAD_OFFSET.name}
    sum_ratio = _sum_ratio(state, settings)
    open_ = [p for p in parameters.others
             if not (ratios[p.name] < limit
                     or (p.name in pair and sum_ratio is not None and sum_ratio < limit))]
    friction = parameters.friction.noun
    parts: list[str] = []
    resolvable = resolution is None or resolution.resolvable
    if resolution is not None and not resolution.resolvable:
        parts.append(resolution.statement)
    if not kinds:
        parts.append("no window yet: " + join_words([friction, *(p.label for p in
                                                                parameters.others)])
                     + " are the prior")
    else:
        for p in open_:
            words = _weight_words(kinds, friction) if p.name == WEIGHT_FACTOR.name else None
            if p.name in pair and sum_ratio is not None:
                # one sentence for the two (dict.fromkeys below keeps it once)
                words = ("the block weight and the hook-load offset rest on their priors "
                         "(no in-slips reading or hang pins down what an empty block reads)")
            parts.append(words or f"weakly identifiable: the {p.label} rests mostly on its "
                                  f"prior (variance {100 * ratios[p.name]:.0f} % of the "
                                  "prior's)")
    identifiable = resolvable and not open_ and bool(kinds)
    note = _pair_note(state, settings, ratios)
    if identifiable:
        statement = "identifiable" + (f"; {note}" if note else "")
    else:
        statement = "; ".join(dict.fromkeys(parts))
    return Identifiability(identifiable, statement, MappingProxyType(ratios), frozen,
                           tuple(p.name for p in open_), resolvable)


#: |correlation| of the block weight and the offset beyond which only their sum is known [-].
PAIR_CORRELATION = 0.9


def _pair_note(state: JointState, settings: JointSettings, ratios: Mapping[str, float]
               ) -> str | None:
    """``block weight and hook-load offset: only their sum is known`` when the two are not
    separated but their sum is (strong negative correlation)."""
    b, o = settings.position(BLOCK_WEIGHT.name), settings.position(HOOKLOAD_OFFSET.name)
    if b is None or o is None:
        return None
    p = state.covariance
    denominator = math.sqrt(max(float(p[b, b] * p[o, o]), 0.0))
    correlation = float(p[b, o]) / denominator if denominator > 0 else 0.0
    if correlation > -PAIR_CORRELATION or min(ratios[BLOCK_WEIGHT.name],
                                 ratios[HOOKLOAD_OFFSET.name]) < settings.identified_ratio:
        return None
    read = (float(state.mean[b]) * settings.scales[b]
            + float(state.mean[o]) * settings.scales[o])
    return (f"block weight and hook-load offset: only their sum is known, an empty block "
            f"reads {read / 1e3:.0f} kN")


def _friction_given(mean: Array, p: Array, fixed: list[tuple[int, float]]
                    ) -> tuple[float, float]:
    """The friction's mean and standard deviation given parameters ``fixed`` (index, value):
    the Gaussian posterior conditioned on them, one at a time (``mu + P_mk / P_kk (x_k -
    m_k)``, variance ``P_mm - P_mk^2 / P_kk``; in turn, the same as all at once)."""
    for k, value in fixed[:-1]:
        mean = mean + p[:, k] / p[k, k] * (value - mean[k])
        p = p - np.outer(p[:, k], p[k, :]) / p[k, k]
    k, value = fixed[-1]
    return (float(mean[0] + p[0, k] / p[k, k] * (value - mean[k])),
            math.sqrt(max(float(p[0, 0] - p[0, k] ** 2 / p[k, k]), 0.0)))


def joint_fields(state: JointState, settings: JointSettings,
                 resolution: Resolution | None = None) -> dict[str, Any]:
    """The joint estimate's message fields (``mu``/``mu_std`` and the kind's own), in the
    order of :meth:`~tdmon.calib.parameters.EstimatedParameters.message_fields`, SI.

    ``mu`` is the joint friction when every other parameter is identified, else the friction
    at the prior of those that are not (the Gaussian posterior conditioned on them, for the
    weight factor ``mu + P_mw / P_ww (w_prior - w)``, variance ``P_mm - P_mw^2 / P_ww``),
    which is what the data say about friction when they cannot say anything about the weight.
    Both are in the message (``mu_joint``, ``mu_at_prior_weight``). Where the well cannot
    resolve friction (``resolution``), ``mu`` and ``mu_std`` are None: no number is published
    that the data cannot carry.
    """
    parameters = settings.parameters
    mean, p = mean_and_covariance(state, settings)
    std = np.sqrt(np.maximum(np.diag(p), 0.0))
    values: dict[str, Any] = {}
    for k, parameter in enumerate(parameters):
        values[parameter.name] = float(mean[k])
        values[parameter.std_field] = float(std[k])
    for i, j in parameters.pairs():
        values[parameters.correlation_field(i, j)] = (
            float(p[i, j] / (std[i] * std[j])) if std[i] > 0 and std[j] > 0 else 0.0)
    # where along the string the weight error sits is unknown: spread evenly (a mud density)
    # the friction is the joint one; all in the vertical top (a fill level) it is mu w
    departure = abs(float(mean[parameters.index(WEIGHT_FACTOR.name)]) - 1.0)
    mu_joint_std = math.hypot(float(std[0]), settings.spread_mu * float(mean[0]) * departure)
    values[parameters.joint_field] = float(mean[0])
    values[f"{parameters.joint_field}_std"] = mu_joint_std
    for k, parameter in enumerate(parameters.others, start=1):
        at_prior, at_prior_std = _friction_given(mean, p, [(k, parameter.prior)])
        values[parameters.at_prior_field(parameter)] = at_prior
        values[f"{parameters.at_prior_field(parameter)}_std"] = at_prior_std
    verdict = identifiability(state, settings, resolution)
    values["identifiable"] = verdict.identifiable
    values["identifiability"] = verdict.statement
    for parameter in parameters.others:
        values[parameter.variance_ratio_field] = verdict.variance_ratios[parameter.name]
    mu: float | None
    mu_std: float | None
    if not verdict.resolvable:
        mu, mu_std = None, None
    elif verdict.identifiable or not verdict.open:
        mu, mu_std = float(mean[0]), mu_joint_std
    else:
        mu, mu_std = _friction_given(mean, p, [
            (parameters.index(name), parameters.get(name).prior) for name in verdict.open])
    extra: dict[str, Any] = {"windows": dict(verdict.kinds), "residuals": residuals(state),
                             "gated": state.gated, "resolvable": verdict.resolvable}
    if resolution is not None:
        extra["friction_signal"] = resolution.signal
        extra["sensor_uncertainty"] = resolution.uncertainty
    return {"mu": mu, "mu_std": mu_std,
            **{f.name: values[f.name] for f in parameters.message_fields()}, **extra}


def residuals(state: JointState) -> dict[str, float]:
    """Mean residual per measurement kind within the horizon [N, or N m for torque]: each
    measurement against the joint estimate before it. Pick-up above and slack-off below zero
    (or the reverse) at once is the signature of a weight error read as friction."""
    sums: dict[str, list[float]] = {}
    for _, _, kind, residual in state.recent:
        sums.setdefault(kind, []).append(residual)
    return {kind: float(np.mean(values)) for kind, values in sums.items()}
