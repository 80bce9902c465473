"""Cased-hole friction: the weighted mean the open-hole solves hold fixed on the casing.

Below the shoe a window's hook load mixes cased and open-hole friction; the open-hole value is
solved with the cased value held fixed, and that comes from the windows taken with the bit
inside casing (docs/back-calculation.md). Per rig state, the cased windows' frictions are
averaged with inverse-variance weights; windows taken deep before any cased window (tripping
out from TD) wait, and are solved again once the mean rests on :data:`MIN_CASED_WINDOWS`.
"""

from __future__ import annotations

from dataclasses import dataclass

from tdmon.calib.windows import Window

__all__ = ["MAX_WAITING", "MIN_CASED_WINDOWS", "CasedFriction", "add_cased", "wait_for_cased"]

#: cased windows needed before waiting windows are solved again with the mean [-]
MIN_CASED_WINDOWS = 3
#: windows kept waiting per rig state, the newest [-]
MAX_WAITING = 500
#: smallest standard deviation a window's weight is computed with [-] (bounds the weight)
_MIN_STD = 1e-4


@dataclass(frozen=True, slots=True)
class CasedFriction:
    """Running inverse-variance weighted mean of one rig state's cased-hole friction.

    Attributes
    ----------
    total : sum of weight times friction [-^-1]
    weight : sum of weights, ``1 / mu_std^2`` [-^-2]
    count : windows in the mean [-]
    """

    total: float = 0.0
    weight: float = 0.0
    count: int = 0

    @property
    def mu(self) -> float | None:
        """The weighted mean [-] (None before the first window)."""
        return self.total / self.weight if self.weight > 0 else None

    @property
    def known(self) -> bool:
        """The mean rests on enough windows to solve waiting windows with it."""
        return self.count >= MIN_CASED_WINDOWS


def add_cased(cased: CasedFriction, mu: float, mu_std: float) -> CasedFriction:
    """Add one cased window's friction ``mu`` [-] with standard deviation ``mu_std`` [-]."""
    w = 1.0 / max(mu_std, _MIN_STD) ** 2
    return CasedFriction(cased.total + w * mu, cased.weight + w, cased.count + 1)


def wait_for_cased(waiting: tuple[Window, ...], window: Window) -> tuple[Window, ...]:
    """``waiting`` with ``window`` added; the oldest beyond :data:`MAX_WAITING` are dropped."""
    return (*waiting, window)[-MAX_WAITING:]
