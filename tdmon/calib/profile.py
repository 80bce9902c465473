"""Local friction profile along MD: an extended Kalman filter on friction per depth bin.

State: the friction factor of each depth bin, mu_k, with covariance P. Each steady window is a
measurement of the hook load (or torque) h(mu) of its operation at its bit depth; its Jacobian
``H_k = dh/dmu_k`` is the sum over the bin's elements of the model's adjoint gradient
(`WellModel.evaluate_gradient`: one march up and one sweep back, whatever the number of bins).
A window sees the friction of every bin along the string at once; what locates friction along
the hole is the sequence of bit depths: once the bit has passed above a stretch, later windows
no longer see it, and the filter's cross-covariances move the part of the earlier misfit that
the shallower bins cannot explain onto the bins the bit has left.

Between windows friction may drift (cuttings beds build up, mud changes): ``predict`` adds
process noise. Pure ``predict``/``update`` on a frozen :class:`ProfileState` (STYLE.md item 6),
with the innovation and its variance kept for diagnostics; :class:`FrictionProfile` is the thin
stateful wrapper the daemon uses.

References
----------
.. [1] Simon, D. (2006). Optimal State Estimation, ch. 13 (extended Kalman filter).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.backcalc import window_measurement
from tdmon.calib.windows import Window
from tdmon.errors import FitError, ModelError
from tdmon.model.torque_drag import WellModel

__all__ = [
    "FrictionProfile",
    "ProfileGrid",
    "ProfileState",
    "initial_state",
    "measurement_jacobian",
    "predict",
    "profile_grid",
    "update",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ProfileGrid:
    """Depth bins of the profile.

    Attributes
    ----------
    edges : bin edges in MD, top down [m], shape (n_bins + 1,)
    element_bin : bin index of every hole-grid element, shape (n_elements,)
    """

    edges: Array
    element_bin: NDArray[np.int64]

    @property
    def n_bins(self) -> int:
        return int(self.edges.size - 1)

    @property
    def mid_md(self) -> Array:
        """Bin midpoints [m]."""
        return np.asarray(0.5 * (self.edges[:-1] + self.edges[1:]))


def profile_grid(model: WellModel, bin_length: float) -> ProfileGrid:
    """Bins of ``bin_length`` [m] from the top to the bottom of the hole."""
    if not (math.isfinite(bin_length) and bin_length > 0.0):
        raise FitError(f"profile bin length must be > 0, got {bin_length}")
    top, bottom = float(model.grid.md[0]), float(model.grid.md[-1])
    n = max(1, math.ceil((bottom - top) / bin_length - 1e-9))
    edges = np.minimum(top + bin_length * np.arange(n + 1, dtype=np.float64), bottom)
    edges[-1] = bottom
    index = np.clip(np.searchsorted(edges, model.grid.element_mid_md, side="right") - 1, 0, n - 1)
    return ProfileGrid(edges, index.astype(np.int64))


@dataclass(frozen=True)
class ProfileState:
    """Filter state.

    Attributes
    ----------
    mu : friction per bin [-]
    covariance : its covariance [-^2]
    updates : windows used so far [-]
    innovation : last measured minus predicted value [N or N m] (0 before the first update)
    innovation_variance : its predicted variance [N^2 or (N m)^2]
    """

    mu: Array
    covariance: Array
    updates: int = 0
    innovation: float = 0.0
    innovation_variance: float = 0.0

    @property
    def std(self) -> Array:
        """Standard deviation per bin [-]."""
        return np.sqrt(np.maximum(np.diag(self.covariance), 0.0))


def initial_state(grid: ProfileGrid, mu: float, std: float) -> ProfileState:
    """Prior: ``mu`` [-] in every bin, independent, standard deviation ``std`` [-]."""
    return ProfileState(np.full(grid.n_bins, float(mu)), np.eye(grid.n_bins) * std**2)


def predict(state: ProfileState, process_std: float) -> ProfileState:
    """Random-walk drift of every bin between windows: ``P += q^2 I``, ``q`` [-]."""
    covariance = state.covariance + np.eye(state.mu.size) * process_std**2
    return replace(state, covariance=covariance)


def update(state: ProfileState, measured: float, predicted: float, jacobian: Array,
           noise_variance: float, *, mu_bounds: tuple[float, float] = (0.0, 1.5)
           ) -> ProfileState:
    """Kalman update with one scalar measurement.

    Parameters
    ----------
    state : prior
    measured : measured hook load [N] or torque [N m]; non-finite keeps the prior
    predicted : model value at the prior mean [N or N m]
    jacobian : d(predicted)/d(mu per bin), shape (n_bins,)
    noise_variance : measurement variance [N^2 or (N m)^2]
    mu_bounds : the posterior mean is clipped to these [-] (friction cannot be negative)

    Returns
    -------
    ProfileState

    Notes
    -----
    ``S = H P H^T + R``, ``K = P H^T / S``, ``mu += K (z - h)``, ``P = (I - K H) P (I - K H)^T
    + K R K^T`` (Joseph form, which keeps P symmetric and positive).
    """
    h = np.asarray(jacobian, dtype=np.float64)
    if not (math.isfinite(measured) and math.isfinite(predicted) and np.isfinite(h).all()
            and math.isfinite(noise_variance) and noise_variance > 0.0):
        return state
    p = state.covariance
    ph = p @ h
    s = float(h @ ph) + noise_variance
    gain = ph / s
    innovation = measured - predicted
    mu = np.clip(state.mu + gain * innovation, *mu_bounds)
    a = np.eye(mu.size) - np.outer(gain, h)
    covariance = a @ p @ a.T + noise_variance * np.outer(gain, gain)
    covariance = 0.5 * (covariance + covariance.T)
    return ProfileState(mu, covariance, state.updates + 1, float(innovation), s)


def measurement_jacobian(model: WellModel, grid: ProfileGrid, mu_bins: Array, operation: str,
                         bit_depth: float, *, quantity_index: int = 0,
                         method: str = "soft-string") -> tuple[float, Array]:
    """Modelled value and its derivative with respect to each bin's friction.

    Parameters
    ----------
    model : prepared well
    grid : the profile's bins
    mu_bins : friction per bin [-] (negative values are taken as 0)
    operation : model operation
    bit_depth : [m]
    quantity_index : 0 hook load, 1 surface torque
    method : torque-and-drag method

    Returns
    -------
    predicted : [N or N m]
    jacobian : shape (n_bins,) [N or N m]; 0 for bins wholly below the bit

    Notes
    -----
    ``H_k = sum over the elements e of bin k of dh/dmu_e``, the element gradient coming from the
    model's adjoint (`WellModel.evaluate_gradient`), exact to rounding where the forward
    differences used before had an error of the order of their step.
    """
    friction = np.maximum(mu_bins[grid.element_bin], 0.0)
    predicted, gradient = model.evaluate_gradient(operation, bit_depth, friction,
                                                  quantity_index=quantity_index, method=method)
    jacobian = np.asarray(np.bincount(grid.element_bin, weights=gradient,
                                      minlength=grid.n_bins), dtype=np.float64)
    jacobian[grid.edges[:-1] >= bit_depth] = 0.0
    return predicted, jacobian


class FrictionProfile:
    """The live profile: hold the model, the bins and the filter state; feed windows.

    Parameters
    ----------
    model : prepared well
    bin_length : [m]
    prior_mu, prior_std : prior friction and its standard deviation per bin [-]
    process_std : drift per window [-]
    model_std_fraction : model error added to each window's variance, as a fraction of the
        friction part of the modelled value (keeps a long session from over-trusting the model)
    method : torque-and-drag method
    gate : a window whose innovation exceeds ``gate`` of its predicted standard deviation is
        left out (counted in ``gated``) [-]
    """

    def __init__(self, model: WellModel, *, bin_length: float = 30.0, prior_mu: float = 0.25,
                 prior_std: float = 0.1, process_std: float = 0.002,
                 model_std_fraction: float = 0.0, method: str = "soft-string",
                 gate: float = 4.0) -> None:
        self.model = model
        self.gate = gate
        self.gated = 0
        self.grid = profile_grid(model, bin_length)
        self.state = initial_state(self.grid, prior_mu, prior_std)
        self.process_std = process_std
        self.model_std_fraction = model_std_fraction
        self.method = method

    def add_window(self, window: Window, *, iterations: int = 2) -> bool:
        """Update with one window; False when the window cannot be used (state unchanged).

        Iterated EKF: the Jacobian is re-evaluated at the updated mean ``iterations`` times,
        which removes most of the linearisation error of the capstan term.
        """
        observed = window_measurement(window)
        if observed is None:
            return False
        operation, index = observed.operation, observed.quantity_index
        measured, se = observed.value, observed.standard_error
        prior = predict(self.state, self.process_std)
        estimate = prior.mu
        try:
            for _ in range(max(1, iterations)):
                predicted, jacobian = measurement_jacobian(
                    self.model, self.grid, estimate, operation, window.bit_depth,
                    quantity_index=index, method=self.method)
                if not np.any(jacobian):
                    return False
                # linearise about the current iterate, not the prior mean
                predicted_at_prior = predicted + float(jacobian @ (prior.mu - estimate))
                friction_part = abs(float(jacobian @ estimate))
                noise = se**2 + (self.model_std_fraction * friction_part) ** 2
                posterior = update(prior, measured, predicted_at_prior, jacobian,
                                   max(noise, 1e-12))
                if posterior.innovation**2 > self.gate**2 * posterior.innovation_variance:
                    # an overpull at a tight spot or a set-down is not friction along the
                    # string: a window this far from what the filter expects is left out
                    self.gated += 1
                    return False
                estimate = posterior.mu
        except ModelError:
            return False
        self.state = posterior
        return True

    def message_fields(self) -> dict[str, object]:
        """``estimate`` message fields of kind ``profile`` (finite numbers only)."""
        std = self.state.std
        return {
            "md_m": [float(x) for x in self.grid.mid_md],
            "mu_profile": [float(x) for x in self.state.mu],
            "mu_profile_std": [float(x) for x in std],
            "innovation": float(self.state.innovation),
            "innovation_std": float(math.sqrt(max(self.state.innovation_variance, 0.0))),
        }
