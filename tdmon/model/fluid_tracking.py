"""Following the fluids in a well through a stream of rig samples (plug flow).

`FluidTracker` turns what a rig streams, sample by sample, into the pure updates of
`tdmon.model.fluid_state`: the bit depth's change trips the string (`move_string`, the hole
kept full with the mud being pumped, the fill policy when no trip-tank volume streams), the
pump rate times the time since the last sample pumps that volume of the mud density in
(`pump`: a pill or a slug is a stretch of heavier mud density in), and an open string settles
when the pumps stop (`u_tube`). The daemon's fluid step and the simulator's true loads both use
it, so the simulated truth and the daemon's estimate come from one model (docs/hydraulics.md,
"Fluids in the live loads").

The pumped volume of an interval is the pump rate at its start times its length (the rate a
rig reports holds until the next report). Units SI: m, s, m^3/s, kg/m^3.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from tdmon.model.fluid_state import (
    FluidPath,
    FluidState,
    element_densities,
    initial_state,
    move_string,
    pump,
    u_tube,
)
from tdmon.model.hydraulics import WellHydraulics
from tdmon.model.well import HoleGrid, Well

__all__ = ["DENSITY_RESOLUTION", "FluidTracker", "hydraulics_configured"]

DENSITY_RESOLUTION = 20.0
"""A streamed mud density in within this of the one in use is taken as the same mud [kg/m^3]."""

Array = NDArray[np.float64]


def hydraulics_configured(well: Well) -> bool:
    """Whether the well's file has a ``[hydraulics]`` table with any key (the fluid terms
    are then modelled; without it the loads are those of one mud, as before)."""
    return well.hydraulics != WellHydraulics()


class FluidTracker:
    """The fluid state of one well, advanced by rig samples.

    Parameters
    ----------
    well : the well (its ``fluid`` is the mud at the start, its ``hydraulics.float_valve``
        says whether the string is closed at the bit)
    grid : its hole grid (default ``hole_grid(well)``)
    bit_depth : where the state starts until the first sample places it [m]
    keep_full : the fill policy while tripping out: the hole is kept full with the mud being
        pumped (True) or left to drop (False)
    resolution : a streamed mud density in closer than this to the one in use is the same mud
        [kg/m^3] (a mud balance reads to 0.1 ppg, 12 kg/m^3; the sensor's noise must not cut
        the columns into a layer per sample)
    """

    def __init__(self, well: Well, grid: HoleGrid | None = None, *, bit_depth: float,
                 keep_full: bool = True, resolution: float = DENSITY_RESOLUTION) -> None:
        self.path = FluidPath(well, grid)
        self.closed = well.hydraulics.float_valve
        self.keep_full = keep_full
        self.resolution = resolution
        self.mud_density = float(well.fluid.density)
        self.bit_depth = self._inside(bit_depth)
        self.state: FluidState = initial_state(self.path, self.bit_depth)
        self.t: float | None = None
        self.flow = 0.0
        self.density_in = self.mud_density
        self.version = 0  # counts changes of the state, for the callers' caches
        self.pumped = 0.0  # the volume pumped so far [m^3]
        self._densities: tuple[int, float, tuple[Array, Array]] | None = None

    def _inside(self, bit_depth: float) -> float:
        top, bottom = float(self.path.hole_knots[0]), self.path.hole_bottom
        return min(max(float(bit_depth), top), bottom)

    def update(self, t: float, bit_depth: float, flow: float | None = None,
               density_in: float | None = None) -> FluidState:
        """The state after the sample at ``t`` [s]: the string moved to ``bit_depth`` [m],
        then the interval's pumped volume (the last sample's rate ``flow`` [m^3/s] of the last
        sample's mud density in [kg/m^3]) pushed through. ``flow`` and ``density_in`` of this
        sample (None: not streamed, no flow and the well's mud) hold until the next one."""
        depth = self._inside(bit_depth)
        if self.t is None:  # the first sample: the well full of its mud at this depth
            self.state = initial_state(self.path, depth)
            self.bit_depth = depth
        state = self.state
        if depth != self.bit_depth:
            fill = self.density_in if self.keep_full else None
            state = move_string(state, self.path, self.bit_depth, depth, fill_density=fill,
                                closed=True)
        if self.t is not None and t > self.t and self.flow > 0.0:
            volume = self.flow * (t - self.t)
            state, _ = pump(state, self.path, depth, volume, self.density_in)
            self.pumped += volume
        new_flow = max(float(flow), 0.0) if flow is not None and math.isfinite(flow) else 0.0
        if not self.closed and new_flow == 0.0 and (self.flow > 0.0 or depth != self.bit_depth):
            state = u_tube(state, self.path, depth)  # an open string settles with pumps off
        if state is not self.state:
            self.version += 1
        self.state = state
        self.bit_depth = depth
        self.t = t if self.t is None else max(self.t, t)
        self.flow = new_flow
        if (density_in is not None and math.isfinite(density_in) and density_in > 0.0
                and abs(density_in - self.density_in) >= self.resolution):
            self.density_in = float(density_in)
        return state

    def densities(self) -> tuple[Array, Array]:
        """Outside and inside density on every hole-grid element now [kg/m^3]."""
        cached = self._densities
        if cached is None or cached[0] != self.version or cached[1] != self.bit_depth:
            cached = (self.version, self.bit_depth,
                      element_densities(self.state, self.path, self.bit_depth))
            self._densities = cached
        return cached[2]

    def uniform(self) -> bool:
        """Whether the well holds the well's own mud everywhere, full to surface (the
        densities then change no weight)."""
        state = self.state
        return (state.annulus_level <= float(self.path.hole_knots[0])
                and state.level >= self.bit_depth - float(self.path.hole_knots[0]) - 1e-9
                and bool(np.all(state.outside_density == self.mud_density))
                and bool(np.all(state.inside_density == self.mud_density)))
