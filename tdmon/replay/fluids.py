"""The drilling fluid's part in a simulated session's true loads (docs/hydraulics.md).

When the scenario's well file has a ``[hydraulics]`` table, the fluids are followed through
the session with the daemon's own plug-flow model (`tdmon.model.fluid_tracking.FluidTracker`,
in steps of `STEP` seconds: the timeline's pump rate and the phases' pumped mud density, the
hole kept full while tripping), and every true load takes the fluid's forces at the true bit
speed and pump rate (`tdmon.model.fluid_force.HydraulicModel`: viscous drag, densities per
element, the jets' and pump-open force at the bit). The standpipe pressure is then the model's
too: the bore's and the annulus's friction and the bit's pressure drop.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from tdmon.model.fluid_force import FluidForces, HydraulicModel
from tdmon.model.fluid_tracking import FluidTracker, hydraulics_configured
from tdmon.model.torque_drag import WellModel
from tdmon.replay.spec import Array, Scenario
from tdmon.replay.timeline import Timeline

__all__ = ["STEP", "FluidTruth", "fluid_truth"]

STEP: Final = 1.0
"""Time step of the simulated fluid state [s]."""


class FluidTruth:
    """The fluid state of a session at every `STEP`, and the fluid's forces at any time."""

    def __init__(self, scenario: Scenario, timeline: Timeline, model: WellModel) -> None:
        well = scenario.well
        self.hydraulic = HydraulicModel(well, model.grid)
        self.timeline = timeline
        tracker = FluidTracker(well, model.grid, bit_depth=scenario.bit_depth)
        times = np.arange(0.0, timeline.duration + STEP, STEP)
        where = timeline.at(times)
        flow = timeline.flow[where.segment]
        density = timeline.density[where.segment]
        self._densities: list[tuple[Array, Array]] = []
        for k, t in enumerate(times.tolist()):
            pumped = float(density[k])
            tracker.update(t, float(where.bit_depth[k]), float(flow[k]),
                           None if math.isnan(pumped) else pumped)
            self._densities.append(tracker.densities())

    def densities(self, t: float) -> tuple[Array, Array]:
        """Outside and inside density per hole-grid element at ``t`` [s from the start]."""
        index = min(max(math.floor(t / STEP + 1e-9), 0), len(self._densities) - 1)
        return self._densities[index]

    def forces(self, t: float, bit_depth: float, speed: float, flow: float) -> FluidForces:
        """The fluid's forces at ``t`` [s] with the bit at ``bit_depth`` [m] moving at
        ``speed`` [m/s] (> 0 down) and the pumps at ``flow`` [m^3/s]."""
        outside, inside = self.densities(t)
        return self.hydraulic.forces(bit_depth, speed, flow_rate=flow,
                                     outside_density=outside, inside_density=inside)

    def standpipe_pressure(self, t: Array) -> Array:
        """The standpipe pressure [Pa] at times ``t`` [s]: the string's and the annulus's
        frictional losses and the bit's pressure drop (0 with the pumps off)."""
        where = self.timeline.at(t)
        index = where.segment
        speed = self.timeline.speed(index)
        pressure = np.zeros(t.size)
        for k in range(t.size):
            flow = float(self.timeline.flow[index[k]])
            if flow <= 0.0:
                continue
            forces = self.forces(float(t[k]), float(where.bit_depth[k]), float(speed[k]), flow)
            drop = forces.bit_pressure_drop if math.isfinite(forces.bit_pressure_drop) else 0.0
            pressure[k] = forces.string_loss + forces.surge_at_bit + drop
        return pressure


def fluid_truth(scenario: Scenario, timeline: Timeline, model: WellModel) -> FluidTruth | None:
    """The session's fluids when its well file has a ``[hydraulics]`` table, else None."""
    if not hydraulics_configured(scenario.well):
        return None
    return FluidTruth(scenario, timeline, model)
