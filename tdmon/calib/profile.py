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
process noise. Pure ``predict``/``update`` on a frozen :class:`ProfileState`, with the innovation
and its variance kept for diagnostics; the filter itself (Joseph-form update, iterated EKF,
gating) is :mod:`tdmon.calib.kalman`. :class:`FrictionProfile` is the thin stateful wrapper the
daemon uses.

References
----------
.. [1] Simon, D. (2006). Optimal State Estimation, ch. 13 (extended Kalman filter).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.calib import kalman
from tdmon.calib.backcalc import window_measurement
from tdmon.calib.kalman import KalmanState, Linearisation
from tdmon.calib.windows import Window
from tdmon.errors import FitError, ModelError
from tdmon.model.torque_drag import WellModel

__all__ = [
    "INFORMED_RATIO",
    "BinInformation",
    "FrictionProfile",
    "ProfileGrid",
    "ProfileState",
    "describe_information",
    "information",
    "initial_state",
    "measurement_jacobian",
    "predict",
    "profile_grid",
    "update",
]

Array = NDArray[np.float64]

#: the filter's mean is clipped to these [-]: friction cannot be negative
_MU_BOUNDS = (0.0, 1.5)

#: a bin is *informed* when its variance is below this fraction of the variance it would have
#: had without any window [-]: the windows then carry at least as much about it as the prior
#: (a posterior standard deviation at most 71 % of the prior's)
INFORMED_RATIO = 0.5

# why a bin is not informed (docs/back-calculation.md, "What the profile knows")
NO_WINDOW_YET = "no window used yet"
NOT_REACHED = "no window reached this depth"
NO_CONTACT = "near-vertical hole: no side force"
NOT_SEPARATED = "seen only with the string above it: too little bit travel"


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


def describe_information(md: Sequence[float], informed: Sequence[bool] | None,
                         reasons: Sequence[str | None] | None) -> str:
    """One line for a reader: how many profile points are informed and, by depth range, why the
    others are not, e.g. ``"12 of 40 points informed; not informed: 2400-3990 m no window
    reached this depth"`` (empty when ``informed`` is None: the message predates the field).

    Parameters
    ----------
    md : MD of the points [m]
    informed : per point (see :func:`information`)
    reasons : per point, why it is not informed (None where informed)
    """
    if informed is None or len(informed) != len(md):
        return ""
    why = list(reasons) if reasons is not None and len(reasons) == len(md) else [None] * len(md)
    count = sum(bool(x) for x in informed)
    runs: list[tuple[float, float, str]] = []
    for depth, known, reason in zip(md, informed, why, strict=True):
        if known:
            continue
        text = reason or "not informed"
        if runs and runs[-1][2] == text:
            runs[-1] = (runs[-1][0], float(depth), text)
        else:
            runs.append((float(depth), float(depth), text))
    head = f"{count} of {len(md)} points informed (variance ratio < {INFORMED_RATIO:g})"
    if not runs:
        return head
    parts = [f"{top:.0f}-{bottom:.0f} m {text}" if bottom > top else f"{top:.0f} m {text}"
             for top, bottom, text in runs[:_MAX_RUNS]]
    if len(runs) > _MAX_RUNS:
        parts.append(f"and {len(runs) - _MAX_RUNS} more stretches")
    return f"{head}; not informed: " + "; ".join(parts)


# depth ranges named by describe_information before it stops (one line stays readable)
_MAX_RUNS = 6


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
class ProfileState(KalmanState):
    """Filter state: a :class:`~tdmon.calib.kalman.KalmanState` on the friction per bin.

    Attributes
    ----------
    mean : friction per bin [-] (also as ``mu``)
    covariance : its covariance [-^2]
    updates : windows used so far [-]
    innovation : last measured minus predicted value [N or N m] (0 before the first update)
    innovation_variance : its predicted variance [N^2 or (N m)^2]
    reference_variance : the variance each bin would have had without any window, the prior
        plus the drift added since [-^2] (empty: taken as the diagonal of ``covariance``)
    windows_seen : per bin, the windows used whose measurement depended on it [-]
    deepest : the deepest bit depth of a window used [m] (-inf before the first)
    """

    reference_variance: Array = field(default_factory=lambda: np.zeros(0))
    windows_seen: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    deepest: float = -math.inf

    @property
    def mu(self) -> Array:
        """Friction per bin [-]."""
        return self.mean


def initial_state(grid: ProfileGrid, mu: float, std: float) -> ProfileState:
    """Prior: ``mu`` [-] in every bin, independent, standard deviation ``std`` [-]."""
    return ProfileState(np.full(grid.n_bins, float(mu)), np.eye(grid.n_bins) * std**2,
                        reference_variance=np.full(grid.n_bins, float(std) ** 2),
                        windows_seen=np.zeros(grid.n_bins, np.int64))


def predict(state: ProfileState, process_std: float) -> ProfileState:
    """Random-walk drift of every bin between windows: ``P += q^2 I``, ``q`` [-] (the
    reference variance of :func:`information` drifts with it)."""
    drifted = kalman.predict(state, process_std)
    if state.reference_variance.size != state.mean.size:
        return drifted
    return replace(drifted, reference_variance=state.reference_variance + process_std**2)


@dataclass(frozen=True)
class BinInformation:
    """What the windows have taught the profile about each bin.

    Attributes
    ----------
    variance_ratio : posterior variance over the variance the bin would have without any
        window (prior plus drift) [-]: 1 nothing learned, towards 0 well informed
    informed : ``variance_ratio < threshold``
    reason : why a bin is not informed (None for an informed bin)
    """

    variance_ratio: Array
    informed: NDArray[np.bool_]
    reason: tuple[str | None, ...]


def information(state: ProfileState, edges: Array, threshold: float = INFORMED_RATIO
                ) -> BinInformation:
    """Per bin: the variance ratio, whether it is informed, and why not.

    Parameters
    ----------
    state : the filter state
    edges : the bins' edges in MD, top down [m]
    threshold : a bin with a smaller variance ratio is informed [-]

    Notes
    -----
    The ratio compares the posterior variance with the prior's plus the drift added since, so
    that a bin no window depends on keeps exactly 1 however long the session. A bin is not
    informed because no window was used yet, because every window's bit stayed above it, because
    the hole there is vertical (no side force: friction does not change the loads), or because
    the windows saw it only through the friction of the whole string above the bit (the bit has
    not travelled far enough for the filter to tell it from its neighbours).
    """
    variance = np.diag(state.covariance)
    reference = (state.reference_variance if state.reference_variance.size == variance.size
                 else variance)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(reference > 0.0, variance / reference, 1.0)
    ratio = np.clip(ratio, 0.0, None)
    informed = ratio < threshold
    seen = (state.windows_seen if state.windows_seen.size == variance.size
            else np.zeros(variance.size, np.int64))
    reasons: list[str | None] = []
    # Python lists: indexing the arrays bin by bin cost more than the rest of this
    informed_list, seen_list = informed.tolist(), seen.tolist()
    edge_list = np.asarray(edges).tolist()
    for k in range(variance.size):
        if informed_list[k]:
            reasons.append(None)
        elif state.updates == 0:
            reasons.append(NO_WINDOW_YET)
        elif seen_list[k] > 0:
            reasons.append(NOT_SEPARATED)
        elif edge_list[k] >= state.deepest:
            reasons.append(NOT_REACHED)
        else:
            reasons.append(NO_CONTACT)
    return BinInformation(np.asarray(ratio, dtype=np.float64), np.asarray(informed),
                          tuple(reasons))


def update(state: ProfileState, measured: float, predicted: float, jacobian: Array,
           noise_variance: float, *, mu_bounds: tuple[float, float] = _MU_BOUNDS
           ) -> ProfileState:
    """Kalman update with one scalar measurement (:func:`tdmon.calib.kalman.update`).

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
    """
    return kalman.update(state, measured, predicted, jacobian, noise_variance, bounds=mu_bounds)


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
        # `information` of the last state asked about: the estimator's message and the profile
        # step's both ask after an update (a copy of this object shares it, keyed by the state)
        self._information: tuple[ProfileState, BinInformation] | None = None

    def add_window(self, window: Window, *, iterations: int = 2) -> bool:
        """Update with one window; False when the window cannot be used (state unchanged).

        Iterated EKF (:func:`tdmon.calib.kalman.iterated_update`): the Jacobian is re-evaluated
        at the updated mean ``iterations`` times, which removes most of the linearisation error
        of the capstan term. An overpull at a tight spot or a set-down is not friction along
        the string: a window further than ``gate`` from what the filter expects is left out.
        """
        observed = window_measurement(window)
        if observed is None:
            return False
        operation, index = observed.operation, observed.quantity_index
        depends = np.zeros(self.grid.n_bins, dtype=bool)

        def linearise(estimate: Array) -> Linearisation:
            predicted, jacobian = measurement_jacobian(
                self.model, self.grid, estimate, operation, window.bit_depth,
                quantity_index=index, method=self.method)
            depends[:] = jacobian != 0.0
            noise = kalman.noise_with_model_error(observed.standard_error,
                                                  self.model_std_fraction, jacobian, estimate)
            return Linearisation(predicted, jacobian, noise)

        try:
            result = kalman.iterated_update(
                predict(self.state, self.process_std), observed.value, linearise,
                iterations=iterations, gate=self.gate, bounds=_MU_BOUNDS)
        except ModelError:
            return False
        if result.gated:
            self.gated += 1
        if result.accepted:
            state = result.state
            if state.windows_seen.size == depends.size:
                # a new array: copies of this object (the estimator's) share the old one
                state = replace(state, windows_seen=state.windows_seen + depends,
                                deepest=max(state.deepest, window.bit_depth))
            self.state = state
        return result.accepted

    def information(self) -> BinInformation:
        """The information per bin now (:func:`information`; the same object until the state
        changes: its arrays are not to be changed)."""
        known = self._information
        if known is not None and known[0] is self.state:
            return known[1]
        info = information(self.state, self.grid.edges)
        self._information = (self.state, info)
        return info

    def message_fields(self) -> dict[str, object]:
        """``estimate`` message fields of kind ``profile`` (finite numbers only).

        Per bin: ``md_m``, ``mu_profile``, ``mu_profile_std``, ``variance_ratio``, ``informed``
        and ``uninformed_reason`` (null for an informed bin), see :func:`information`.
        """
        std = self.state.std
        info = self.information()
        # tolist: the same Python floats and bools as converting element by element
        return {
            "md_m": _floats(self.grid.mid_md),
            "mu_profile": _floats(self.state.mu),
            "mu_profile_std": _floats(std),
            "variance_ratio": _floats(info.variance_ratio),
            "informed": np.asarray(info.informed, dtype=bool).tolist(),
            "uninformed_reason": list(info.reason),
            "innovation": float(self.state.innovation),
            "innovation_std": float(math.sqrt(max(self.state.innovation_variance, 0.0))),
        }


def _floats(values: ArrayLike) -> list[float]:
    """``[float(x) for x in values]`` at the cost of one NumPy call."""
    listed: list[float] = np.asarray(values, dtype=np.float64).tolist()
    return listed
