"""Block weight from in-slips periods, and the weight and buoyancy check.

In slips the hook carries only the travelling equipment (block, top drive, elevators), so the
hook load then *is* the block weight (REFERENCE.md section 5; Volve F-4: about 655 kN). Samples
where the empty block is hoisted or lowered carry inertia and guide friction, so only steady
in-slips samples count, and a running median keeps the pulls of the empty block out.

Static and rotating-off-bottom hook loads carry no axial friction: the string's weight less the
block weight checks the weights and the buoyancy the model uses. Static hook load is linear in
the buoyancy factor (eq 35) when the string's weights are given in air, so the measured over the
modelled weight in air gives the buoyancy factor and the fluid density the rig actually has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from tdmon.errors import FitError
from tdmon.model.string import STEEL_DENSITY

__all__ = [
    "BlockWeightEstimate",
    "BlockWeightState",
    "BuoyancyCheck",
    "block_weight_from_samples",
    "buoyancy_check",
    "update_block_weight",
]


@dataclass(frozen=True)
class BlockWeightEstimate:
    """Block weight [N], its standard error [N] and the number of samples used."""

    value: float
    std: float
    n: int


def block_weight_from_samples(hookload: ArrayLike) -> BlockWeightEstimate:
    """Block weight from steady in-slips hook loads (median, MAD-based standard error).

    Parameters
    ----------
    hookload : hook loads while in slips [N]

    Returns
    -------
    BlockWeightEstimate

    Raises
    ------
    FitError
        No finite value.
    """
    values = np.asarray(hookload, dtype=np.float64).ravel()
    values = values[np.isfinite(values)]
    if values.size == 0:
        raise FitError("no in-slips hook load to take the block weight from")
    median = float(np.median(values))
    spread = 1.4826 * float(np.median(np.abs(values - median)))
    # the median's standard error is ~1.25 sigma/sqrt(n) for normal noise
    return BlockWeightEstimate(median, 1.2533 * spread / math.sqrt(values.size), int(values.size))


@dataclass(frozen=True)
class BlockWeightState:
    """Recent steady in-slips hook loads (a bounded tuple) and the current estimate."""

    recent: tuple[float, ...] = ()
    estimate: BlockWeightEstimate | None = None


def update_block_weight(state: BlockWeightState, hookload: float, *, keep: int = 400
                        ) -> BlockWeightState:
    """Add one steady in-slips hook load [N]; non-finite values keep the prior."""
    if not math.isfinite(hookload):
        return state
    recent = ((*state.recent, float(hookload)))[-keep:]
    return BlockWeightState(recent, block_weight_from_samples(recent))


@dataclass(frozen=True)
class BuoyancyCheck:
    """Measured against modelled string weight.

    Attributes
    ----------
    measured_weight : hook load less block weight [N]
    modelled_weight : the model's static string weight in its fluid [N]
    ratio : measured over modelled [-]
    buoyancy_factor : implied buoyancy factor, measured over modelled weight in air [-]
    fluid_density : implied fluid density, eq 35 read backwards [kg/m3]
    """

    measured_weight: float
    modelled_weight: float
    ratio: float
    buoyancy_factor: float
    fluid_density: float


def buoyancy_check(measured_hookload: float, block_weight: float, modelled_hookload: float,
                   modelled_hookload_in_air: float, modelled_block_weight: float
                   ) -> BuoyancyCheck:
    """Weight and buoyancy check from a static or rotating-off-bottom hook load.

    Parameters
    ----------
    measured_hookload : steady static or rotating hook load [N]
    block_weight : block weight (measured in slips, or configured) [N]
    modelled_hookload : modelled static hook load at the same bit depth [N]
    modelled_hookload_in_air : the same with the fluid density set to zero [N]
    modelled_block_weight : block weight included in both modelled values [N]

    Returns
    -------
    BuoyancyCheck

    Raises
    ------
    FitError
        The modelled weights are not positive.

    Notes
    -----
    With one fluid and weights in air, the static effective force is the buoyancy factor
    ``beta = 1 - rho_m / rho_s`` (eq 35 of the seed thesis) times the weight in air, so
    ``beta = W_measured / W_air`` and ``rho_m = rho_s (1 - beta)``.
    """
    measured = measured_hookload - block_weight
    modelled = modelled_hookload - modelled_block_weight
    in_air = modelled_hookload_in_air - modelled_block_weight
    if not (modelled > 0.0 and in_air > 0.0 and math.isfinite(measured)):
        raise FitError("the modelled string weight is not positive: no buoyancy check")
    beta = measured / in_air
    return BuoyancyCheck(measured, modelled, measured / modelled, beta,
                         STEEL_DENSITY * (1.0 - beta))
