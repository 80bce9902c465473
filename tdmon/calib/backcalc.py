"""Back-calculated friction factor of one steady window.

The torque-and-drag model is iterated on the friction factor until it matches the measured
value (section 4.2.6 of the seed thesis; docs/back-calculation.md): pick-up hook load rises with
mu, slack-off hook load falls, off-bottom torque rises, so a bracketed root solve
(`scipy.optimize.brentq`) finds the one mu that fits. Its standard deviation propagates the
window's standard error through the model's slope, ``sigma_mu = sigma_measured / |dF/dmu|``.

Cased hole first, open hole after: while the string is inside casing the solve sets one mu on
the cased elements; once the bit is far enough below the shoe, the cased value is held fixed and
the solve sets the open-hole elements only (per-element friction arrays of
`tdmon.model.torque_drag.WellModel`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon import vocabulary
from tdmon.calib.windows import Window
from tdmon.errors import FitError, ModelError
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import Operation, RigState

__all__ = [
    "OPERATION_FOR_STATE",
    "REAMING_OPERATIONS",
    "FrictionEstimate",
    "back_calculate",
    "back_calculate_window",
    "base_friction",
    "motion_angle",
    "shoe_depth",
    "window_measurement",
]

Quantity = Literal["hookload", "torque"]

OPERATION_FOR_STATE: Mapping[RigState, tuple[Operation, Quantity]] = MappingProxyType({
    state: (vocabulary.OPERATION_FOR_STATE[state],
            "torque" if state == RigState.ROTATING_OFF_BOTTOM else "hookload")
    for state in (RigState.PICK_UP, RigState.SLACK_OFF, RigState.ROTATING_OFF_BOTTOM)
})
"""Which model operation and measured quantity a window of a rig state calibrates: the
`tdmon.vocabulary.CALIBRATING_STATES`, with the vocabulary's load case; off-bottom rotation
calibrates on the torque (its hook load has no axial friction)."""

@dataclass(frozen=True)
class WindowMeasurement:
    """What a steady window offers a friction estimator: the model operation it calibrates, the
    quantity (index 0 hook load [N], 1 surface torque [N m] in ``WellModel.evaluate``'s result),
    the measured mean and its standard error."""

    operation: str
    quantity_index: int
    value: float
    standard_error: float


def window_measurement(window: Window) -> WindowMeasurement | None:
    """The measurement a window carries for the friction estimators; None when it has none
    (rejected, a state that calibrates nothing, or a missing/non-finite mean or error)."""
    if window.rejected is not None or window.state not in OPERATION_FOR_STATE:
        return None
    operation, quantity = OPERATION_FOR_STATE[window.state]
    measured = window.torque if quantity == "torque" else window.hookload
    se = window.torque_se if quantity == "torque" else window.hookload_se
    if measured is None or se is None or not (math.isfinite(measured) and math.isfinite(se)):
        return None
    return WindowMeasurement(operation, 1 if quantity == "torque" else 0, measured, se)


REAMING_OPERATIONS: Final[Mapping[RigState, Operation]] = vocabulary.REAMING_AXIAL_OPERATION
"""Axial operation of the combined-motion states; their friction comes from the torque with
the friction split by the motion angle psi (Aadnoy, Fazaelizadeh and Hareland 2010)."""

_DERIVATIVE_STEP = 1e-3


@dataclass(frozen=True)
class FrictionEstimate:
    """Friction factor that reproduces one measurement.

    Attributes
    ----------
    operation : model operation (``pick_up``, ``slack_off``, ``rotating``)
    quantity : ``"hookload"`` [N] or ``"torque"`` [N m]
    bit_depth : [m]
    mu : back-calculated friction factor [-]
    mu_std : its standard deviation from the measurement's standard error [-]
    measured : the measured value [N or N m]
    measured_se : its standard error [N or N m]
    sensitivity : d(quantity)/d(mu) at the solution [N or N m]
    section : which elements the solve set: ``"cased"``, ``"open"`` or ``"all"``
    evaluations : torque-and-drag evaluations used [-]
    """

    operation: str
    quantity: str
    bit_depth: float
    mu: float
    mu_std: float
    measured: float
    measured_se: float
    sensitivity: float
    section: str
    evaluations: int


def shoe_depth(model: WellModel) -> float:
    """MD of the deepest cased element's bottom [m] (0 when the hole has no casing)."""
    cased = np.flatnonzero(model.grid.element_kind == "cased")
    return float(model.grid.md[cased[-1] + 1]) if cased.size else 0.0


def base_friction(base_mu: ArrayLike, n: int) -> NDArray[np.float64]:
    """The friction of the elements a fit leaves alone [-]: ``base_mu`` as an array for
    ``np.where`` beside ``n`` elements. A number or one value per element is taken as it is
    (``np.where`` spreads a number itself; ``np.broadcast_to`` cost more than the rest of a
    small call); any other shape is spread to ``n`` here, which raises for one that does not
    fit."""
    base = np.asarray(base_mu, dtype=np.float64)
    if base.ndim and base.shape != (n,):
        base = np.broadcast_to(base, (n,))
    return base


def back_calculate(
    model: WellModel,
    operation: str,
    bit_depth: float,
    measured: float,
    measured_se: float,
    *,
    quantity: Quantity = "hookload",
    base_mu: float | NDArray[np.float64] = 0.0,
    free: NDArray[np.bool_] | None = None,
    bracket: tuple[float, float] = (0.0, 1.0),
    method: str = "soft-string",
    section: str = "all",
    xtol: float = 1e-6,
    psi: float | None = None,
) -> FrictionEstimate:
    """Friction factor on the ``free`` elements that reproduces ``measured``.

    Parameters
    ----------
    model : prepared well
    operation : ``"pick_up"``, ``"slack_off"`` or ``"rotating"``
    bit_depth : [m]
    measured : hook load [N] (block weight included) or surface torque [N m]
    measured_se : standard error of ``measured`` [N or N m]
    quantity : ``"hookload"`` or ``"torque"``
    base_mu : friction of the elements that are not free [-], a number or one per element
    free : elements whose friction is solved for (all when None)
    bracket : friction factors between which the root must lie [-]
    method : torque-and-drag method
    section : label of the free elements for the result
    xtol : absolute tolerance on mu [-]
    psi : motion angle for pick-up/slack-off while rotating, ``atan(V_axial / V_tangential)``
        [rad]; None for pure axial motion

    Returns
    -------
    FrictionEstimate

    Raises
    ------
    FitError
        Non-finite input, a bit depth the model refuses, or a measurement outside what the
        bracket can reproduce (the message gives the modelled range).
    """
    if not (math.isfinite(measured) and math.isfinite(measured_se) and measured_se >= 0.0
            and math.isfinite(bit_depth)):
        raise FitError(f"measured {quantity} {measured!r} +/- {measured_se!r} at bit depth "
                       f"{bit_depth!r} m is not finite")
    n = model.n_elements
    base = base_friction(base_mu, n)
    mask = np.ones(n, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    index = 1 if quantity == "torque" else 0
    calls = 0

    def modelled(mu: float) -> float:
        nonlocal calls
        calls += 1
        # every element free: the model's own uniform array of the same value (no array built
        # and checked per call); -0.0 keeps its array (the model's keeps one zero per value)
        friction: float | NDArray[np.float64] = (
            float(mu) if free is None and mu != 0.0 else np.where(mask, mu, base))
        return model.evaluate(operation, bit_depth, friction, method=method, psi=psi)[index]

    def modelled_pair(mu_a: float, mu_b: float) -> tuple[float, float]:
        """`modelled` at two friction factors, marched together (one call)."""
        nonlocal calls
        calls += 2
        cases = np.stack((np.where(mask, mu_a, base), np.where(mask, mu_b, base)))
        values = model.evaluate_cases(operation, bit_depth, cases, method=method, psi=psi)[index]
        return float(values[0]), float(values[1])

    low, high = bracket
    try:
        model_low, model_high = modelled_pair(low, high)
        f_low, f_high = model_low - measured, model_high - measured
    except ModelError as exc:
        raise FitError(f"cannot model {operation} at bit depth {bit_depth:.1f} m: {exc}") from exc
    if f_low * f_high > 0.0:
        unit = "kN m" if quantity == "torque" else "kN"
        # in the engineer's words: no friction factor in the searched range explains it
        what = "torque" if quantity == "torque" else "hook load"
        raise FitError(
            f"measured {operation.replace('_', '-')} {what} {measured / 1e3:.1f} {unit} at "
            f"{bit_depth:.1f} m bit depth cannot be matched by any friction factor from {low:g} "
            f"to {high:g} (the model gives {min(f_low, f_high) / 1e3 + measured / 1e3:.1f} to "
            f"{max(f_low, f_high) / 1e3 + measured / 1e3:.1f} {unit}): check the well file, "
            "block weight and sensor")
    if f_low == 0.0 or f_high == 0.0:
        mu = low if f_low == 0.0 else high
    else:
        # here, not at import: scipy.optimize is 20 MB and 0.2 s an idle daemon need not pay
        from scipy.optimize import brentq

        try:
            mu = float(brentq(lambda m: modelled(m) - measured, low, high, xtol=xtol))
        except (RuntimeError, ValueError) as exc:
            raise FitError(f"root solve for {operation} failed: {exc}") from exc
    step_low, step_high = max(low, mu - _DERIVATIVE_STEP), min(high, mu + _DERIVATIVE_STEP)
    at_high, at_low = modelled_pair(step_high, step_low)
    slope = (at_high - at_low) / (step_high - step_low)
    if not (math.isfinite(slope) and slope != 0.0):
        raise FitError(f"{operation} {quantity} does not depend on friction at "
                       f"{bit_depth:.1f} m (vertical string or no free element)")
    mu_std = float(measured_se / abs(slope))
    if not math.isfinite(mu_std):
        raise FitError(f"the uncertainty of {operation} friction at {bit_depth:.1f} m is not "
                       "finite (measurement standard error too large)")
    return FrictionEstimate(
        operation=operation, quantity=quantity, bit_depth=float(bit_depth), mu=mu,
        mu_std=mu_std, measured=float(measured),
        measured_se=float(measured_se), sensitivity=float(slope), section=section,
        evaluations=calls,
    )


def back_calculate_window(
    model: WellModel,
    window: Window,
    *,
    mu_cased: float | None = None,
    min_open_length: float = 30.0,
    bracket: tuple[float, float] = (0.0, 1.0),
    method: str = "soft-string",
    shoe: float | None = None,
) -> FrictionEstimate:
    """Back-calculate the friction factor of one window, cased hole first.

    Parameters
    ----------
    model : prepared well
    window : a usable window of state ``pick_up``, ``slack_off``, ``rotating_off_bottom``
        (torque), ``reaming`` or ``back_reaming`` (torque with the friction split by the motion
        angle, `motion_angle`)
    mu_cased : cased-hole friction found so far; with the bit more than ``min_open_length``
        below the shoe it is held on the cased elements and the open-hole mu is solved
    min_open_length : string length below the shoe needed for an open-hole solve [m]
    bracket : [-]
    method : torque-and-drag method
    shoe : `shoe_depth` of ``model`` when the caller keeps it [m] (None: found here)

    Returns
    -------
    FrictionEstimate

    Raises
    ------
    FitError
        The window is rejected, of a state without a friction solve, lacks its quantity, or
        the root is not bracketed.
    """
    if window.rejected is not None:
        raise FitError(f"window rejected: {window.rejected}")
    psi = None
    quantity: Quantity
    if window.state in REAMING_OPERATIONS:
        operation, quantity = REAMING_OPERATIONS[window.state], "torque"
        psi = motion_angle(model, window)
    elif window.state in OPERATION_FOR_STATE:
        operation, quantity = OPERATION_FOR_STATE[window.state]
    else:
        raise FitError(f"no friction solve for rig state '{window.state}'")
    if quantity == "torque":
        if window.torque is None or window.torque_se is None:
            raise FitError("rotating window without surface torque")
        measured, se = window.torque, window.torque_se
    else:
        measured, se = window.hookload, window.hookload_se
    kind = model.grid.element_kind
    if shoe is None:
        shoe = shoe_depth(model)
    below_shoe = window.bit_depth - shoe
    if mu_cased is not None and below_shoe > min_open_length and (kind == "open").any():
        return back_calculate(model, operation, window.bit_depth, measured, se,
                              quantity=quantity, base_mu=np.where(kind == "cased", mu_cased, 0.0),
                              free=np.asarray(kind == "open"), bracket=bracket, method=method,
                              section="open", psi=psi)
    if below_shoe <= 0.0 and shoe > 0.0:
        return back_calculate(model, operation, window.bit_depth, measured, se,
                              quantity=quantity, bracket=bracket, method=method, section="cased",
                              psi=psi)
    return back_calculate(model, operation, window.bit_depth, measured, se, quantity=quantity,
                          bracket=bracket, method=method, section="all", psi=psi)


def motion_angle(model: WellModel, window: Window) -> float:
    """Angle of the pipe surface's motion from the tangential direction [rad].

    ``psi = atan(|V_axial| / (omega r))`` with the window's mean axial speed and rotation and the
    torque radius of the string's top component (most of the string's contact length).

    Raises
    ------
    FitError
        The window has no speed or no rotation.
    """
    if window.velocity is None or window.rpm is None or window.rpm <= 0.0:
        raise FitError(f"{window.state} window without axial speed and rotation")
    radius = float(model.component_radius[-1])
    return math.atan2(abs(window.velocity), window.rpm * radius)
