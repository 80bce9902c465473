"""The fluids in a well: the density inside the string and around it, as plug flow moves them.

A pure state and pure updates (`FluidState`, then `pump`, `move_string`, `u_tube`), and the
per-element densities the torque-and-drag model buoys each piece with (`element_densities`,
into `tdmon.model.fluid_terms.FluidTerms`):

* the fluid inside the string is kept along the string, by the distance from the bit (it moves
  with the string); above its top, the ``level``, the string is empty (pipe pulled dry, pipe run
  unfilled);
* the fluid outside is kept along the hole, by measured depth (it stays where it is while the
  string moves past it); above its top the annulus is empty;
* `pump` pushes a volume of a fluid (the active mud, a pill, a spacer) down the string and up
  the annulus as a plug: the fronts move by the pumped volume over the capacity they pass
  (bore, then annulus), and what reaches surface leaves (`Returns`: the mud density out);
* `move_string` trips the string to another bit depth: the stands that leave take their fluid,
  those that arrive come empty, and the hole is kept full from the trip tank with a given fluid
  (or not, and its level drops); the steel (and the bore, for a closed string) that enters the
  hole pushes fluid out at surface;
* `u_tube` lets an open string (no float valve, pumps off) settle: fluid runs through the bit
  until the pressures inside and outside it are equal, the way a heavy pill pumped before a
  trip leaves the top of the string dry.

Volumes are exact for the string's and the hole's nominal diameters; a tool joint's volume is
not counted, and the fluids are incompressible and do not mix (plug flow: the fronts stay
sharp, which is what Ekrann and Rommetveit-type models refine with dispersion).

Units: m, m^3, kg/m^3, SI throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from tdmon.errors import ModelError
from tdmon.model.string import GRAVITY
from tdmon.model.well import HoleGrid, Well, hole_grid

__all__ = ["FluidPath", "FluidState", "Returns", "element_densities", "initial_state",
           "move_string", "pump", "u_tube"]

Array = NDArray[np.float64]
_EPS = 1e-9


@dataclass(frozen=True)
class FluidState:
    """Where each fluid is.

    Attributes
    ----------
    inside_bounds : ends of the layers inside the string, as the distance from the bit [m],
        rising from 0; the last is the level (the string is empty above it)
    inside_density : of each layer inside [kg/m^3]
    outside_bounds : ends of the layers outside the string and below the bit, as measured depth
        [m], rising from the annulus's level (0: full) to the bottom of the hole
    outside_density : of each layer outside [kg/m^3]
    """

    inside_bounds: Array
    inside_density: Array
    outside_bounds: Array
    outside_density: Array

    def __post_init__(self) -> None:
        for name in ("inside", "outside"):
            bounds = getattr(self, f"{name}_bounds")
            density = getattr(self, f"{name}_density")
            if bounds.size != density.size + 1 or np.any(np.diff(bounds) < 0.0):
                raise ModelError(f"{name} layers: need rising bounds, one more than densities")

    @property
    def level(self) -> float:
        """Top of the fluid inside the string, as the distance from the bit [m]."""
        return float(self.inside_bounds[-1])

    @property
    def annulus_level(self) -> float:
        """MD of the top of the fluid outside the string [m] (0: the hole is full)."""
        return float(self.outside_bounds[0])


@dataclass(frozen=True)
class Returns:
    """What a `pump` pushed out at surface: the volume of each fluid [m^3], in the order it
    came out, and its density [kg/m^3]."""

    volume: Array
    density: Array

    @property
    def mean_density(self) -> float:
        """Volume-weighted density of all that came out [kg/m^3] (NaN if nothing did)."""
        total = float(np.sum(self.volume))
        return float(np.sum(self.volume * self.density)) / total if total > 0 else math.nan


class FluidPath:
    """A well's volumes along the string and the hole, prepared once.

    Parameters
    ----------
    well : the well (hole sections and string diameters; a component given by its buoyed
        weight has no bore and its tool joint's diameter)
    grid : its hole grid (for `element_densities` and the TVD), default ``hole_grid(well)``
    """

    def __init__(self, well: Well, grid: HoleGrid | None = None) -> None:
        self.well = well
        self.grid = hole_grid(well) if grid is None else grid
        components = well.string.components
        self.component_top = well.string.component_tops()
        outer = [c.contact_diameter if math.isnan(c.outer_diameter) else c.outer_diameter
                 for c in components]
        inner = [0.0 if math.isnan(c.inner_diameter) else c.inner_diameter for c in components]
        self.outer_area = np.pi / 4.0 * np.asarray(outer) ** 2
        self.bore_area = np.pi / 4.0 * np.asarray(inner) ** 2
        # the bore's volume from the bit, at the components' tops
        self.bore_knots = np.concatenate([[0.0], self.component_top])
        self.bore_volume = np.concatenate([[0.0], np.cumsum(
            self.bore_area * np.diff(self.bore_knots))])
        sections = well.sections
        self.hole_knots = np.array([sections[0].top] + [s.bottom for s in sections])
        self.hole_area = np.pi / 4.0 * np.array([s.diameter for s in sections]) ** 2

    @property
    def hole_bottom(self) -> float:
        """[m]"""
        return float(self.hole_knots[-1])

    def bore(self, distance: Array) -> Array:
        """Bore volume between the bit and ``distance`` from it [m^3]."""
        return np.asarray(np.interp(distance, self.bore_knots, self.bore_volume,
                                    right=np.nan))

    def bore_distance(self, volume: Array) -> Array:
        """Distance from the bit [m] that holds ``volume`` of bore above the bit."""
        return np.asarray(np.interp(volume, self.bore_volume, self.bore_knots))

    def open_volume(self, bit_depth: float) -> tuple[Array, Array]:
        """The hole's volume outside the string from surface down, at the bit depth: knots in
        MD [m] and the cumulative volume there [m^3] (piecewise linear in between)."""
        joints = bit_depth - self.component_top
        knots = np.unique(np.concatenate([self.hole_knots, [bit_depth],
                                          joints[(joints > self.hole_knots[0])
                                                 & (joints < bit_depth)]]))
        middle = 0.5 * (knots[:-1] + knots[1:])
        hole = self.hole_area[np.clip(np.searchsorted(self.hole_knots, middle) - 1, 0,
                                      self.hole_area.size - 1)]
        inside = middle < bit_depth
        component = np.minimum(np.searchsorted(self.component_top, bit_depth - middle),
                               self.component_top.size - 1)
        steel = np.where(inside, self.outer_area[component], 0.0)
        return knots, np.concatenate([[0.0], np.cumsum((hole - steel) * np.diff(knots))])

    def tvd(self, md: Array) -> Array:
        """TVD at MD ``md`` [m] (linear between the grid's nodes)."""
        return np.asarray(np.interp(md, self.grid.md, self.grid.tvd))


def initial_state(path: FluidPath, bit_depth: float, density: float | None = None,
                  inside_density: float | None = None) -> FluidState:
    """The well full of one fluid (the well's, by default), the string full of another (the
    well's inside fluid, by default)."""
    fluid = path.well.fluid
    outside = fluid.density if density is None else float(density)
    inside = (fluid.inside_density if fluid.inside_density is not None else outside) \
        if inside_density is None else float(inside_density)
    if not (math.isfinite(outside) and math.isfinite(inside)):
        raise ModelError("the fluid state needs the densities of the fluids ([fluid] density)")
    return FluidState(np.array([0.0, bit_depth - path.hole_knots[0]]), np.array([inside]),
                      np.array([path.hole_knots[0], path.hole_bottom]), np.array([outside]))


class _Gone:
    """Fluid that slid past one end of a column: volumes [m^3] and densities, in the order it
    left."""

    def __init__(self, volume: Array, density: Array) -> None:
        self.volume = volume
        self.density = density


def _slide(bounds: Array, density: Array, shift: float, low: float,
           high: float) -> tuple[Array, Array, _Gone, _Gone]:
    """Layers along a volume coordinate slid by ``shift``: what stays within [low, high]
    (bounds, densities) and what went past the low end (lowest first) and the high end
    (highest first)."""
    moved = bounds + shift
    lower = np.clip(moved[:-1], low, high)
    upper = np.clip(moved[1:], low, high)
    keep = upper - lower > _EPS
    kept = np.concatenate([lower[keep][:1], upper[keep]]) if np.any(keep) else \
        np.array([float(np.clip(moved[0], low, high))])
    past_low = np.minimum(moved[1:], low) - np.minimum(moved[:-1], low)
    past_high = np.maximum(moved[1:], high) - np.maximum(moved[:-1], high)
    at_low, at_high = past_low > _EPS, past_high > _EPS
    return (kept, density[keep], _Gone(past_low[at_low], density[at_low]),
            _Gone(past_high[at_high][::-1], density[at_high][::-1]))


def _merge(bounds: Array, density: Array) -> tuple[Array, Array]:
    """Neighbouring layers of one density as one."""
    if density.size < 2:
        return bounds, density
    same = np.flatnonzero(density[1:] == density[:-1]) + 1
    return np.delete(bounds, same), np.delete(density, same)


def _annulus_from_bit(state: FluidState, path: FluidPath, bit_depth: float) -> tuple[
        Array, Array, Array, Array, float]:
    """The annulus above the bit as volume from the bit up: (bounds, densities, the open
    volume's knots and cumulative volume, the volume between surface and the bit)."""
    knots, cumulative = path.open_volume(bit_depth)
    total = float(np.interp(bit_depth, knots, cumulative))
    bounds = state.outside_bounds
    above = bounds < bit_depth
    clipped = np.concatenate([bounds[above], [bit_depth]])
    from_bit = (total - np.interp(clipped, knots, cumulative))[::-1]
    layers = state.outside_density[: clipped.size - 1][::-1]
    return from_bit, layers, knots, cumulative, total


def _annulus_back(state: FluidState, path: FluidPath, bit_depth: float, from_bit: Array,
                  layers: Array, knots: Array, cumulative: Array, total: float) -> tuple[
        Array, Array]:
    """`_annulus_from_bit` undone: outside layers in MD, the hole below the bit as it was."""
    md = np.interp(total - from_bit, cumulative, knots)[::-1]
    bounds = state.outside_bounds
    below = bounds > bit_depth
    below_density = state.outside_density[state.outside_density.size - int(np.sum(below)):]
    return _merge(np.concatenate([md, bounds[below]]),
                  np.concatenate([layers[::-1], below_density]))


def _into_annulus(state: FluidState, path: FluidPath, bit_depth: float,
                  entering: _Gone) -> tuple[FluidState, Returns]:
    """Fluids entering the annulus at the bit, in order, push the annulus's fluid up; what
    passes its top (the level, usually surface) leaves."""
    from_bit, layers, knots, cumulative, total = _annulus_from_bit(state, path, bit_depth)
    top = float(from_bit[-1])
    out_volume: list[float] = []
    out_density: list[float] = []
    for volume, density in zip(entering.volume.tolist(), entering.density.tolist(),
                               strict=True):
        while volume > _EPS and top > _EPS:  # a fluid longer than the annulus passes through
            chunk = min(volume, top)
            from_bit, layers, _, gone = _slide(from_bit, layers, chunk, 0.0, top)
            from_bit = np.concatenate([[0.0], from_bit])
            layers = np.concatenate([[density], layers])
            out_volume.extend(gone.volume.tolist())
            out_density.extend(gone.density.tolist())
            volume -= chunk
    bounds, density = _annulus_back(state, path, bit_depth, from_bit, layers, knots,
                                    cumulative, total)
    return (FluidState(state.inside_bounds, state.inside_density, bounds, density),
            Returns(np.asarray(out_volume), np.asarray(out_density)))


def pump(state: FluidState, path: FluidPath, bit_depth: float, volume: float,
         density: float) -> tuple[FluidState, Returns]:
    """Pump ``volume`` [m^3] of a fluid of ``density`` [kg/m^3] down the string and up the
    annulus (plug flow).

    The fluid first fills the string's empty top (a string pulled dry, run unfilled), then
    pushes the column down; what leaves the bit enters the annulus at the bit and pushes its
    fluid up; what passes surface is returned (`Returns`: the mud coming back, its density the
    mud density out). A fill-up from the top of a string run unfilled is the same call; so is a
    pill (its volume and density) and its chase.
    """
    if volume < 0.0:
        raise ModelError(f"pumped volume must be >= 0, got {volume}")
    if volume == 0.0:
        return state, Returns(np.empty(0), np.empty(0))
    capacity = float(path.bore(np.array(bit_depth - path.hole_knots[0])))
    volumes = path.bore(state.inside_bounds)
    filled = min(volume, max(capacity - float(volumes[-1]), 0.0))
    layers = state.inside_density
    if filled > 0.0:
        volumes = np.append(volumes, volumes[-1] + filled)
        layers = np.append(layers, density)
    pushed = volume - filled
    if pushed <= 0.0:
        bounds, inside = _merge(path.bore_distance(volumes), layers)
        return (FluidState(bounds, inside, state.outside_bounds, state.outside_density),
                Returns(np.empty(0), np.empty(0)))
    volumes, layers, out_bit, _ = _slide(volumes, layers, -pushed, 0.0, capacity)
    volumes = np.append(volumes, capacity)
    layers = np.append(layers, density)
    if pushed > capacity:  # the pumped fluid itself reaches the bit and follows
        out_bit = _Gone(np.append(out_bit.volume, pushed - capacity),
                        np.append(out_bit.density, density))
    bounds, inside = _merge(path.bore_distance(volumes), layers)
    between = FluidState(bounds, inside, state.outside_bounds, state.outside_density)
    return _into_annulus(between, path, bit_depth, out_bit)


def move_string(state: FluidState, path: FluidPath, from_depth: float, to_depth: float, *,
                fill_density: float | None, closed: bool = True) -> FluidState:
    """Trip the string from bit depth ``from_depth`` to ``to_depth`` [m].

    Parameters
    ----------
    state : before the trip
    path : the well's volumes
    from_depth, to_depth : bit depths [m]
    fill_density : the trip tank's fluid, which keeps the hole full as the string leaves it
        [kg/m^3]; None: no fill (the annulus's level drops by the volume the string took out)
    closed : a string whose bore does not drain or fill through the bit (a float valve); an
        open one settles (`u_tube`) at the new depth

    Notes
    -----
    The fluid inside moves with the string: pulling, the stands that leave the hole take
    theirs (the level never stands above the string's top); running in, the stands come empty.
    Outside, as volume from surface: the hole's volume the string leaves (its steel and its
    bore) is filled at the top from the trip tank, or left empty; running in, what the string
    brings in pushes the hole's fluid out at surface.
    """
    old_knots, old_cum = path.open_volume(from_depth)
    new_knots, new_cum = path.open_volume(to_depth)
    level = min(state.level, max(to_depth - path.hole_knots[0], 0.0))
    inside_bounds = np.minimum(state.inside_bounds, level)
    keep = np.diff(inside_bounds) > _EPS
    inside_bounds = np.concatenate([inside_bounds[:1], inside_bounds[1:][keep]])
    inside_density = state.inside_density[keep]
    from_surface = np.interp(state.outside_bounds, old_knots, old_cum)
    gained = float(new_cum[-1] - old_cum[-1])
    from_surface, density, _, _ = _slide(from_surface, state.outside_density, gained, 0.0,
                                         float(new_cum[-1]))
    if fill_density is not None and from_surface[0] > _EPS:
        from_surface = np.concatenate([[0.0], from_surface])
        density = np.concatenate([[fill_density], density])
    outside_bounds, outside_density = _merge(np.interp(from_surface, new_cum, new_knots),
                                             density)
    moved = FluidState(inside_bounds, inside_density, outside_bounds, outside_density)
    return moved if closed else u_tube(moved, path, to_depth)


def _bore_pressure(state: FluidState, path: FluidPath, bit_depth: float) -> float:
    """Hydrostatic pressure inside the string at the bit [Pa]."""
    md = np.clip(bit_depth - state.inside_bounds, path.hole_knots[0], path.hole_bottom)
    tvd = path.tvd(md)
    return float(GRAVITY * np.sum(state.inside_density * (tvd[:-1] - tvd[1:])))


def _annulus_pressure(state: FluidState, path: FluidPath, bit_depth: float) -> float:
    """Hydrostatic pressure outside the string at the bit [Pa]."""
    tvd = path.tvd(np.minimum(state.outside_bounds, bit_depth))
    return float(GRAVITY * np.sum(state.outside_density * np.diff(tvd)))


def _drained(state: FluidState, path: FluidPath, bit_depth: float,
             volume: float) -> FluidState:
    """``volume`` [m^3] run out of the string at the bit into the annulus (its level drops
    inside; the annulus overflows at surface)."""
    volumes = path.bore(state.inside_bounds)
    volumes, layers, out_bit, _ = _slide(volumes, state.inside_density, -volume, 0.0,
                                         float(volumes[-1]))
    drained = FluidState(path.bore_distance(volumes), layers, state.outside_bounds,
                         state.outside_density)
    return _into_annulus(drained, path, bit_depth, out_bit)[0] if out_bit.volume.size \
        else drained


def _drawn_in(state: FluidState, path: FluidPath, bit_depth: float,
              volume: float) -> FluidState:
    """``volume`` [m^3] of the annulus's fluid drawn into the string at the bit (the annulus's
    level drops; nothing fills it)."""
    from_bit, layers, knots, cumulative, total = _annulus_from_bit(state, path, bit_depth)
    from_bit, layers, entering, _ = _slide(from_bit, layers, -volume, 0.0, total)
    outside_bounds, outside_density = _annulus_back(state, path, bit_depth, from_bit, layers,
                                                    knots, cumulative, total)
    capacity = float(path.bore(np.array(bit_depth - path.hole_knots[0])))
    volumes = path.bore(state.inside_bounds)
    # what entered first is pushed up by what followed it
    entered = np.concatenate([[0.0], np.cumsum(entering.volume[::-1])])
    volumes = np.concatenate([entered, volumes[1:] + entered[-1]])
    density = np.concatenate([entering.density[::-1], state.inside_density])
    volumes = np.minimum(volumes, capacity)
    inside_bounds, inside_density = _merge(path.bore_distance(volumes), density)
    return FluidState(inside_bounds, inside_density, outside_bounds, outside_density)


def u_tube(state: FluidState, path: FluidPath, bit_depth: float) -> FluidState:
    """An open string with the pumps off, settled: fluid has run through the bit until the
    hydrostatic pressure inside the string at the bit equals the annulus's.

    A heavier column inside (a pill pumped before a trip) runs out into the annulus, which
    overflows at surface, and the top of the string falls dry; a lighter one (a string run
    unfilled) takes the annulus's fluid in at the bit, and the annulus's level drops by it.
    Found by Brent's method on the volume that runs through the bit (out positive).
    """
    def after(volume: float) -> FluidState:
        if volume >= 0.0:
            return _drained(state, path, bit_depth, volume)
        return _drawn_in(state, path, bit_depth, -volume)

    def imbalance(volume: float) -> float:
        settled = after(volume)
        return (_bore_pressure(settled, path, bit_depth)
                - _annulus_pressure(settled, path, bit_depth))

    held = float(path.bore(state.inside_bounds[-1:])[0])
    capacity = float(path.bore(np.array(bit_depth - path.hole_knots[0])))
    low, high = -max(capacity - held, 0.0), held
    # draining lowers the pressure inside: the imbalance falls with the volume
    f_low, f_high = imbalance(low), imbalance(high)
    if f_low <= 0.0:  # not even a full string balances the annulus
        return after(low)
    if f_high >= 0.0:  # the string empties and still weighs more
        return after(high)
    return after(float(brentq(imbalance, low, high, xtol=1e-9)))


def element_densities(state: FluidState, path: FluidPath,
                      bit_depth: float) -> tuple[Array, Array]:
    """The mean density outside and inside the string on every hole-grid element [kg/m^3],
    for `tdmon.model.fluid_terms.FluidTerms` (an empty part counts as 0: air).

    Inside, elements below the bit (no string) get the outside density (the loops never read
    it there)."""
    md = path.grid.md
    outside = _mean_over(state.outside_bounds, state.outside_density, md)
    # inside: along the string, distance from the bit rising as MD falls
    distance = bit_depth - md[::-1]
    inside = _mean_over(state.inside_bounds, state.inside_density, distance)[::-1]
    below = md[:-1] >= bit_depth - _EPS
    return outside, np.where(below, outside, inside)


def _mean_over(bounds: Array, density: Array, edges: Array) -> Array:
    """Mean density of layers (``bounds``, ``density``, 0 outside them) over each interval of
    ``edges`` (rising)."""
    mass = np.concatenate([[0.0], np.cumsum(density * np.diff(bounds))])
    at = np.interp(edges, bounds, mass, left=0.0, right=float(mass[-1]))
    width = np.diff(edges)
    return np.asarray(np.divide(np.diff(at), width, out=np.zeros(width.size),
                                where=width > 0.0))
