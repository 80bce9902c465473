"""Broomstick plots: modelled pick-up, slack-off and rotating hook load and rotating torque
against bit depth for a family of friction factors.

Measured hook loads drawn against these curves show which friction factor the well behaves
like. All depths and cases go through one sweep of the element loop (`sweep` of
`tdmon.model._kernels`); with fluid terms, which change with the bit depth, one march of all
cases and operations per depth.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError
from tdmon.model.fluid_terms import FluidTerms
from tdmon.model.torque_drag import Method, Operation, WellModel, _check_method, operation_terms
from tdmon.model.well import Well

__all__ = ["BROOMSTICK_OPERATIONS", "Broomstick", "broomstick", "broomstick_from_model"]

BROOMSTICK_OPERATIONS: tuple[Operation, ...] = (
    Operation.PICK_UP, Operation.SLACK_OFF, Operation.ROTATING,
)


@dataclass(frozen=True)
class Broomstick:
    """Hook load and torque curves over bit depth for several friction cases.

    Attributes
    ----------
    bit_depth : (n_d,) [m]
    mu : (n_mu,) the friction factor of each case; for per-element friction cases, the
        element-length-weighted mean of the case [-]
    hookload : ``pick_up``, ``slack_off``, ``rotating``: (n_mu, n_d) [N] (block weight included)
    surface_torque : ``rotating``: (n_mu, n_d) [N m]
    method : ``"soft-string"`` or ``"aadnoy"``
    hookload_limit : (n_d,) tensile limit (eq 28) of the component at surface plus block weight,
        NaN where its yield strength is not given [N]
    makeup_torque_limit : (n_d,) smallest make-up torque of the components in the hole, NaN
        where none is given [N m]
    """

    bit_depth: NDArray[np.float64]
    mu: NDArray[np.float64]
    hookload: dict[str, NDArray[np.float64]]
    surface_torque: dict[str, NDArray[np.float64]]
    method: str
    hookload_limit: NDArray[np.float64]
    makeup_torque_limit: NDArray[np.float64]


def _friction_cases(model: WellModel, mus: Sequence[float] | ArrayLike) -> NDArray[np.float64]:
    values = np.asarray(mus, dtype=np.float64)
    if values.ndim == 1:
        return np.ascontiguousarray(np.stack([model.friction(float(m)) for m in values]))
    if values.ndim == 2:
        return np.ascontiguousarray(np.stack([model.friction(row) for row in values]))
    raise ModelError(
        "mus must be a sequence of friction factors or a 2-D array (cases x hole-grid elements), "
        f"got shape {values.shape}"
    )


def _limit_lines(model: WellModel, depths: NDArray[np.float64]) -> tuple[
        NDArray[np.float64], NDArray[np.float64]]:
    components = model.well.string.components
    tops = model.component_top
    top_index = np.minimum(np.searchsorted(tops, depths, side="left"), len(components) - 1)
    safety = model.well.limits.safety_factor
    tensile = np.array([c.area * c.yield_strength / safety if c.yield_strength else np.nan
                        for c in components])
    makeup = np.array([c.makeup_torque if c.makeup_torque else np.nan for c in components])
    hookload_limit = tensile[top_index] + model.well.block_weight
    makeup_limit = np.array([
        np.nanmin(makeup[: i + 1]) if np.isfinite(makeup[: i + 1]).any() else np.nan
        for i in top_index
    ])
    return hookload_limit, makeup_limit


FluidAt = Callable[[float, Operation], FluidTerms | None]
"""The fluid terms of an operation at a bit depth [m] (`tdmon.model.fluid_force` makes them)."""


def _swept_with_fluid(model: WellModel, kernel_method: int, cases: NDArray[np.float64],
                      depths: NDArray[np.float64], terms: NDArray[np.float64],
                      fluid: FluidAt) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """`sweep`'s arrays, one march of every case and operation per depth with its fluid
    terms (each the march `WellModel.evaluate` makes of them)."""
    loops: Any = model.kernels.module
    forces = np.empty((cases.shape[0], depths.size, len(BROOMSTICK_OPERATIONS)))
    torques = np.empty_like(forces)
    for d, depth in enumerate(depths):
        per_operation = [fluid(float(depth), op) for op in BROOMSTICK_OPERATIONS]
        bit_forces = terms[:, 0] + np.array(
            [0.0 if t is None else t.bit_force for t in per_operation])
        forces[:, d, :], torques[:, d, :] = loops.march_cases(
            *model.kernel_well, kernel_method, cases, float(depth),
            np.ascontiguousarray(bit_forces), np.ascontiguousarray(terms[:, 1]),
            np.ascontiguousarray(terms[:, 2]), np.ascontiguousarray(terms[:, 3]),
            model.kernel_fluid(per_operation))
    return forces, torques


def broomstick_from_model(
    model: WellModel,
    bit_depths: ArrayLike,
    mus: Sequence[float] | ArrayLike,
    *,
    method: Method | str = "soft-string",
    fluid: FluidAt | None = None,
) -> Broomstick:
    """`broomstick` on a prepared `WellModel` (no grid rebuild when called repeatedly)."""
    kernel_method = _check_method(method)
    depths = np.atleast_1d(np.asarray(bit_depths, dtype=np.float64))
    if depths.ndim != 1 or depths.size == 0:
        raise ModelError("bit depths must be a non-empty 1-D sequence")
    depths = np.array([model.check_bit_depth(d) for d in depths])
    cases = _friction_cases(model, mus)
    terms = np.array([operation_terms(op) for op in BROOMSTICK_OPERATIONS])
    loops: Any = model.kernels.module  # numba's dispatchers or plain Python (see `WellModel`)
    if fluid is not None:
        forces, torques = _swept_with_fluid(model, kernel_method, cases, depths, terms, fluid)
    else:
        forces, torques = loops.sweep(
            *model.kernel_well, kernel_method, cases, depths,
            np.ascontiguousarray(terms[:, 0]), np.ascontiguousarray(terms[:, 1]),
            np.ascontiguousarray(terms[:, 2]), np.ascontiguousarray(terms[:, 3]))
    hookloads = forces + model.well.block_weight
    lengths = np.diff(model.node_md)
    labels = np.asarray(mus, dtype=np.float64)
    if labels.ndim == 2:
        labels = cases @ lengths / lengths.sum()
    hookload_limit, makeup_limit = _limit_lines(model, depths)
    return Broomstick(
        bit_depth=depths,
        mu=np.asarray(labels, dtype=np.float64),
        hookload={op.value: hookloads[:, :, i] for i, op in enumerate(BROOMSTICK_OPERATIONS)},
        surface_torque={Operation.ROTATING.value: torques[:, :, 2]},
        method=str(method),
        hookload_limit=hookload_limit,
        makeup_torque_limit=makeup_limit,
    )


def broomstick(
    well: Well,
    bit_depths: ArrayLike,
    mus: Sequence[float] | ArrayLike,
    *,
    method: Method | str = "soft-string",
    fluid: FluidAt | None = None,
) -> Broomstick:
    """Pick-up, slack-off and rotating hook loads and rotating torque over bit depth.

    Parameters
    ----------
    well : the well
    bit_depths : (n_d,) bit depths [m]
    mus : friction cases: a sequence of friction factors, or a 2-D array
        (n_cases, n_elements of ``hole_grid(well)``) of per-element friction [-]
    method : ``"soft-string"`` or ``"aadnoy"``
    fluid : the fluid terms of an operation at a bit depth (a trip speed's viscous drag, say:
        `tdmon.model.fluid_force.FluidForces`), or None

    Returns
    -------
    Broomstick

    Notes
    -----
    Every (case, depth, operation) is evaluated by the same compiled march as
    `tdmon.model.torque_drag.torque_drag`, in one call, so the curves equal the single-depth
    model's numbers exactly.
    """
    return broomstick_from_model(WellModel(well), bit_depths, mus, method=method, fluid=fluid)
