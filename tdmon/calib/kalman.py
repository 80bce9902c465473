"""Kalman filter for a Gaussian state and scalar measurements, shared by the estimators.

A :class:`KalmanState` holds the mean and covariance of a state vector and, for diagnostics, the
innovation of its last update and that innovation's predicted variance. The functions are pure
(``update(state, z, ...) -> state``, in the manner of filterpy) and keep the state's type: the
friction profile along MD (:mod:`tdmon.calib.profile`) and the mu(T) calibration
(:mod:`tdmon.calib.mu_calibration`) subclass :class:`KalmanState` with their own names and fields,
and what comes back from here is of their class.

- :func:`predict`: random-walk drift between measurements.
- :func:`update`: one scalar measurement, Joseph form.
- :func:`iterated_update`: the iterated extended Kalman filter for one nonlinear scalar
  measurement, with optional gating by the normalised innovation.
- :func:`update_batch`: several linear scalar measurements with independent errors at once.

References
----------
.. [1] Simon, D. (2006). Optimal State Estimation. Wiley. Ch. 5 (Joseph form), ch. 6
   (sequential processing of measurements), ch. 13 (extended and iterated extended Kalman
   filter).
.. [2] Bell, B. M. and Cathey, F. W. (1993). The iterated Kalman filter update as a Gauss-Newton
   method. IEEE Transactions on Automatic Control 38(2), 294-297.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Generic, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "IteratedUpdate",
    "KalmanState",
    "Linearisation",
    "iterated_update",
    "noise_with_model_error",
    "predict",
    "update",
    "update_batch",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class KalmanState:
    """Mean and covariance of the state, and the last update's innovation.

    Attributes
    ----------
    mean : state mean, shape (n,) [units of the state]
    covariance : its covariance, shape (n, n) [units of the state squared]
    updates : measurements used so far [-]
    innovation : last measured minus predicted value [units of the measurement] (0 before the
        first update)
    innovation_variance : its predicted variance ``H P H^T + R`` [units of the measurement
        squared]
    """

    mean: Array
    covariance: Array
    updates: int = 0
    innovation: float = 0.0
    innovation_variance: float = 0.0

    @property
    def std(self) -> Array:
        """Standard deviation of each state component [units of the state]."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))


S = TypeVar("S", bound=KalmanState)


def predict(state: S, process_std: ArrayLike) -> S:
    """Random-walk drift between measurements: ``P += diag(q^2)``.

    Parameters
    ----------
    state : the state before the drift
    process_std : standard deviation ``q`` of the drift of each component, or one for all
        [units of the state]
    """
    q = np.asarray(process_std, dtype=np.float64)
    if q.ndim and q.shape != state.mean.shape:
        # one for all adds itself to every diagonal element as it is: np.broadcast_to (~2 us,
        # more than the rest for the joint estimate's 2 x 2) only checks and spreads a vector
        q = np.broadcast_to(q, state.mean.shape)
    # P + diag(q^2) without the n x n diagonal matrix: adding 0.0 copies P as the zeros off the
    # diagonal would (-0.0 becomes 0.0), then the diagonal takes q^2
    covariance = state.covariance + 0.0
    covariance.flat[::state.mean.size + 1] += q**2
    return replace(state, covariance=covariance)


#: A state of more components than this takes the Joseph form multiplied out, O(n^2) (the
#: friction profile's ~140 bins: 100 instead of 340 us an update; its numbers move by 1e-13
#: relative, docs/benchmarks.md). The small filters (mu(T) with its two badly scaled
#: parameters, the joint estimate) keep the two matrix products, whose rounding they need.
_EXPANDED_FROM = 16


def update(state: S, measured: float, predicted: float, jacobian: ArrayLike,
           noise_variance: float, *, bounds: tuple[ArrayLike, ArrayLike] | None = None) -> S:
    """Kalman update with one scalar measurement, Joseph form; bad input returns ``state``.

    Parameters
    ----------
    state : prior
    measured : the measurement ``z`` [units of the measurement]; non-finite keeps the prior
    predicted : the measurement model at the prior mean, ``h(x)`` [units of the measurement]
    jacobian : ``H = dh/dx``, shape (n,) [units of the measurement per unit of the state]
    noise_variance : measurement variance ``R`` > 0 [units of the measurement squared]
    bounds : the posterior mean is clipped to these, one for all components or one per
        component [units of the state] (None: not clipped)

    Returns
    -------
    The posterior, of the class of ``state`` (its other fields unchanged); ``state`` itself when
    an input is not finite or ``R`` is not positive.

    Notes
    -----
    ``S = H P H^T + R``, ``K = P H^T / S``, ``x += K (z - h)``,
    ``P = (I - K H) P (I - K H)^T + K R K^T`` (Joseph form, [1]_ ch. 5: P stays symmetric and
    positive where the short form ``(I - K H) P`` loses both to rounding), symmetrised. For
    more than ``_EXPANDED_FROM`` components the same expression multiplied out,
    ``P - K (P H^T)^T - (P H^T) K^T + S K K^T``, true for any gain, in O(n^2) instead of the
    products' O(n^3).
    """
    h = np.asarray(jacobian, dtype=np.float64)
    step = _mean_step(state, measured, predicted, h, noise_variance, bounds)
    if step is None:
        return state
    mean, gain, innovation, s, ph = step
    # outer products by broadcasting: np.outer's products without its wrapper (~2 us a call)
    column = gain[:, np.newaxis]
    if h.size > _EXPANDED_FROM:
        # ``P - K (P H^T)^T - (P H^T) K^T + S K K^T`` left to right, as written, the steps
        # after the first in place (no new n x n array each: 141 bins, ~74 -> ~69 us)
        cross = column * ph  # K (P H^T)^T
        covariance = state.covariance - cross
        covariance -= cross.T
        outer = column * gain
        outer *= s
        covariance += outer
    else:
        a = np.eye(h.size) - column * h
        covariance = a @ state.covariance @ a.T + noise_variance * (column * gain)
    symmetric = covariance + covariance.T
    symmetric *= 0.5
    return replace(state, mean=mean, covariance=symmetric, updates=state.updates + 1,
                   innovation=innovation, innovation_variance=s)


def _mean_step(state: KalmanState, measured: float, predicted: float, h: Array,
               noise_variance: float, bounds: tuple[ArrayLike, ArrayLike] | None
               ) -> tuple[Array, Array, float, float, Array] | None:
    """The first half of :func:`update`: (posterior mean, gain, innovation, its variance,
    ``P H^T``), or None where :func:`update` keeps the prior. The covariance, the costly half
    (two products of n x n matrices), is left to the caller: an iterate of
    :func:`iterated_update` before the last needs the mean alone."""
    if not (math.isfinite(measured) and math.isfinite(predicted) and np.isfinite(h).all()
            and math.isfinite(noise_variance) and noise_variance > 0.0):
        return None
    ph = state.covariance @ h
    s = float(h @ ph) + noise_variance
    gain = ph / s
    innovation = measured - predicted
    mean = state.mean + gain * innovation
    if bounds is not None:
        mean = mean.clip(*bounds)  # np.clip calls this method, after a wrapper of ~1 us
    return mean, gain, float(innovation), s, ph


def noise_with_model_error(standard_error: float, model_std_fraction: float, jacobian: Array,
                           estimate: Array, *, floor: float = 1e-12) -> float:
    """Measurement variance plus a model error proportional to the state's part of the value.

    ``R = se^2 + (f |H x|)^2``, at least ``floor``: ``H x`` is the part of the predicted value
    that is linear in the state (the friction part of a hook load or torque), and a model
    error relative to it keeps a long session from over-trusting the model.

    Parameters
    ----------
    standard_error : of the measurement [units of the measurement]
    model_std_fraction : ``f`` [-]
    jacobian : ``H`` at ``estimate``, shape (n,)
    estimate : the state ``x`` the measurement is linearised about, shape (n,)
    floor : smallest variance returned [units of the measurement squared]
    """
    state_part = abs(float(jacobian @ estimate))
    return max(standard_error**2 + (model_std_fraction * state_part) ** 2, floor)


@dataclass(frozen=True)
class Linearisation:
    """The measurement model linearised at an iterate ``x_i``.

    Attributes
    ----------
    predicted : ``h(x_i)`` [units of the measurement]
    jacobian : ``dh/dx`` at ``x_i``, shape (n,)
    noise_variance : measurement variance ``R`` to use at ``x_i`` [units of the measurement
        squared]
    """

    predicted: float
    jacobian: Array
    noise_variance: float


L = TypeVar("L", bound=Linearisation)


@dataclass(frozen=True)
class IteratedUpdate(Generic[S, L]):
    """Outcome of :func:`iterated_update`.

    Attributes
    ----------
    state : the posterior when accepted, else the prior
    accepted : the measurement was used
    gated : it was left out because its innovation exceeded the gate
    linearisation : the measurement model at the last iterate (None if none was evaluated)
    """

    state: S
    accepted: bool
    gated: bool = False
    linearisation: L | None = None


def iterated_update(prior: S, measured: float, linearise: Callable[[Array], L], *,
                    iterations: int = 1, gate: float | None = None,
                    bounds: tuple[ArrayLike, ArrayLike] | None = None) -> IteratedUpdate[S, L]:
    """Iterated extended Kalman update with one nonlinear scalar measurement.

    Parameters
    ----------
    prior : the state before the measurement
    measured : the measurement ``z`` [units of the measurement]
    linearise : ``x_i -> Linearisation`` (``h(x_i)``, ``H_i``, ``R``) at an iterate; may be a
        subclass carrying more (it is handed back with the result)
    iterations : linearisations (at least 1; 1 is the ordinary extended Kalman filter)
    gate : leave the measurement out when, at any iterate, ``innovation^2 > gate^2 S`` with
        ``S`` the innovation variance (None: no gating) [-]
    bounds : the mean is clipped to these at every iterate (see :func:`update`)

    Returns
    -------
    IteratedUpdate
        Not accepted (and the prior kept) when the Jacobian is all zero (the measurement does
        not see the state), :func:`update` rejects the input, or the gate closes.

    Notes
    -----
    Each iterate ``x_i`` (``x_0`` the prior mean) relinearises the measurement:
    ``h(x) ~ h(x_i) + H_i (x - x_i)``, so the update from the prior uses the prediction
    ``h(x_i) + H_i (x_0 - x_i)`` at the prior mean, and the posterior mean becomes ``x_{i+1}``.
    The covariance is the last iterate's. This is Gauss-Newton on the MAP problem [2]_ and
    removes most of the linearisation error of a strongly curved ``h`` (the capstan term of a
    hook load).
    """
    estimate = prior.mean
    posterior = prior
    linearisation: L | None = None
    last = max(1, iterations) - 1
    for iterate in range(last + 1):
        linearisation = linearise(estimate)
        h = linearisation.jacobian
        if not np.asarray(h).any():  # the method: np.any's dispatch costs more than the test
            return IteratedUpdate(prior, False, linearisation=linearisation)
        # linearise about the current iterate, not the prior mean
        predicted_at_prior = linearisation.predicted + float(h @ (prior.mean - estimate))
        if iterate < last:
            # only the last iterate's covariance is kept: the others need their mean (and the
            # gate its innovation), which is update's own first half, so the same numbers
            step = _mean_step(prior, measured, predicted_at_prior,
                              np.asarray(h, dtype=np.float64), linearisation.noise_variance,
                              bounds)
            if step is None:
                return IteratedUpdate(prior, False, linearisation=linearisation)
            estimate, _, innovation, variance, _ = step
        else:
            posterior = update(prior, measured, predicted_at_prior, h,
                               linearisation.noise_variance, bounds=bounds)
            if posterior is prior:
                return IteratedUpdate(prior, False, linearisation=linearisation)
            innovation, variance = posterior.innovation, posterior.innovation_variance
        if gate is not None and innovation**2 > gate**2 * variance:
            return IteratedUpdate(prior, False, gated=True, linearisation=linearisation)
    return IteratedUpdate(posterior, True, linearisation=linearisation)


def update_batch(state: S, measured: ArrayLike, predicted: ArrayLike, jacobian: ArrayLike,
                 noise_variance: ArrayLike, *,
                 bounds: tuple[ArrayLike, ArrayLike] | None = None) -> S:
    """Update with several linear scalar measurements whose errors are independent.

    Parameters
    ----------
    state : prior
    measured : the measurements, shape (m,) [units of each measurement]
    predicted : the measurement model at the prior mean, shape (m,)
    jacobian : one row ``H_j`` per measurement, shape (m, n)
    noise_variance : variance of each measurement, shape (m,) or one for all
    bounds : the mean is clipped to these after every measurement (see :func:`update`)

    Returns
    -------
    The posterior; ``updates`` counts the measurements used, ``innovation`` and
    ``innovation_variance`` are the last used one's. Measurements :func:`update` rejects (not
    finite, variance not positive) are skipped.

    Notes
    -----
    With independent errors the joint update equals the sequence of scalar updates ([1]_,
    ch. 6), which needs no matrix inverse. Each measurement's prediction is moved to the
    current mean along its row, ``h_j + H_j (x - x_0)``: the model is taken as linear, so for a
    nonlinear one relinearise and call :func:`iterated_update` per measurement instead.
    """
    z = np.atleast_1d(np.asarray(measured, dtype=np.float64))
    h0 = np.broadcast_to(np.asarray(predicted, dtype=np.float64), z.shape)
    rows = np.asarray(jacobian, dtype=np.float64).reshape(z.size, state.mean.size)
    r = np.broadcast_to(np.asarray(noise_variance, dtype=np.float64), z.shape)
    x0 = state.mean
    posterior = state
    for j in range(z.size):
        predicted_now = float(h0[j]) + float(rows[j] @ (posterior.mean - x0))
        posterior = update(posterior, float(z[j]), predicted_now, rows[j], float(r[j]),
                           bounds=bounds)
    return posterior
