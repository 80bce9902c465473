"""Drilling: tags, the bit's torque and the weight at the bit from the surface (docs/drilling.md).

A *tag* is the bit reaching bottom (``on_bottom``) or leaving it (``off_bottom``): the rig state
entering or leaving ``drilling``. At an on-bottom tag the string turned off bottom just before,
and the torque it took then (the mean of its last steady rotating-off-bottom samples) is the
string's own: the step to the torque on bottom, less what the weight on bit changes of the
string's torque (the model's), is the bit's torque (:func:`bit_torque_step`), averaged over the
first ``settle`` seconds on bottom and kept until the next tag.

The weight at the bit from the hook load (:func:`downhole_wob`): rotating, the string's axial
friction vanishes (Johancsik, Friesen and Dawson 1984: the sliding velocity is all
tangential), so the top force on bottom is the top force off bottom less the weight set on the
bit (the model's slope, -1 in both of tdmon's methods, is taken from the model; a fluid or
buckling term would change it); the top force a reading stands for comes from the
hook-load measurement model (`tdmon.calib.measurement.SensorEstimate`), block lowering at the
rate of penetration. The surface weight on bit, the driller's zero taken off the hook load at
the tag, is never used for it.

Pure functions on frozen values; the monitor step keeps a :class:`DrillingState` per rig.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Final, NamedTuple

from tdmon.calib.measurement import SensorEstimate
from tdmon.errors import FitError
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import Operation

__all__ = [
    "BIT_TORQUE_SOURCES",
    "DrillingFriction",
    "DrillingState",
    "Tag",
    "WobEstimate",
    "bit_torque_pessier",
    "bit_torque_step",
    "downhole_wob",
    "drilling_friction",
    "track",
]

#: Where a bit torque comes from, best first: the MWD's downhole torque, the torque step at
#: the last on-bottom tag, the configured bit model (:func:`bit_torque_pessier`).
BIT_TORQUE_SOURCES: Final = ("downhole", "tag", "model")

#: How many tags are kept (the latest last).
KEPT_TAGS: Final = 32

_DRILLING: Final = "drilling"
_OFF_BOTTOM: Final = "rotating_off_bottom"


class Tag(NamedTuple):
    """The bit reaching (``kind = "on_bottom"``) or leaving (``"off_bottom"``) bottom.

    ``t`` [s], ``bit_depth`` and ``hole_depth`` [m] (None: not read), and for an on-bottom tag
    the string's torque [N m] and hook load [N] turning off bottom just before (None: not seen
    since the last tag)."""

    t: float
    kind: str
    bit_depth: float | None
    hole_depth: float | None
    off_bottom_torque: float | None = None
    off_bottom_hookload: float | None = None


@dataclass(frozen=True, slots=True)
class DrillingState:
    """What is remembered between frames.

    Attributes
    ----------
    drilling : the previous frame was drilling
    off_bottom_torque, off_bottom_hookload : running means of the steady rotating-off-bottom
        samples since the string last left that state [N m], [N] (None: none yet)
    off_bottom_samples : how many samples those means hold
    since : when the last on-bottom tag was [s]
    step_sum, step_samples : the bit torque steps summed since that tag, and how many
    bit_torque : the bit torque of the last tag [N m] (None: not known)
    tags : the last :data:`KEPT_TAGS` tags, oldest first
    """

    drilling: bool = False
    off_bottom_torque: float | None = None
    off_bottom_hookload: float | None = None
    off_bottom_samples: int = 0
    since: float = -math.inf
    step_sum: float = 0.0
    step_samples: int = 0
    bit_torque: float | None = None
    tags: tuple[Tag, ...] = ()


def bit_torque_step(on_bottom_torque: float, off_bottom_torque: float,
                    string_torque_change: float) -> float:
    """The bit's torque from the torque step at a tag [N m].

    Parameters
    ----------
    on_bottom_torque : surface torque drilling [N m]
    off_bottom_torque : surface torque turning off bottom just before the tag [N m]
    string_torque_change : what the weight on bit changes of the string's own torque, the
        model's on-bottom torque without bit torque less its rotating torque [N m]

    Notes
    -----
    Surface torque on bottom is the bit's torque plus the string's, ``T = T_b + T_s(W)``
    (Johancsik et al. 1984: the bit torque is the boundary value of the torque balance); off
    bottom ``T_0 = T_s(0)``, so ``T_b = T - T_0 - (T_s(W) - T_s(0))``.
    """
    return on_bottom_torque - off_bottom_torque - string_torque_change


def bit_torque_pessier(wob: float, bit_diameter: float, bit_friction: float) -> float:
    """Torque of a bit drilling with weight ``wob`` [N m].

    Parameters
    ----------
    wob : weight on bit [N]
    bit_diameter : [m]
    bit_friction : the bit's specific coefficient of sliding friction [-] (about 0.2-0.4 for
        PDC bits, 0.1-0.2 for roller cones)

    Notes
    -----
    ``T_b = mu_b W D_b / 3``: Pessier and Fear (1992) define the bit-specific coefficient of
    sliding friction as ``mu_b = 36 T_b / (D_b W)`` (``T_b`` in ft lbf, ``D_b`` in inches: a
    flat cutting face loaded uniformly), which is this in consistent units.

    References
    ----------
    Pessier, R.C. and Fear, M.J. (1992). Quantifying Common Drilling Problems With Mechanical
    Specific Energy and a Bit-Specific Coefficient of Sliding Friction. SPE 24584.
    """
    return bit_friction * wob * bit_diameter / 3.0


def track(prior: DrillingState, t: float, state: str, steady: bool, bit_depth: float | None,
          hole_depth: float | None, hookload: float | None, torque: float | None, *,
          string_torque_change: float = 0.0, settle: float = 30.0) -> DrillingState:
    """The drilling state after one frame of rig state ``state`` (the ``state`` message's
    name) and its steadiness.

    ``string_torque_change`` is the model's change of the string's torque by this frame's
    weight on bit [N m] (see :func:`bit_torque_step`); the bit torque of a tag is the mean
    step of the drilling samples of its first ``settle`` seconds [s]."""
    drilling = state == _DRILLING
    new = prior
    if drilling and not prior.drilling:
        tag = Tag(t, "on_bottom", bit_depth, hole_depth, prior.off_bottom_torque,
                  prior.off_bottom_hookload)
        new = replace(prior, drilling=True, since=t, step_sum=0.0, step_samples=0,
                      tags=(*prior.tags, tag)[-KEPT_TAGS:])
    elif prior.drilling and not drilling:
        tag = Tag(t, "off_bottom", bit_depth, hole_depth)
        new = replace(prior, drilling=False, off_bottom_torque=None, off_bottom_hookload=None,
                      off_bottom_samples=0, tags=(*prior.tags, tag)[-KEPT_TAGS:])
    if drilling:
        return _settle_bit_torque(new, t, torque, string_torque_change, settle)
    if state == _OFF_BOTTOM and steady and torque is not None and hookload is not None:
        n = new.off_bottom_samples + 1
        torque_mean = torque if new.off_bottom_torque is None else (
            new.off_bottom_torque + (torque - new.off_bottom_torque) / n)
        load_mean = hookload if new.off_bottom_hookload is None else (
            new.off_bottom_hookload + (hookload - new.off_bottom_hookload) / n)
        return replace(new, off_bottom_torque=torque_mean, off_bottom_hookload=load_mean,
                       off_bottom_samples=n)
    if state != _OFF_BOTTOM and new.off_bottom_samples and state not in ("reaming",
                                                                          "back_reaming"):
        # pumps off, in slips, a trip: the next tag's off-bottom torque is read again
        return replace(new, off_bottom_torque=None, off_bottom_hookload=None,
                       off_bottom_samples=0)
    return new


def _settle_bit_torque(state: DrillingState, t: float, torque: float | None,
                       string_torque_change: float, settle: float) -> DrillingState:
    tag = state.tags[-1] if state.tags else None
    off = None if tag is None else tag.off_bottom_torque
    if torque is None or off is None or t - state.since > settle:
        return state
    step_sum = state.step_sum + bit_torque_step(torque, off, string_torque_change)
    samples = state.step_samples + 1
    return replace(state, step_sum=step_sum, step_samples=samples,
                   bit_torque=step_sum / samples)


class WobEstimate(NamedTuple):
    """The weight at the bit from the hook load [N] and its standard deviation [N]."""

    wob: float
    std: float


def downhole_wob(hookload: float, off_bottom_load: float, estimate: SensorEstimate, *,
                 load_per_wob: float = -1.0, weight_std: float = 0.0, motion: int = -1
                 ) -> WobEstimate:
    """Weight on bit from the hook load read drilling [N].

    Parameters
    ----------
    hookload : the hook-load reading [N]
    off_bottom_load : the model's string top force rotating off bottom at this bit depth [N]
        (its hook load less its block weight)
    estimate : the hook-load measurement as known now
    load_per_wob : the model's change of the top force per newton on the bit [-] (-1 rotating)
    weight_std : what is not known of the string's modelled weight [N] (e.g. the weight
        factor's standard deviation times the buoyed weight)
    motion : the block's motion (-1: lowering at the rate of penetration)

    Returns
    -------
    WobEstimate

    Notes
    -----
    The reading stands for a top force ``F = (H - o)/f - B`` (docs/hookload.md), and on bottom
    ``F = F_0 + (dF/dW) W`` with ``F_0`` the off-bottom top force, so
    ``W = (F - F_0)/(dF/dW)``. Its variance is that of the reading's top force (offset, block
    weight, sheave efficiency) and of the modelled weight.
    """
    string_load = estimate.string_load(hookload, motion)
    wob = (string_load - off_bottom_load) / load_per_wob
    reading_std = estimate.uncertainty(string_load, motion) / estimate.factor(motion)
    return WobEstimate(wob, math.hypot(reading_std, weight_std) / abs(load_per_wob))


class DrillingFriction(NamedTuple):
    """Friction from a drilling window's torque: ``mu`` [-], ``mu_std`` [-] (its torque's
    standard error and the bit torque's uncertainty through the slope), the string's torque
    it matched [N m] and that slope [N m per unit friction]."""

    mu: float
    mu_std: float
    string_torque: float
    slope: float


def drilling_friction(model: WellModel, bit_depth: float, wob: float, torque: float,
                      torque_se: float, bit_torque: float, bit_torque_std: float = 0.0, *,
                      method: str = "soft-string",
                      bracket: tuple[float, float] = (0.0, 1.0)) -> DrillingFriction:
    """The friction factor whose modelled drilling torque is the measured one.

    Parameters
    ----------
    model : the prepared well
    bit_depth : [m]
    wob : weight on bit [N]
    torque : the window's mean surface torque [N m] and ``torque_se`` its standard error
    bit_torque : the bit's torque [N m] and ``bit_torque_std`` its uncertainty
    method : torque-and-drag method
    bracket : friction range of the solve [-]

    Raises
    ------
    FitError
        No friction in ``bracket`` gives the string's torque (``torque - bit_torque``).

    Notes
    -----
    The surface torque on bottom is ``T = T_b + T_s(mu, W)`` (the bit torque the boundary
    value of the torque balance, Johancsik et al. 1984), so friction solves
    ``T_s(mu, W) = T - T_b``; ``T_s`` rises monotonically with ``mu``.
    """
    from scipy.optimize import brentq

    target = torque - bit_torque

    def string_torque(mu: float) -> float:
        return model.evaluate(Operation.ON_BOTTOM, bit_depth, mu, method=method, wob=wob)[1]

    low, high = (string_torque(m) - target for m in bracket)
    if low * high > 0.0:
        raise FitError(f"drilling torque less the bit's, {target / 1e3:.1f} kN m at "
                       f"{bit_depth:.1f} m bit depth, cannot be matched by any friction factor "
                       f"from {bracket[0]:g} to {bracket[1]:g} (the model gives "
                       f"{(low + target) / 1e3:.1f} to {(high + target) / 1e3:.1f} kN m)")
    mu = float(brentq(lambda m: string_torque(m) - target, *bracket, xtol=1e-6))
    step = 1e-3
    slope = (string_torque(min(mu + step, bracket[1]))
             - string_torque(max(mu - step, bracket[0]))) / (
        min(mu + step, bracket[1]) - max(mu - step, bracket[0]))
    std = math.hypot(torque_se, bit_torque_std) / slope if slope > 0.0 else math.inf
    return DrillingFriction(mu, std, target, slope)
