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
from tdmon.calib.parameters import (
    JOINT_PARAMETERS,
    WEIGHT_FACTOR,
    EstimatedParameters,
    join_words,
)
from tdmon.calib.windows import Window
from tdmon.errors import ModelError
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import Operation, RigState

__all__ = [
    "JointSettings",
    "JointState",
    "Measurement",
    "identifiability",
    "initial_joint",
    "measurements",
    "update_joint",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class JointSettings:
    """Settings of the joint estimate (SI).

    Attributes
    ----------
    parameters : what is estimated, with each parameter's prior, drift and bounds
        (:data:`tdmon.calib.parameters.JOINT_PARAMETERS`: the friction factor and the weight
        factor, whose prior is 1 +/- 0.05: the model is right)
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
    """

    parameters: EstimatedParameters = JOINT_PARAMETERS
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

    def __post_init__(self) -> None:
        self.parameters.index(WEIGHT_FACTOR.name)  # the measurement model needs it

    def with_prior(self, name: str, prior: float, prior_std: float) -> JointSettings:
        """These settings with parameter ``name``'s prior replaced (ValueError: unknown)."""
        return replace(self, parameters=self.parameters.with_prior(name, prior, prior_std))

    @property
    def bounds(self) -> tuple[Array, Array]:
        """Lower and upper bounds of the state vector."""
        return (np.array([p.bounds[0] for p in self.parameters]),
                np.array([p.bounds[1] for p in self.parameters]))


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
    """

    t: float | None = None
    bit_depth: float | None = None
    recent: tuple[tuple[float, float, str, float], ...] = ()
    gated: int = 0


def initial_joint(settings: JointSettings) -> JointState:
    """The prior state: each parameter's prior, uncorrelated."""
    parameters = settings.parameters
    return JointState(np.array([p.prior for p in parameters]),
                      np.diag([p.prior_std**2 for p in parameters]))


class Measurement(NamedTuple):
    """One scalar a window offers: the model operation, the quantity (0 hook load [N], 1
    torque [N m]), the measured mean and its standard error, and its kind (``pick_up``,
    ``slack_off``, ``static``, ``rotating_hookload``, ``rotating_torque``)."""

    operation: str
    quantity: int
    value: float
    se: float
    kind: str


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
        return (Measurement(str(state), 0, window.hookload, window.hookload_se, str(state)),)
    if state in (RigState.STATIC, RigState.CIRCULATING):
        if last_motion in (RigState.PICK_UP, RigState.SLACK_OFF):
            return ()
        kind = "static" if last_motion is None else "static_released"
        return (Measurement(Operation.STATIC, 0, window.hookload, window.hookload_se, kind),)
    if state != RigState.ROTATING_OFF_BOTTOM:
        return ()
    out = [Measurement(Operation.STATIC, 0, window.hookload, window.hookload_se,
                       "rotating_hookload")]
    if (window.torque is not None and window.torque_se is not None
            and math.isfinite(window.torque) and "torque_stuck" not in window.flags):
        out.append(Measurement(Operation.ROTATING, 1, window.torque, window.torque_se,
                               "rotating_torque"))
    return tuple(out)


@dataclass(frozen=True)
class _Linear(Linearisation):
    model_value: float = 0.0  # F or T at w = 1 [N or N m]


def _linearise(model: WellModel, m: Measurement, bit_depth: float, block: float, tau: float,
               settings: JointSettings, method: str) -> Callable[[Array], _Linear]:
    """``x -> _Linear`` for one measurement (the closure `iterated_update` calls).

    The measurement model of each parameter (a new one in ``settings.parameters`` enters
    here): hook load ``block + w F(mu)``, torque ``w T(mu)``; a parameter the model does not
    use has a zero derivative and keeps its prior."""
    offset = block if m.quantity == 0 else 0.0
    model_offset = model.well.block_weight if m.quantity == 0 else 0.0
    n = len(settings.parameters)
    at_mu, at_w = 0, settings.parameters.index(WEIGHT_FACTOR.name)

    def linearise(x: Array) -> _Linear:
        mu = float(x[at_mu].clip(0.0, 1.0))  # np.clip's own call, without its wrapper
        w = float(x[at_w])
        value, gradient = model.evaluate_gradient(m.operation, bit_depth, mu,
                                                  quantity_index=m.quantity, method=method)
        f = value - model_offset
        slope = float(gradient.sum())  # uniform friction: the sum of the per-element gradient
        variance = (m.se**2 + (tau * w * slope) ** 2 + (settings.weight_model_std * w * f) ** 2)
        if m.kind in ("static", "static_released"):
            drag = model.evaluate(Operation.PICK_UP, bit_depth, mu, method=method)[0] - value
            # the drag share a hang may hold: uniform on -1..1 when the last motion is unknown
            share = (1.0 / math.sqrt(3.0) if m.kind == "static"
                     else settings.released_drag_std)
            variance += (share * w * drag) ** 2
        jacobian = np.zeros(n)
        jacobian[at_mu] = w * slope
        jacobian[at_w] = f
        return _Linear(offset + w * f, jacobian, max(variance, 1.0), f)

    return linearise


def update_joint(state: JointState, model: WellModel, window: Window, block: float,
                 scatter: Mapping[str, float], settings: JointSettings,
                 method: str = "soft-string", *, last_motion: str | None = None) -> JointState:
    """The joint state after one window (``state`` itself when the window offers nothing).

    Parameters
    ----------
    state : the state so far
    model : the prepared well
    window : a closed window
    block : block weight (learnt in slips, else configured) [N]
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
    if state.t is not None and state.bit_depth is not None:
        hours = max(window.t_end - state.t, 0.0) / 3600.0
        metres = abs(depth - state.bit_depth) / 100.0
        q = np.sqrt([p.drift_per_hour**2 * hours + p.drift_per_100m**2 * metres
                     for p in settings.parameters])
        state = predict(state, q)
    recent = list(state.recent)
    gated = state.gated
    bounds = settings.bounds
    for m in offered:
        tau = scatter.get(m.kind, settings.scatter_prior)
        # a hang's hook load is linear in the state (friction enters only its variance): one
        # linearisation is exact; pick-up, slack-off and torque are relinearised
        iterations = 1 if m.operation == Operation.STATIC else settings.iterations
        try:
            result = iterated_update(state, m.value, _linearise(model, m, depth, block, tau,
                                                                settings, method),
                                     iterations=iterations, gate=settings.gate,
                                     bounds=bounds)
        except ModelError:
            continue
        if result.accepted:
            state = result.state
            recent.append((window.t_end, depth, m.kind, result.state.innovation))
        elif result.gated:
            gated += 1
    recent = [r for r in recent if window.t_end - r[0] <= settings.horizon
              and abs(depth - r[1]) <= settings.horizon_depth]
    return replace(state, t=window.t_end, bit_depth=depth, recent=tuple(recent), gated=gated)


@dataclass(frozen=True)
class Identifiability:
    """Whether friction and the parameters beside it are separated now.

    Attributes
    ----------
    identifiable : every parameter beside the friction is known from the data, not its prior
    statement : the verdict in words
    variance_ratios : per parameter beside the friction, its posterior over prior variance [-]
    kinds : measurements per kind within the horizon [-]
    """

    identifiable: bool
    statement: str
    variance_ratios: Mapping[str, float]
    kinds: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))


def identifiability(state: JointState, settings: JointSettings) -> Identifiability:
    """The verdict on the current joint estimate.

    A parameter is identified when its variance fell below ``identified_ratio`` of its prior
    (for the weight factor: a hang, rotation off bottom, or pick-up with slack-off did it).
    Otherwise the verdict says what is missing for the first one that is not: pick-up (or
    slack-off) windows alone cannot separate weight from friction, and the friction is then
    the one at the prior weight.
    """
    parameters = settings.parameters
    kinds: dict[str, int] = {}
    for _, _, kind, _ in state.recent:
        kinds[kind] = kinds.get(kind, 0) + 1
    ratios = {p.name: float(state.covariance[k, k]) / p.prior_std**2
              for k, p in enumerate(parameters) if k > 0}
    frozen = MappingProxyType(kinds)
    open_ = [p for p in parameters.others if not ratios[p.name] < settings.identified_ratio]
    if not open_:
        return Identifiability(True, "identifiable", MappingProxyType(ratios), frozen)
    first, friction = open_[0], parameters.friction.noun
    moving = {k for k in kinds if k in ("pick_up", "slack_off")}
    weighing = {k for k in kinds if k not in moving}
    if not kinds:
        statement = ("no window yet: "
                     + join_words([friction, *(p.label for p in parameters.others)])
                     + " are the prior")
    elif len(moving) == 1 and not weighing and first.name == WEIGHT_FACTOR.name:
        # what pick-up or slack-off alone leaves open for the weight (another parameter says
        # what separates it when its measurement model is written)
        which = next(iter(moving)).replace("_", "-")
        what = first.key.replace("_", " ")
        statement = (f"{which} only: {what} and {friction} not separable, {friction} given "
                     f"at the prior {what} (rotation off bottom or "
                     f"{'slack-off' if which == 'pick-up' else 'pick-up'} nearby separates them)")
    else:
        statement = (f"weakly identifiable: the {first.label} rests mostly on its prior "
                     f"(variance {100 * ratios[first.name]:.0f} % of the prior's)")
    return Identifiability(False, statement, MappingProxyType(ratios), frozen)


def _friction_given(state: JointState, fixed: list[tuple[int, float]]) -> tuple[float, float]:
    """The friction's mean and standard deviation given parameters ``fixed`` (index, value):
    the Gaussian posterior conditioned on them, one at a time (``mu + P_mk / P_kk (x_k -
    m_k)``, variance ``P_mm - P_mk^2 / P_kk``; in turn, the same as all at once)."""
    mean, p = state.mean, state.covariance
    for k, value in fixed[:-1]:
        mean = mean + p[:, k] / p[k, k] * (value - mean[k])
        p = p - np.outer(p[:, k], p[k, :]) / p[k, k]
    k, value = fixed[-1]
    return (float(mean[0] + p[0, k] / p[k, k] * (value - mean[k])),
            math.sqrt(max(float(p[0, 0] - p[0, k] ** 2 / p[k, k]), 0.0)))


def joint_fields(state: JointState, settings: JointSettings) -> dict[str, Any]:
    """The joint estimate's message fields (``mu``/``mu_std`` and the kind's own), in the
    order of :meth:`~tdmon.calib.parameters.EstimatedParameters.message_fields`.

    ``mu`` is the joint friction when every other parameter is identified, else the friction
    at the prior of those that are not (the Gaussian posterior conditioned on them, for the
    weight factor ``mu + P_mw / P_ww (w_prior - w)``, variance ``P_mm - P_mw^2 / P_ww``),
    which is what the data say about friction when they cannot say anything about the weight.
    Both are in the message (``mu_joint``, ``mu_at_prior_weight``).
    """
    parameters = settings.parameters
    p = state.covariance
    std = state.std
    values: dict[str, Any] = {}
    for k, parameter in enumerate(parameters):
        values[parameter.name] = float(state.mean[k])
        values[parameter.std_field] = float(std[k])
    for i, j in parameters.pairs():
        values[parameters.correlation_field(i, j)] = (
            float(p[i, j] / (std[i] * std[j])) if std[i] > 0 and std[j] > 0 else 0.0)
    # where along the string the weight error sits is unknown: spread evenly (a mud density)
    # the friction is the joint one; all in the vertical top (a fill level) it is mu w
    departure = abs(float(state.mean[parameters.index(WEIGHT_FACTOR.name)]) - 1.0)
    mu_joint_std = math.hypot(float(std[0]), settings.spread_mu * float(state.mean[0])
                              * departure)
    values[parameters.joint_field] = float(state.mean[0])
    values[f"{parameters.joint_field}_std"] = mu_joint_std
    for k, parameter in enumerate(parameters.others, start=1):
        at_prior, at_prior_std = _friction_given(state, [(k, parameter.prior)])
        values[parameters.at_prior_field(parameter)] = at_prior
        values[f"{parameters.at_prior_field(parameter)}_std"] = at_prior_std
    verdict = identifiability(state, settings)
    values["identifiable"] = verdict.identifiable
    values["identifiability"] = verdict.statement
    for parameter in parameters.others:
        values[parameter.variance_ratio_field] = verdict.variance_ratios[parameter.name]
    if verdict.identifiable:
        mu, mu_std = float(state.mean[0]), mu_joint_std
    else:
        mu, mu_std = _friction_given(state, [
            (k, parameter.prior) for k, parameter in enumerate(parameters.others, start=1)
            if not verdict.variance_ratios[parameter.name] < settings.identified_ratio])
    return {"mu": mu, "mu_std": mu_std,
            **{f.name: values[f.name] for f in parameters.message_fields()},
            "windows": dict(verdict.kinds), "residuals": residuals(state), "gated": state.gated}


def residuals(state: JointState) -> dict[str, float]:
    """Mean residual per measurement kind within the horizon [N, or N m for torque]: each
    measurement against the joint estimate before it. Pick-up above and slack-off below zero
    (or the reverse) at once is the signature of a weight error read as friction."""
    sums: dict[str, list[float]] = {}
    for _, _, kind, residual in state.recent:
        sums.setdefault(kind, []).append(residual)
    return {kind: float(np.mean(values)) for kind, values in sums.items()}
