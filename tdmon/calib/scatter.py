"""Between-window scatter of friction: the random effect the published uncertainty carries.

A window's back-calculated friction scatters from joint to joint far more than its measurement
error says (Volve F-4: 0.03 against 0.011): tool joints, local doglegs, cuttings, drag locked in
by the last motion. None of this is in the model, so it is treated as a random effect: each
window's friction is ``mu + e`` with ``e ~ N(0, tau^2)``, and ``tau`` is estimated online from
the recent windows of one operation.

Estimator (robust, and blind to a slow trend along the trip, which the filters follow on their
own): the median absolute difference of consecutive windows, ``s = 1.4826 median|d| / sqrt 2``
(``d = mu_j - mu_{j-1}`` has variance ``2 sigma^2`` for independent windows), less the typical
measurement variance, ``tau^2 = max(0, s^2 - median(se_j^2))``. Until :data:`MIN_WINDOWS`
windows exist, the prior ``tau`` is used (docs/back-calculation.md, "Honest uncertainty").
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from statistics import median

__all__ = ["MIN_WINDOWS", "Scatter", "add_window", "scatter_std"]

#: windows of one operation needed before the scatter is estimated from them [-]
MIN_WINDOWS = 5


@dataclass(frozen=True, slots=True)
class Scatter:
    """The recent windows of one operation: friction [-] and its measurement error [-]."""

    mu: tuple[float, ...] = ()
    se: tuple[float, ...] = ()


def add_window(scatter: Scatter, mu: float, se: float, keep: int) -> Scatter:
    """``scatter`` with one more window (the newest ``keep`` are kept); non-finite ignored."""
    if not (math.isfinite(mu) and math.isfinite(se)):
        return scatter
    return Scatter((*scatter.mu, mu)[-keep:], (*scatter.se, se)[-keep:])


def scatter_std(scatter: Scatter | None, prior: float) -> float:
    """Between-window standard deviation ``tau`` of the friction [-].

    Parameters
    ----------
    scatter : the recent windows of one operation (None: none yet)
    prior : ``tau`` used until :data:`MIN_WINDOWS` windows exist [-]
    """
    if scatter is None or len(scatter.mu) < MIN_WINDOWS:
        return prior
    # in Python, once per window and operation: NumPy's calls cost more than these few
    # values (the same differences, squares and medians, statistics.median)
    s = 1.4826 * median([abs(b - a) for a, b in itertools.pairwise(scatter.mu)]) / math.sqrt(2.0)
    measurement = median([se * se for se in scatter.se])
    return math.sqrt(max(0.0, s * s - measurement))
