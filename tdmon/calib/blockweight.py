"""Block weight from in-slips periods, and the weight and buoyancy check.

In slips the hook carries only the travelling equipment (block, top drive, elevators), so the
hook load then *is* the block weight (docs/back-calculation.md; Volve F-4: about 655 kN).
Samples where the empty block is hoisted or lowered carry inertia and guide friction, so only
steady in-slips samples count, and a running median keeps the pulls of the empty block out. The
estimator (`tdmon.calib.estimator`) keeps that median as a :class:`BlockWeightWindow` (a sorted
window, updated per sample by :func:`add_block_weight` with one binary search and one copy),
which gives the numbers of :func:`update_block_weight` (the plain reference, which sorts the
whole window again on every sample); :class:`BlockWeightTracker` is its stateful wrapper.

Static and rotating-off-bottom hook loads carry no axial friction: the string's weight less the
block weight checks the weights and the buoyancy the model uses. Static hook load is linear in
the buoyancy factor (eq 35) when the string's weights are given in air, so the measured over the
modelled weight in air gives the buoyancy factor and the fluid density the rig actually has.
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_left, bisect_right
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from tdmon.errors import FitError
from tdmon.model.string import STEEL_DENSITY

__all__ = [
    "BlockWeightEstimate",
    "BlockWeightState",
    "BlockWeightTracker",
    "BlockWeightWindow",
    "BuoyancyCheck",
    "add_block_weight",
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


def _doubles() -> array[float]:
    return array("d")


@dataclass(frozen=True)
class BlockWeightWindow:
    """The last steady in-slips hook loads as a value: in arrival order and sorted.

    The frozen, incremental form of :class:`BlockWeightState`: :func:`add_block_weight` keeps
    the sorted copy up to date (one binary search and one copy of the doubles per sample)
    instead of sorting the whole window again, and gives the same estimate to the last bit.
    The arrays are never changed once in a window (plain doubles: a copy is one memory copy,
    where a tuple of floats would touch every element).

    Attributes
    ----------
    recent : hook loads in the window, oldest first [N]
    ordered : the same values sorted ascending [N]
    """

    recent: array[float] = field(default_factory=_doubles)
    ordered: array[float] = field(default_factory=_doubles)

    @property
    def median(self) -> float | None:
        """The estimate's ``value`` without its spread [N] (None while the window is empty):
        what the rig-state threshold takes on every in-slips sample."""
        return _median_of_sorted(self.ordered) if self.ordered else None

    @cached_property
    def estimate(self) -> BlockWeightEstimate | None:
        """The estimate of the window (None while it is empty).

        Worked out when first asked, not per sample: the estimator asks per window, and the
        spread's binary search was half of `add_block_weight` (~2.5 of 6 us per in-slips
        sample, ~13 ms of a 3.3 h replay's 5 280 of them)."""
        return _estimate_of_sorted(self.ordered) if self.ordered else None


def add_block_weight(window: BlockWeightWindow, hookload: float, *, keep: int = 400
                     ) -> BlockWeightWindow:
    """Add one steady in-slips hook load [N] to a window of ``keep`` values.

    A non-finite hook load returns ``window`` itself (the prior estimate stays).
    """
    if not math.isfinite(hookload):
        return window
    value = float(hookload)
    # copies, changed before anyone else sees them: the arrays of `window` stay as they are
    full = len(window.recent) >= keep
    recent = window.recent[1:] if full else window.recent[:]
    recent.append(value)
    ordered = window.ordered[:]
    ordered.insert(bisect_right(ordered, value), value)
    if full:
        del ordered[_index_of(ordered, window.recent[0])]
    return BlockWeightWindow(recent, ordered)


def _index_of(ordered: Sequence[float], value: float) -> int:
    """Index of one occurrence of ``value`` in ``ordered`` (which holds it)."""
    index = bisect_left(ordered, value)
    if value == 0.0:
        # 0.0 and -0.0 compare equal: take out the one that went in
        sign = math.copysign(1.0, value)
        while math.copysign(1.0, ordered[index]) != sign:
            index += 1
    return index


class BlockWeightTracker:
    """Running block weight over the last ``keep`` steady in-slips hook loads.

    The stateful wrapper of :func:`add_block_weight`: the same window and the same estimate as
    :func:`update_block_weight` (median and MAD from a sorted copy of the window, so equal to
    NumPy's to the last bit) without sorting the whole window on every sample. ``estimate`` is
    None until a finite hook load has been added.

    Parameters
    ----------
    keep : samples in the window [-]
    """

    def __init__(self, keep: int = 400) -> None:
        if keep < 1:
            raise ValueError("keep must be at least 1")
        self.keep = keep
        self.window = BlockWeightWindow()

    @property
    def recent(self) -> tuple[float, ...]:
        """The hook loads in the window, oldest first [N]."""
        return tuple(self.window.recent)

    @property
    def estimate(self) -> BlockWeightEstimate | None:
        """The current estimate (None before the first finite hook load)."""
        return self.window.estimate

    def add(self, hookload: float) -> BlockWeightEstimate | None:
        """Add one steady in-slips hook load [N]; a non-finite one keeps the prior estimate."""
        self.window = add_block_weight(self.window, hookload, keep=self.keep)
        return self.window.estimate


def _estimate_of_sorted(ordered: Sequence[float]) -> BlockWeightEstimate:
    """`block_weight_from_samples` of a sorted, finite, non-empty list, without sorting it.

    The absolute deviations from the median are two sorted runs (the values below the median
    read downwards, those above it read upwards), so their middle order statistics come from a
    binary search over the two runs; each deviation is computed as NumPy computes it
    (``|x - m|`` is ``m - x`` or ``x - m`` exactly), and even counts average the two middle
    values as ``np.median`` does.
    """
    n = len(ordered)
    half = n // 2
    median = _median_of_sorted(ordered)
    if n % 2:
        mad = _middle_deviations(ordered, median, half)[0]
    else:
        lower, upper = _middle_deviations(ordered, median, half - 1)
        mad = (lower + upper) / 2
    spread = 1.4826 * mad
    return BlockWeightEstimate(median, 1.2533 * spread / math.sqrt(n), n)


def _median_of_sorted(ordered: Sequence[float]) -> float:
    """``np.median`` of a sorted, non-empty list (the mean of the two middle values when even)."""
    half = len(ordered) // 2
    return ordered[half] if len(ordered) % 2 else (ordered[half - 1] + ordered[half]) / 2


def _middle_deviations(ordered: Sequence[float], median: float, k: int) -> tuple[float, float]:
    """The k-th and (k + 1)-th smallest (from 0) of ``|x - median|`` over ``ordered`` (sorted
    ascending, ``median`` its median); the second is inf when there are only k + 1 values.

    Run ``below[i] = median - ordered[half - 1 - i]`` and run ``above[j] = ordered[half + j] -
    median`` (``half = n // 2``) are both ascending; the k + 1 smallest deviations are the first
    ``a`` of ``below`` and the first ``k + 1 - a`` of ``above`` for the smallest ``a`` at which
    ``below[a]`` is not below ``above[k - a]``; the next one is the smaller of the two runs'
    next values.
    """
    n = len(ordered)
    half = n // 2
    lo, hi = max(0, k + 1 - (n - half)), min(k + 1, half)
    while lo < hi:
        a = (lo + hi) // 2
        b = k + 1 - a  # >= 1 here since a < k + 1
        if median - ordered[half - 1 - a] < ordered[half + b - 1] - median:
            lo = a + 1
        else:
            hi = a
    a, b = lo, k + 1 - lo
    kth = max(median - ordered[half - a] if a > 0 else -math.inf,
              ordered[half + b - 1] - median if b > 0 else -math.inf)
    following = min(median - ordered[half - 1 - a] if a < half else math.inf,
                    ordered[half + b] - median if half + b < n else math.inf)
    return kth, following


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
