"""The fluid step: the mud's forces on the string at every frame, for the monitor and the
calibration (docs/hydraulics.md, "Fluids in the live loads").

From the well file's ``[hydraulics]`` and ``[fluid]`` and what streams (``mud_density``: the
mud density in, ``flow_in``, ``spp``; the rig-state detector's block speed), it keeps the fluid
state along the string (`tdmon.model.fluid_tracking.FluidTracker`: plug flow of the pumped mud,
the hole kept full while tripping) and works out, with the monitor's friction factor:

* the change the fluid terms make to each modelled curve's hook load and torque: pick-up and
  slack-off at the measured trip speed in their own direction (the viscous drag), the
  rotating curve at rest, all with the per-element densities and the force at the bit while
  circulating (jets and pump-open force, from the nozzles or the standpipe pressure). The
  monitor adds them to its curves (`tdmon.daemon.steps.monitor.with_fluid`);
* the change for the frame's own rig state, which the calibration step takes off the
  measured hook load and torque before its windows (friction is then what is left);
* a ``hydraulics`` message: surge or swab pressure at the bit and the shoe, their equivalent
  densities, the trip-speed limits of the pore/fracture window, the force at the bit;
* a ``trip_speed`` alarm when the measured trip speed exceeds the limit of its direction.

The step is there only when the well file has a ``[hydraulics]`` table
(`fluid_step_for`); without it every output is what it was without the step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from tdmon.daemon.pipeline import Emit, Frame
from tdmon.errors import ModelError
from tdmon.messages import alarm_message
from tdmon.vocabulary import (
    OPERATION_FOR_STATE,
    REAMING_AXIAL_OPERATION,
    AlarmKind,
    Operation,
    RigState,
    Severity,
)

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig
    from tdmon.config.well_file import WellFile
    from tdmon.daemon.steps.rig_state import RigStateStep
    from tdmon.model.fluid_force import FluidForces, HydraulicModel, TripSpeedLimits
    from tdmon.model.fluid_terms import FluidTerms
    from tdmon.model.fluid_tracking import FluidTracker
    from tdmon.model.torque_drag import WellModel

__all__ = ["FLUID_RESULT", "FluidEffect", "FluidStep", "fluid_step_for"]

FLUID_RESULT = "fluids"
"""The key of `FluidEffect` in ``frame.results`` for the steps after this one."""

#: below this trip speed the string is taken as still (no viscous drag) [m/s]
STILL_SPEED = 0.005
#: the trip-speed limits are solved again when the bit has moved this far [m]
LIMITS_EVERY = 10.0
#: the state a curve's operation is modelled at: its direction of motion (+1 down)
_CURVES: dict[Operation, int] = {Operation.PICK_UP: -1, Operation.SLACK_OFF: 1,
                                 Operation.ROTATING: 0}


@dataclass(frozen=True, slots=True)
class FluidEffect:
    """What the fluid terms change at one frame [N, N m]: per monitor curve (``pick_up``,
    ``slack_off``, ``rotating``) and for the frame's own rig state (``hookload``,
    ``torque``; 0 where the state hangs nothing from the hook)."""

    curve_hookload: dict[str, float]
    curve_torque: dict[str, float]
    hookload: float
    torque: float


class FluidStep:
    """Step: the fluid state and the fluid's forces per frame (see the module docstring).

    Parameters
    ----------
    model : the prepared well
    hydraulic : its hydraulic model
    tracker : the fluid state, advanced per frame
    mu : the monitor's friction factor, at which the changes are worked out [-]
    method : torque-and-drag method
    rig_state : the rig-state step before this one (its block speed)
    """

    name = "fluids"

    def __init__(self, model: WellModel, hydraulic: HydraulicModel, tracker: FluidTracker,
                 mu: float, method: str = "soft-string",
                 rig_state: RigStateStep | None = None) -> None:
        self.model = model
        self.hydraulic = hydraulic
        self.tracker = tracker
        self.mu = mu
        self.method = method
        self.rig_state = rig_state
        self.pipe_radius = float(model.component_radius[-1])
        self._limits: tuple[float, float, TripSpeedLimits] | None = None
        self._alarmed: int = 0  # the direction of motion alarmed and not yet back within
        self._last: tuple[tuple[Any, ...], FluidForces, FluidEffect] | None = None

    def _speed(self, frame: Frame) -> float:
        """The block's speed [m/s] (> 0 down), from the rig-state detector; 0 when unknown."""
        rig = self.rig_state
        if rig is None or rig.last_detection is None or rig.last_sample is None \
                or rig.last_sample.t != frame.t:
            return 0.0
        velocity = rig.last_detection.velocity
        return velocity if velocity is not None and math.isfinite(velocity) else 0.0

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        values = frame.values
        bit_depth = values.get("bit_depth")
        if bit_depth is None or not math.isfinite(bit_depth):
            return
        try:
            self.model.check_bit_depth(bit_depth)
        except ModelError:  # the model does not reach this depth (coverage alarms it)
            return
        flow = values.get("flow_in")
        self.tracker.update(frame.t, bit_depth, flow, values.get("mud_density"))
        speed = self._speed(frame)
        if abs(speed) < STILL_SPEED:
            speed = 0.0
        pumping = max(flow, 0.0) if flow is not None and math.isfinite(flow) else 0.0
        spp = values.get("spp") if pumping > 0.0 else None
        # a frame like the last (in slips, hanging, pumps off): the same forces and changes
        key = (bit_depth, speed, pumping, spp, self.tracker.version, frame.state,
               values.get("rpm"))
        if self._last is not None and self._last[0] == key:
            moving, effect = self._last[1], self._last[2]
        else:
            terms, moving = self._forces(bit_depth, speed, pumping, spp)
            effect = self._effect(frame, bit_depth, speed, terms)
            self._last = (key, moving, effect)
        frame.results[FLUID_RESULT] = {"effect": effect}
        limits = self._trip_limits(bit_depth)
        emit("hydraulics", hydraulics_message(frame.t, bit_depth, speed, pumping, moving,
                                              limits, effect))
        self._check_speed(frame.t, speed, limits, emit)

    def _forces(self, bit_depth: float, speed: float, flow: float, spp: float | None
                ) -> tuple[dict[int, FluidTerms], FluidForces]:
        """The fluid's terms at rest (0) and moving up (-1) and down (+1) at ``|speed|``, and
        its forces at the frame's own speed."""
        from tdmon.model.fluid_terms import FluidTerms

        outside, inside = self.tracker.densities()

        def at(pipe_speed: float) -> FluidForces:
            return self.hydraulic.forces(
                bit_depth, pipe_speed, flow_rate=flow,
                standpipe_pressure=spp if spp is not None and math.isfinite(spp) else None,
                outside_density=outside, inside_density=inside)

        if speed == 0.0 or self.hydraulic.hydraulics.rheology is None:
            rest = at(0.0)
            return {0: rest.terms, -1: rest.terms, 1: rest.terms}, rest
        up, down = at(-abs(speed)), at(abs(speed))
        # at rest with the pumps off only the densities act: no march of the hydraulics
        rest_terms = (FluidTerms(outside_density=outside, inside_density=inside)
                      if flow == 0.0 else at(0.0).terms)
        return {0: rest_terms, -1: up.terms, 1: down.terms}, down if speed > 0.0 else up

    def _change(self, operation: Operation, bit_depth: float, terms: FluidTerms,
                psi: float | None = None) -> tuple[float, float]:
        """Hook load [N] and torque [N m] with the fluid terms less without them (none when
        the terms hold only the well's own mud, full to surface)."""
        if terms.axial is None and terms.bit_force == 0.0 and self.tracker.uniform():
            return 0.0, 0.0
        model, mu, method = self.model, self.mu, self.method
        hookload, torque = model.evaluate(operation, bit_depth, mu, method=method, psi=psi,
                                          fluid=terms)
        dry_hookload, dry_torque = model.evaluate(operation, bit_depth, mu, method=method,
                                                  psi=psi)
        return hookload - dry_hookload, torque - dry_torque

    def _effect(self, frame: Frame, bit_depth: float, speed: float,
                terms: dict[int, FluidTerms]) -> FluidEffect:
        curve_hookload: dict[str, float] = {}
        curve_torque: dict[str, float] = {}
        for curve, direction in _CURVES.items():
            load, torque = self._change(curve, bit_depth, terms[direction])
            curve_hookload[curve.value] = load
            curve_torque[curve.value] = torque
        state = RigState(frame.state)
        operation = OPERATION_FOR_STATE.get(state)
        hookload = torque = 0.0
        if state in REAMING_AXIAL_OPERATION:
            rpm = frame.values.get("rpm")
            axial = REAMING_AXIAL_OPERATION[state]
            hookload = curve_hookload[axial.value]
            if rpm is not None and rpm > 0.0:
                psi = math.atan2(abs(speed), rpm * self.pipe_radius)
                direction = _CURVES[axial]
                torque = self._change(axial, bit_depth, terms[direction], psi)[1]
        elif operation is Operation.STATIC:
            hookload, torque = self._change(operation, bit_depth, terms[0])
        elif operation is not None and operation.value in curve_hookload:
            hookload = curve_hookload[operation.value]
            torque = curve_torque[operation.value]
        return FluidEffect(curve_hookload, curve_torque, hookload, torque)

    def _trip_limits(self, bit_depth: float) -> TripSpeedLimits:
        """The trip-speed limits near this bit depth: solved again when the bit has moved
        `LIMITS_EVERY` m, and when the pumps stop (what they pumped changed the densities)."""
        cached = self._limits
        pumped = self.tracker.pumped
        if cached is None or abs(cached[0] - bit_depth) >= LIMITS_EVERY or (
                cached[1] != pumped and self.tracker.flow == 0.0):
            outside, inside = self.tracker.densities()
            limits = self.hydraulic.trip_speed_limits(bit_depth, outside_density=outside,
                                                      inside_density=inside)
            cached = (bit_depth, pumped, limits)
            self._limits = cached
        return cached[2]

    def _check_speed(self, t: float, speed: float, limits: TripSpeedLimits,
                     emit: Emit) -> None:
        """A ``trip_speed`` alarm once per excursion beyond the limit of the motion's
        direction."""
        direction = 1 if speed > 0.0 else -1
        limit = limits.running_in if direction > 0 else limits.pulling_out
        over = speed != 0.0 and math.isfinite(limit) and abs(speed) > limit
        if not over:
            if self._alarmed and (speed == 0.0 or direction == self._alarmed):
                self._alarmed = 0
            return
        if self._alarmed == direction:
            return
        self._alarmed = direction
        what = ("surge above the fracture density" if direction > 0
                else "swab below the pore density")
        emit("alarm", alarm_message(
            t, AlarmKind.TRIP_SPEED, Severity.WARNING,
            f"trip speed {abs(speed):.2f} m/s over the {limit:.2f} m/s at which the {what} "
            f"({'running in' if direction > 0 else 'pulling out'})",
            value=abs(speed), limit=limit))

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def hydraulics_message(t: float, bit_depth: float, speed: float, flow: float,
                       forces: FluidForces, limits: TripSpeedLimits,
                       effect: FluidEffect) -> dict[str, Any]:
    """The ``hydraulics`` daemon message (docs/architecture.md; its JSON Schema in
    `tdmon.record.schemas`)."""
    return {
        "t": t,
        "bit_depth_m": bit_depth,
        "trip_speed_m_s": speed,
        "flow_m3_s": flow,
        "surge_Pa": {"bit": _finite(forces.surge_at_bit), "shoe": _finite(forces.surge_at_shoe)},
        "density_kg_m3": {"bit": _finite(forces.density_at_bit),
                          "shoe": _finite(forces.density_at_shoe)},
        "trip_speed_limit_m_s": {"running_in": _finite(limits.running_in),
                                 "pulling_out": _finite(limits.pulling_out)},
        "bit_force_N": forces.terms.bit_force,
        "bit_pressure_drop_Pa": _finite(forces.bit_pressure_drop),
        "fluid_hookload_N": effect.hookload,
        "fluid_torque_Nm": effect.torque,
    }


def fluid_step_for(config: DaemonConfig, well_file: WellFile,
                   rig_state: RigStateStep | None) -> FluidStep | None:
    """The fluid step for the daemon's well file, or None when it has no ``[hydraulics]``."""
    from tdmon.model.fluid_tracking import FluidTracker, hydraulics_configured

    well = well_file.well
    if not hydraulics_configured(well):
        return None
    from tdmon.model.fluid_force import HydraulicModel
    from tdmon.model.torque_drag import WellModel

    model = WellModel(well)
    hydraulic = HydraulicModel(well, model.grid)
    tracker = FluidTracker(well, model.grid, bit_depth=float(model.grid.md[0]))
    return FluidStep(model, hydraulic, tracker, config.monitor.mu, config.monitor.method,
                     rig_state)
