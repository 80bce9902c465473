"""Live calibration of the friction law mu(T) from every steady window.

The parameters theta of the configured mu(T) family (e.g. ``a`` and ``b`` of mu = a + b T,
eq 5 of the seed thesis), or a single scale on a laboratory fit (mu = s mu_lab(T)), are the
state of an iterated extended Kalman filter. Each window measures the hook load (or torque) of
its operation at its bit depth with every element's friction mu(T_element; theta), T_element the
annulus temperature there; the Jacobian d(hook load)/d(theta) comes from finite differences on
the torque-and-drag model.

The temperature dependence is only identifiable when windows see different temperatures: a
window's *effective temperature* is the friction-weighted mean temperature of the elements it
feeds on, ``T_eff = sum(J_j T_j) / sum(J_j)`` with ``J_j = dh/dmu_j``. :func:`identifiability`
reports the slope dmu/dT with its 95 % interval and the range of T_eff seen, and says the slope
is not identified when the interval includes zero or the range is too narrow.

Pure ``predict``/``update`` on a frozen :class:`MuTState` (the filter itself, Joseph-form update
and iterated EKF, is :mod:`tdmon.calib.kalman`), a thin wrapper (:class:`MuTCalibrator`); fit
results are keyed like the family's own arguments so ``FrictionModel(family, params)`` works.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.calib import kalman
from tdmon.calib.backcalc import base_friction, window_measurement
from tdmon.calib.kalman import KalmanState, Linearisation
from tdmon.calib.windows import Window
from tdmon.errors import FitError, ModelError
from tdmon.model.friction import FAMILIES, FrictionModel, evaluate_law
from tdmon.model.torque_drag import WellModel

__all__ = [
    "Identifiability",
    "MuTCalibrator",
    "MuTParametrisation",
    "MuTState",
    "family_parametrisation",
    "identifiability",
    "initial_state",
    "measurement",
    "predict",
    "scale_parametrisation",
    "update",
]

Array = NDArray[np.float64]

_Z95 = 1.959964


@dataclass(frozen=True)
class MuTParametrisation:
    """What is calibrated: a family's coefficients, or a scale on a lab fit.

    Attributes
    ----------
    names : parameter names, in the order of the state vector
    family : the family of the friction law the parameters produce
    lab : the lab fit that is scaled (scale mode), or None
    """

    names: tuple[str, ...]
    family: str
    lab: FrictionModel | None = None

    def friction_model(self, theta: ArrayLike) -> FrictionModel:
        """The friction law at parameters ``theta`` (what the model layer takes)."""
        return FrictionModel(*self._law(theta))

    def mu(self, theta: ArrayLike, temperature: ArrayLike) -> Array:
        """Friction factor [-] at ``temperature`` [degC]."""
        # the law evaluated without building its FrictionModel (the same numbers and errors)
        family, coefficients = self._law(theta)
        return evaluate_law(family, coefficients, temperature)

    def _law(self, theta: ArrayLike) -> tuple[str, dict[str, float]]:
        """The family and coefficients of the friction law at parameters ``theta``."""
        values = np.asarray(theta, dtype=np.float64)
        if self.lab is None:
            # tolist: the Python floats float() makes of each element, in one call
            return self.family, dict(zip(self.names, values.tolist(), strict=True))
        # the coefficients the family declares proportional to mu (tdmon.model.friction)
        return self.lab.family, FAMILIES[self.lab.family].scale(self.lab.coefficients,
                                                                 float(values[0]))


def family_parametrisation(model: FrictionModel) -> tuple[MuTParametrisation, Array]:
    """Calibrate every coefficient of ``model``; returns the parametrisation and its theta."""
    names = tuple(model.coefficients)
    return (MuTParametrisation(names, model.family),
            np.array([model.coefficients[n] for n in names], dtype=np.float64))


def scale_parametrisation(lab: FrictionModel) -> tuple[MuTParametrisation, Array]:
    """Calibrate one scale ``s`` on a lab fit: mu = s mu_lab(T); theta = [1]."""
    return MuTParametrisation(("scale",), lab.family, lab), np.ones(1)


@dataclass(frozen=True)
class MuTState(KalmanState):
    """Filter state: a :class:`~tdmon.calib.kalman.KalmanState` on the law's parameters, and
    the range of effective temperatures seen.

    Attributes
    ----------
    mean : parameters (also as ``theta``)
    covariance : their covariance
    updates : windows used [-]
    innovation : last measured minus predicted [N or N m]
    innovation_variance : its predicted variance
    temperature_min, temperature_max : range of the windows' effective temperatures [degC]
    """

    temperature_min: float = math.inf
    temperature_max: float = -math.inf

    @property
    def theta(self) -> Array:
        """Parameters, in the order of the parametrisation's names."""
        return self.mean


def initial_state(theta: ArrayLike, std: ArrayLike) -> MuTState:
    """Prior mean ``theta`` and independent standard deviations ``std``."""
    mean = np.asarray(theta, dtype=np.float64)
    spread = np.broadcast_to(np.asarray(std, dtype=np.float64), mean.shape)
    return MuTState(mean.copy(), np.diag(spread**2))


def predict(state: MuTState, process_std: ArrayLike = 0.0) -> MuTState:
    """Random-walk drift of the parameters between windows."""
    return kalman.predict(state, process_std)


def update(state: MuTState, measured: float, predicted: float, jacobian: Array,
           noise_variance: float, effective_temperature: float | None = None) -> MuTState:
    """Kalman update with one scalar measurement (:func:`tdmon.calib.kalman.update`); bad
    input, or a Jacobian that is all zero, keeps the prior.

    Parameters
    ----------
    state : prior
    measured, predicted : measured value and the model at the prior mean [N or N m]
    jacobian : d(predicted)/d(theta)
    noise_variance : measurement variance
    effective_temperature : the window's T_eff [degC], for the range seen
    """
    if not np.any(jacobian):
        return state
    posterior = kalman.update(state, measured, predicted, jacobian, noise_variance)
    if posterior is state:
        return state
    return _seen(posterior, effective_temperature)


def _seen(state: MuTState, effective_temperature: float | None) -> MuTState:
    """``state`` with the range of effective temperatures widened to ``effective_temperature``
    [degC] (unchanged when None or not finite)."""
    if effective_temperature is None or not math.isfinite(effective_temperature):
        return state
    return replace(state, temperature_min=min(state.temperature_min, effective_temperature),
                   temperature_max=max(state.temperature_max, effective_temperature))


def measurement(model: WellModel, parametrisation: MuTParametrisation, theta: Array,
                temperature: Array, operation: str, bit_depth: float, *,
                quantity_index: int = 0, mask: NDArray[np.bool_] | None = None,
                base_mu: float | Array = 0.0, method: str = "soft-string",
                relative_step: float = 1e-3) -> tuple[float, Array, float]:
    """Modelled value, its Jacobian in theta and the window's effective temperature.

    Parameters
    ----------
    model : prepared well
    parametrisation : what theta means
    theta : parameters
    temperature : annulus temperature per hole-grid element [degC]
    operation : model operation
    bit_depth : [m]
    quantity_index : 0 hook load, 1 torque
    mask : elements the law applies to (all when None); the others keep ``base_mu``
    base_mu : friction of the other elements [-]
    method : torque-and-drag method
    relative_step : finite-difference step relative to each parameter (absolute floor 1e-6)

    Returns
    -------
    predicted [N or N m], jacobian (len(theta),), effective temperature [degC] (nan if none)
    """
    # every friction case of the finite differences marched together, in one call: each
    # row the law (plus a bump), then, all rows at once, the other elements' friction and
    # no negative friction (per row as before, element by element: the same numbers)
    base = base_friction(base_mu, model.n_elements)
    cases = np.empty((theta.size + 3, model.n_elements))
    # the law at theta once: three of the cases bump it, not theta
    at_theta = parametrisation.mu(theta, temperature)
    np.add(at_theta, 0.0, out=cases[0])  # + 0.0 as before: -0.0 becomes 0.0
    steps = np.empty(theta.size)
    for k in range(theta.size):
        steps[k] = max(abs(theta[k]) * relative_step, 1e-6)
        bumped = theta.copy()
        bumped[k] += steps[k]
        np.add(parametrisation.mu(bumped, temperature), 0.0, out=cases[k + 1])
    delta = 1e-3
    scale = max(float(np.abs(temperature).max()), 1.0)
    np.add(at_theta, delta, out=cases[-2])
    np.add(at_theta, delta * temperature / scale, out=cases[-1])
    if mask is not None:
        cases = np.where(np.asarray(mask, dtype=bool), cases, base)
    np.maximum(cases, 0.0, out=cases)
    values = model.evaluate_cases(operation, bit_depth, cases, method=method)[quantity_index]
    predicted = float(values[0])
    jacobian = (values[1:theta.size + 1] - predicted) / steps
    uniform = float(values[-2]) - predicted
    weighted = float(values[-1]) - predicted
    effective = weighted / uniform * scale if uniform != 0.0 else math.nan
    return predicted, jacobian, effective


@dataclass(frozen=True)
class Identifiability:
    """Whether the data so far pin the temperature dependence down.

    Attributes
    ----------
    identifiable : slope interval excludes zero and the temperature range is wide enough
    slope : dmu/dT at the middle of the range seen [1/K]
    slope_std : its standard deviation [1/K]
    slope_interval : 95 % interval [1/K]
    temperature_range : (min, max) of the windows' effective temperatures [degC]
    reason : one line saying why (not)
    """

    identifiable: bool
    slope: float
    slope_std: float
    slope_interval: tuple[float, float]
    temperature_range: tuple[float, float]
    reason: str


def identifiability(parametrisation: MuTParametrisation, state: MuTState, *,
                    min_range: float = 10.0) -> Identifiability:
    """Slope dmu/dT with its interval and the effective-temperature range seen.

    Parameters
    ----------
    parametrisation, state : the calibration
    min_range : narrower ranges of T_eff [K] cannot identify a slope

    Notes
    -----
    The slope is ``(mu(T + 0.5) - mu(T - 0.5))`` at the middle of the range; its variance is
    ``g P g^T`` with ``g`` its gradient in theta (delta method). In scale mode the temperature
    dependence is the lab's and only its level is fitted.
    """
    if state.updates == 0 or not math.isfinite(state.temperature_min):
        return Identifiability(False, 0.0, 0.0, (0.0, 0.0), (0.0, 0.0), "no window used yet")
    low, high = state.temperature_min, state.temperature_max
    middle = 0.5 * (low + high)

    def slope_at(theta: Array) -> float:
        values = parametrisation.mu(theta, np.array([middle - 0.5, middle + 0.5]))
        return float(values[1] - values[0])

    try:
        slope = slope_at(state.theta)
        gradient = np.empty(state.theta.size)
        for k in range(state.theta.size):
            step = max(abs(state.theta[k]) * 1e-4, 1e-8)
            bumped = state.theta.copy()
            bumped[k] += step
            gradient[k] = (slope_at(bumped) - slope) / step
    except ModelError as exc:
        return Identifiability(False, 0.0, 0.0, (0.0, 0.0), (low, high),
                               f"the law is not defined over the range seen: {exc}")
    std = math.sqrt(max(float(gradient @ state.covariance @ gradient), 0.0))
    interval = (slope - _Z95 * std, slope + _Z95 * std)
    if parametrisation.lab is not None:
        reason, ok = "scale mode: the temperature dependence is the lab fit's, only its level " \
                     "is calibrated", False
    elif high - low < min_range:
        reason, ok = (f"the temperature range seen, {high - low:.1f} K, is narrower than the "
                      f"{min_range:g} K needed"), False
    elif interval[0] <= 0.0 <= interval[1]:
        reason, ok = "the slope's 95 % interval includes zero", False
    else:
        reason, ok = (f"slope {slope:.3g} 1/K, 95 % interval {interval[0]:.3g}.."
                      f"{interval[1]:.3g}, over {high - low:.1f} K"), True
    return Identifiability(bool(ok), slope, std, interval, (low, high), reason)


@dataclass(frozen=True)
class _WindowLinearisation(Linearisation):
    """A window's measurement linearised at an iterate, with its effective temperature."""

    effective_temperature: float = math.nan


class MuTCalibrator:
    """The live mu(T) calibration: feed windows, read parameters and identifiability.

    Parameters
    ----------
    model : prepared well
    temperature : annulus temperature per hole-grid element [degC]
    prior : the configured law (family mode) or the lab fit (scale mode)
    mode : ``"family"`` or ``"scale"``
    prior_std : standard deviation of each parameter (default: max(|theta|, 0.01))
    mask, base_mu : elements the law applies to, and the friction of the others
    process_std : drift per window
    model_std_fraction : model error per window, relative to the friction part of the value
    method : torque-and-drag method
    """

    def __init__(self, model: WellModel, temperature: ArrayLike, prior: FrictionModel, *,
                 mode: str = "family", prior_std: ArrayLike | None = None,
                 mask: NDArray[np.bool_] | None = None, base_mu: float | Array = 0.0,
                 process_std: ArrayLike = 0.0, model_std_fraction: float = 0.0,
                 method: str = "soft-string") -> None:
        if mode not in ("family", "scale"):
            raise FitError(f"mu(T) calibration mode must be 'family' or 'scale', got {mode!r}")
        self.model = model
        self.temperature = np.asarray(temperature, dtype=np.float64)
        if self.temperature.shape != (model.n_elements,) or not np.isfinite(
                self.temperature).all():
            raise FitError("need one finite annulus temperature per hole-grid element")
        self.parametrisation, theta = (family_parametrisation(prior) if mode == "family"
                                       else scale_parametrisation(prior))
        spread = (np.maximum(np.abs(theta), 0.01) if prior_std is None
                  else np.asarray(prior_std, dtype=np.float64))
        self.state = initial_state(theta, spread)
        self.mask = mask
        self.base_mu = base_mu
        self.process_std = process_std
        self.model_std_fraction = model_std_fraction
        self.method = method

    def add_window(self, window: Window, *, iterations: int = 3) -> bool:
        """Update with one window; False when it cannot be used (state unchanged).

        Iterated EKF (:func:`tdmon.calib.kalman.iterated_update`), without gating; the range
        of effective temperatures takes the last iterate's T_eff.
        """
        observed = window_measurement(window)
        if observed is None:
            return False
        operation, index = observed.operation, observed.quantity_index

        def linearise(estimate: Array) -> _WindowLinearisation:
            predicted, jacobian, t_eff = measurement(
                self.model, self.parametrisation, estimate, self.temperature, operation,
                window.bit_depth, quantity_index=index, mask=self.mask,
                base_mu=self.base_mu, method=self.method)
            noise = kalman.noise_with_model_error(observed.standard_error,
                                                  self.model_std_fraction, jacobian, estimate)
            return _WindowLinearisation(predicted, jacobian, noise, t_eff)

        try:
            result = kalman.iterated_update(predict(self.state, self.process_std),
                                            observed.value, linearise, iterations=iterations)
        except ModelError:
            return False
        if not result.accepted or not np.isfinite(result.state.theta).all():
            return False
        assert result.linearisation is not None  # accepted: linearised at least once
        self.state = _seen(result.state, result.linearisation.effective_temperature)
        return True

    @property
    def params(self) -> dict[str, float]:
        """Calibrated coefficients, keyed like the family's arguments."""
        return dict(self.friction_model().coefficients)

    def friction_model(self) -> FrictionModel:
        """The calibrated law, as the model layer takes it."""
        return self.parametrisation.friction_model(self.state.theta)

    def mu_at(self, temperature: float) -> tuple[float, float]:
        """Calibrated friction [-] at ``temperature`` [degC] and its standard deviation [-]."""
        theta = self.state.theta
        value = float(self.parametrisation.mu(theta, temperature))
        gradient = np.empty(theta.size)
        for k in range(theta.size):
            step = max(abs(theta[k]) * 1e-4, 1e-8)
            bumped = theta.copy()
            bumped[k] += step
            gradient[k] = (float(self.parametrisation.mu(bumped, temperature)) - value) / step
        return value, math.sqrt(max(float(gradient @ self.state.covariance @ gradient), 0.0))

    def message_fields(self) -> dict[str, object]:
        """``estimate`` fields of kind ``mu_T`` (``mu``/``mu_std`` at the middle of the
        temperature range seen; finite numbers only)."""
        ident = identifiability(self.parametrisation, self.state)
        std = self.state.std
        middle = (0.5 * (ident.temperature_range[0] + ident.temperature_range[1])
                  if ident.temperature_range != (0.0, 0.0) else 50.0)
        try:
            mu_middle, mu_std = self.mu_at(middle)
        except ModelError:
            mu_middle, mu_std = 0.0, 0.0
        return {
            "mu": mu_middle,
            "mu_std": mu_std,
            "model": self.friction_model().describe(),
            "params": {k: float(v) for k, v in zip(self.parametrisation.names,
                                                   self.state.theta, strict=True)},
            "params_std": {k: float(v) for k, v in zip(self.parametrisation.names, std,
                                                       strict=True)},
            "mu_at_temperature_C": middle,
            "temperature_C": [float(ident.temperature_range[0]),
                              float(ident.temperature_range[1])],
            "slope_per_K": ident.slope,
            "slope_std_per_K": ident.slope_std,
            "slope_interval_per_K": [ident.slope_interval[0], ident.slope_interval[1]],
            "identifiable": bool(ident.identifiable),
            "identifiability": ident.reason,
        }
