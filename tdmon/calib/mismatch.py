"""The weight-mismatch alarm: the joint estimate's weight factor in kN and %, with likely causes.

When friction and weight are separated (:mod:`tdmon.calib.joint`) and the weight factor stays
away from 1 beyond the tolerance and two standard deviations for a few estimates in a row, the
alarm says how much lighter or heavier the string is than modelled, in kN of hook load at the
bit depth and in %, and which physical errors could give it, each in its own unit:

- lighter: the pipe not filled (the empty length from surface whose missing inside fluid weighs
  the difference), mud heavier than configured (the density that buoys the steel in the hole
  that much more), or a lighter pipe (mass per metre);
- heavier: mud lighter than configured, or a heavier pipe (mass per metre, tool joints);
- either way, the hook-load measurement: a sensor whose scale is off by that fraction reads the
  string that much lighter or heavier (docs/hookload.md), and a block weight the estimate knows
  only loosely trades against the string weight (its value and spread are given).

A cause is named only with a value it can physically have: a fill level inside the string, a
density change of at most :data:`MAX_DENSITY_CHANGE`. Never an impossible density.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tdmon.calib.alarms import Alarm
from tdmon.errors import ModelError
from tdmon.model.string import GRAVITY, StringComponent
from tdmon.model.torque_drag import WellModel
from tdmon.vocabulary import AlarmKind, Operation, Severity

__all__ = ["MAX_DENSITY_CHANGE", "Mismatch", "empty_length", "mismatch_alarm",
           "mud_density_for", "weight_difference"]

#: largest relative mud-density error offered as a cause [-]
MAX_DENSITY_CHANGE = 0.2


@dataclass(frozen=True, slots=True)
class Mismatch:
    """Memory of the alarm: estimates in a row beyond the tolerance, and whether it is raised."""

    count: int = 0
    raised: bool = False


def weight_difference(model: WellModel, bit_depth: float, weight_factor: float) -> float:
    """Hook-load difference of the string hanging free, measured minus modelled [N]:
    ``(w - 1) F_static`` at ``bit_depth`` [m]."""
    static = model.evaluate(Operation.STATIC, bit_depth, 0.0)[0] - model.well.block_weight
    return (weight_factor - 1.0) * static


def _inside_weight(component: StringComponent, outside: float, inside: float) -> float:
    """Weight of the fluid inside one metre of the component [N/m], as the model counts it.

    The model's buoyed weight with a different inside fluid (eq 36) scales the weight in air,
    tool joints included, so the fluid inside weighs a little more there than ``rho g A_i``;
    the level is found with the model's own figure. A component given by its buoyed weight
    ignores the fluids: ``rho g A_i`` then."""
    counted = (component.buoyed_weight_in(outside, inside)
               - component.buoyed_weight_in(outside, 0.0))
    if counted > 0.0:
        return counted
    return inside * GRAVITY * math.pi / 4.0 * component.inner_diameter**2


def empty_length(model: WellModel, bit_depth: float, deficit: float) -> float | None:
    """MD from surface down to which the pipe must be empty to weigh ``deficit`` [N] less.

    The inside fluid of the string above the level weighs ``rho_i g A_i dTVD``; the level is
    where that sum from surface reaches the deficit. None when no level inside the string can
    (the deficit exceeds the weight of all the fluid inside).
    """
    fluid = model.well.fluid
    rho = fluid.inside_density if fluid.inside_density is not None else fluid.density
    if not (deficit > 0.0 and rho > 0.0):
        return None
    md = model.grid.md
    md = md[md <= bit_depth]
    if md.size < 2:
        return None
    tvd = model.grid.tvd[: md.size]
    mid = 0.5 * (md[:-1] + md[1:])
    tops = model.well.string.component_tops()
    inside = np.array([_inside_weight(c, fluid.density, rho)
                       for c in model.well.string.components])
    # component at each element: distance above the bit against the tops, bit up
    index = np.clip(np.searchsorted(tops, bit_depth - mid), 0, inside.size - 1)
    weight = inside[index] * np.diff(tvd)
    cumulative = np.concatenate([[0.0], np.cumsum(weight)])
    if cumulative[-1] < deficit:
        return None
    return float(np.interp(deficit, cumulative, md))


def mud_density_for(model: WellModel, air_model: WellModel | None, bit_depth: float,
                    difference: float) -> float | None:
    """Mud density (inside and out) that changes the free-hanging weight by ``difference`` [N]
    [kg/m3]; None without a fluid or beyond :data:`MAX_DENSITY_CHANGE`.

    The buoyant force on the string is proportional to the density:
    ``F_air - F_fluid = rho g V``, so ``d rho = -difference rho / (F_air - F_fluid)``.
    """
    rho = model.well.fluid.density
    if air_model is None or rho <= 0.0:
        return None
    try:
        buoyant = (air_model.evaluate(Operation.STATIC, bit_depth, 0.0)[0]
                   - model.evaluate(Operation.STATIC, bit_depth, 0.0)[0])
    except ModelError:
        return None
    if buoyant <= 0.0:
        return None  # weights given buoyed: the density does not enter the model
    change = -difference * rho / buoyant
    if abs(change) > MAX_DENSITY_CHANGE * rho:
        return None
    return rho + change


def _causes(model: WellModel, air_model: WellModel | None, bit_depth: float,
            difference: float, off: float, block: tuple[float, float] | None) -> str:
    density = mud_density_for(model, air_model, bit_depth, difference)
    mud = ("" if density is None else
           f"mud {density:.0f} kg/m3 rather than {model.well.fluid.density:.0f}?, ")
    word = "low" if difference < 0.0 else "high"
    sensor = (f"or the hook-load sensor reading {100 * off:.1f} % {word} (its calibration)?")
    if block is not None:
        sensor += (f"; the block weight is known to {block[1] / 1e3:.0f} kN only "
                   f"({block[0] / 1e3:.0f} kN)")
    if difference < 0.0:
        level = empty_length(model, bit_depth, -difference)
        fill = ("fluid inside the pipe" if level is None
                else f"pipe not filled (empty down to about {level:.0f} m)?")
        return f"{fill}, {mud}mass per metre, {sensor}"
    return f"{mud}heavier pipe (mass per metre, tool joints), {sensor}"


def _loose(block: tuple[float, float] | None, difference: float
           ) -> tuple[float, float] | None:
    """The block weight when it is known too loosely to rule it out as a cause."""
    if block is None or block[1] < abs(difference) / 3.0:
        return None
    return block


def mismatch_alarm(memory: Mismatch, model: WellModel, air_model: WellModel | None, t: float,
                   bit_depth: float, weight_factor: float, weight_factor_std: float, mu: float,
                   identifiable: bool, *, tolerance: float, windows: int,
                   block: tuple[float, float] | None = None) -> tuple[Mismatch, Alarm | None]:
    """Update the alarm's memory with one joint estimate; the alarm when it is due.

    Parameters
    ----------
    memory : the memory so far
    model, air_model : the prepared well, and the same without fluid (None: no density cause)
    t : [s]
    bit_depth : [m]
    weight_factor, weight_factor_std : the joint estimate [-]
    mu : its friction [-]
    identifiable : friction and weight are separated (otherwise the count restarts)
    tolerance : relative weight difference that counts [-]
    windows : estimates in a row beyond it that raise the alarm [-]
    block : the estimated block weight and its standard deviation [N], named among the causes
        when its spread is at least a third of the difference (None: not estimated)

    Returns
    -------
    (memory, alarm or None): raised once; again only after the weight agreed in between.
    """
    off = abs(weight_factor - 1.0)
    beyond = identifiable and off > max(tolerance, 2.0 * weight_factor_std)
    if not beyond:
        agreed = off <= tolerance
        return Mismatch(0, memory.raised and not agreed), None
    count = memory.count + 1
    if memory.raised or count < windows:
        return Mismatch(count, memory.raised), None
    try:
        difference = weight_difference(model, bit_depth, weight_factor)
    except ModelError:
        return Mismatch(count, memory.raised), None
    word = "lighter" if difference < 0 else "heavier"
    text = (f"string {abs(difference) / 1e3:.0f} kN ({100 * off:.1f} %) {word} than modelled at "
            f"{bit_depth:.0f} m (weight factor {weight_factor:.3f} +/- "
            f"{weight_factor_std:.3f}, friction {mu:.2f}): "
            f"{_causes(model, air_model, bit_depth, difference, off, _loose(block, difference))}")
    return Mismatch(count, True), Alarm(t, AlarmKind.WEIGHT_MISMATCH, Severity.WARNING, text,
                                        weight_factor, 1.0)
