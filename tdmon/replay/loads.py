"""The surface loads of a simulated session: hook load and torque of every rig state, from the
torque-and-drag model with the true friction profile.

At every sample time the surface hook load and torque come from one call of
:meth:`tdmon.model.torque_drag.WellModel.evaluate` with the true per-element friction profile.
One call costs about 12 us (compiled march over ~400 elements), so even an hour at 1 s is
well under a second, and the recorded noise-free value *is* the model at that bit depth: a test
or a calibrator can compare with the model exactly. A broomstick over a depth grid with
interpolation would only pay off beyond ~10^5 samples and would put an interpolation error
into the truth. Tight spots add overpull or set-down weight, and a pull from rest a
break-over peak. A pipe run unfilled (the scenario's ``fill_level``) is empty above a fixed MD,
so its weight per metre depends on the bit depth: the model is rebuilt for each bit depth with
the string split at the fluid level inside (about 0.3 ms).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Final

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from tdmon.model.fluid_terms import FluidTerms
from tdmon.model.string import DrillString, StringComponent
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well
from tdmon.replay.fluids import FluidTruth
from tdmon.replay.spec import Array, FrictionAnomaly, Scenario
from tdmon.replay.timeline import Timeline
from tdmon.vocabulary import (
    MOVING_STATES,
    OPERATION_FOR_STATE,
    REAMING_AXIAL_OPERATION,
    Operation,
    RigState,
)

__all__ = ["MOVING_DOWN", "MOVING_UP", "Loads", "friction_with_anomalies", "unfilled_string"]

MOVING_UP: Final = tuple(sorted(s for s in MOVING_STATES
                                if OPERATION_FOR_STATE[s] is Operation.PICK_UP))
"""States pulling the string up (pick-up, back-reaming): overpull at a tight spot."""

MOVING_DOWN: Final = tuple(sorted(s for s in MOVING_STATES
                                  if OPERATION_FOR_STATE[s] is Operation.SLACK_OFF))
"""States lowering the string (slack-off, reaming): set-down weight at a tight spot."""


def friction_with_anomalies(element_mid_md: Array, base: Array,
                            anomalies: tuple[FrictionAnomaly, ...]) -> Array:
    """Per-element friction factor [-]: ``base`` plus each anomaly on the elements it covers."""
    mu = np.array(base, dtype=np.float64, copy=True)
    for anomaly in anomalies:
        mu[(element_mid_md >= anomaly.top) & (element_mid_md <= anomaly.bottom)] += \
            anomaly.delta_mu
    return mu


def unfilled_string(well: Well, bit_depth: float, fill_level: float) -> DrillString:
    """The string of ``well`` with the bit at ``bit_depth`` [m], empty inside above MD
    ``fill_level`` [m] and full of the well's fluid below (eq 36 with no fluid inside).

    The component the level falls in is cut in two; components above it get the buoyed weight
    of an empty pipe (their weight in air must be known: :func:`tdmon.replay.scenario`
    refuses a fluid error on a buoyed weight).
    """
    below = bit_depth - fill_level  # distance of the level from the bit along the string
    if below >= well.string.length:
        return well.string
    density = well.fluid.density
    parts: list[StringComponent] = []
    bottom = 0.0
    for component in well.string.components:
        top = bottom + component.length
        empty = replace(component, buoyed_weight=component.buoyed_weight_in(density, 0.0))
        if top <= below:
            parts.append(component)
        elif bottom >= below:
            parts.append(empty)
        else:
            parts.append(replace(component, length=below - bottom))
            parts.append(replace(empty, length=top - below))
        bottom = top
    return DrillString(tuple(parts))


class Loads:
    """Surface hook load [N] and torque [N m] of any timeline state, from the model."""

    def __init__(self, scenario: Scenario, mu: Array, model: WellModel,
                 fluid: FluidTruth | None = None) -> None:
        self.scenario = scenario
        self.fluid = fluid
        self.model = model
        self.mu = mu
        # psi needs the pipe's surface speed: the radius of the top component, which is most
        # of the string in the hole
        self.pipe_radius = float(self.model.component_radius[-1])
        self.block_weight = scenario.well.block_weight
        self._unfilled: tuple[float, WellModel] | None = None

    def model_at(self, bit: float) -> WellModel:
        """The true model with the bit at ``bit`` [m] (the fill level moves along the string)."""
        level = self.scenario.mismatch.fill_level
        if level is None:
            return self.model
        if self._unfilled is None or self._unfilled[0] != bit:
            well = self.model.well
            model = WellModel(replace(well, string=unfilled_string(well, bit, level)))
            self._unfilled = (bit, model)
        return self._unfilled[1]

    def at(self, timeline: Timeline, t: Array) -> tuple[Array, Array]:
        """Hook load [N] (break-over included) and surface torque [N m] at times ``t`` [s]."""
        where = timeline.at(t)
        index = where.segment
        speed = timeline.speed(index)
        hookload = np.empty(t.size)
        torque = np.empty(t.size)
        for k in range(t.size):
            i = int(index[k])
            bit = float(where.bit_depth[k])
            terms = None
            if self.fluid is not None and timeline.state[i] != RigState.IN_SLIPS:
                terms = self.fluid.forces(float(t[k]), bit, float(speed[k]),
                                          float(timeline.flow[i])).terms
            hookload[k], torque[k] = self.one(
                timeline.state[i], bit, float(speed[k]), float(timeline.rpm[i]),
                float(timeline.wob[i]), terms)
        return hookload + self.break_over(timeline, index, t), torque

    def break_over(self, timeline: Timeline, index: NDArray[np.int64], t: Array) -> Array:
        """Break-over peak [N] of pulls that start from rest (not from another pull)."""
        rig = self.scenario.rig
        extra = np.zeros(t.size)
        if rig.break_over <= 0.0:
            return extra
        for k, i in enumerate(index):
            if (timeline.state[i] in MOVING_UP and i > 0
                    and timeline.state[i - 1] not in MOVING_UP):
                extra[k] = rig.break_over * math.exp(-(t[k] - timeline.t0[i])
                                                     / rig.break_over_time)
        return extra

    def one(self, state: RigState, bit: float, speed: float, rpm: float, wob: float,
            fluid: FluidTerms | None = None) -> tuple[float, float]:
        """Hook load [N] and torque [N m] in ``state`` at bit depth ``bit`` [m], bit speed
        ``speed`` [m/s], rotation ``rpm`` [rad/s] and weight on bit ``wob`` [N], with the
        fluid's terms ``fluid`` (None: one mud, no viscous drag)."""
        if state == RigState.IN_SLIPS:
            return self.block_weight, 0.0
        method = self.scenario.method
        psi = None
        if state in REAMING_AXIAL_OPERATION and rpm > 0.0:
            psi = math.atan2(abs(speed), rpm * self.pipe_radius)
        # in slips aside, every state of a timeline hangs the string from the hook
        operation = OPERATION_FOR_STATE[state]
        hookload, torque = self.model_at(bit).evaluate(
            operation, bit, self.mu, method=method, wob=wob,
            bit_torque=wob * self.scenario.rig.bit_torque_factor, psi=psi, fluid=fluid)
        for spot in self.scenario.tight_spots:
            if spot.md <= bit <= spot.md + spot.length:
                if state in MOVING_UP:
                    hookload += spot.force
                elif state in MOVING_DOWN:
                    hookload -= spot.force
        return hookload, torque

    def effective_mu(self, operation: Operation, bit: float) -> float:
        """Uniform mu giving the true profile's pick-up/slack-off hook load or rotating torque."""
        method = self.scenario.method
        model = self.model_at(bit)
        if operation is Operation.ROTATING:
            _, true_torque = model.evaluate(operation, bit, self.mu, method=method)
            _, unit_torque = model.evaluate(operation, bit, 1.0, method=method)
            # off-bottom torque is linear in a uniform mu: no axial friction changes the tension
            return true_torque / unit_torque if unit_torque > 0 else math.nan
        target, _ = model.evaluate(operation, bit, self.mu, method=method)

        def mismatch(mu: float) -> float:
            return model.evaluate(operation, bit, mu, method=method)[0] - target

        low, high = mismatch(0.0), mismatch(2.0)
        if low == 0.0:
            return 0.0
        if low * high > 0:
            return math.nan
        return float(brentq(mismatch, 0.0, 2.0, xtol=1e-7))


    def weight_factor(self, model: WellModel, bit: float) -> float:
        """True over modelled buoyed string weight at the hook [-]: the static (friction-free)
        hook loads less the block, the true well's over ``model``'s (the daemon's well file,
        its top component reaching surface)."""
        block = self.block_weight
        true_static, _ = self.model_at(bit).evaluate(Operation.STATIC, bit, 0.0)
        modelled, _ = model.evaluate(Operation.STATIC, bit, 0.0)
        return (true_static - block) / (modelled - block)
