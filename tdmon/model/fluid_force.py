"""The fluid's forces on a string in a well, per hole-grid element, for the torque-and-drag model.

`HydraulicModel` is prepared once per well (its hole grid, the string's diameters, the casing
shoe); at a bit depth it cuts the string in the hole into pieces of one hole diameter and one
component (`string_in_hole`) and gives, for a block speed and a pump rate (`HydraulicModel.forces`):

* the axial fluid force per metre of every element, `FluidTerms.axial`: the annular flow's
  pressure gradient on the pipe's end areas and its wall shear, ``f = -(dp_a/dz) pi d_o d_h /
  4`` (derived below), with the gradient of `tdmon.model.hydraulics.surge_swab` (Burkhardt's
  effective velocity, the flow split of an open string, the pumps' flow up the annulus);
* the jets' force on the string at the bit while circulating, `FluidTerms.bit_force`, and the
  pump-open force of pressure-actuated tools (`WellHydraulics.pump_open_area` times the bit's
  pressure drop), from the bit's nozzles or else from the standpipe pressure less the modelled
  string and annulus losses;
* the surge (or swab) pressure at the bit and at the casing shoe, the equivalent densities
  there, and (`HydraulicModel.trip_speed_limits`) the trip speeds at which they would reach
  the fracture or the pore pressure.

Notes
-----
What is included, in effective-force terms (tension positive, z measured depth down; the
effective force ``F_e = F + p_o A_o - p_i A_i`` is what the march integrates, Sparks 1984):

* a piece of string of outer and inner areas ``A_o``, ``A_i`` feels, besides its buoyed weight,
  ``-A_o dp_o + A_i dp_i + S_o + S_i`` from the frictional (flow) part of the pressures outside
  and inside and the wall shear forces ``S`` of the flows on its outer and inner surfaces;
* inside, the bore's fluid balances its own friction: ``A_i dp_i = -S_i``, so the bore's flow
  adds nothing to the effective force anywhere (nor do the standpipe pressure and the inside
  friction at the surface: the hook carries the effective force plus the pressure on the top
  drive's closed flow path, which the pressure in the string's bore cancels);
* outside, the slot approximation of the annulus shares the flow's wall shear equally between
  the hole's wall and the pipe's: ``S_o = -dp_a pi d_o (d_h - d_o) / 4``, which with the end
  area gives ``f = -(dp_a/dz) pi d_o d_h / 4`` per metre (``d_o``: the pipe body's outer
  diameter, or the tool joint's where the body is not known);
* at the bit, the jets leave at ``v_n`` and push the string up by their momentum flux
  ``rho q v_n`` (`tdmon.model.hydraulics.jet_impact_force`): with the pressures there, which
  cancel in the effective force, this is the whole bit term off bottom.

Not included: the fluid's inertia (a string accelerating the mud: surge is taken as the steady
flow at the current speed), gel strength when flow starts, eccentric annuli, tool joints'
local losses, temperature and pressure effects on density and rheology, a pump-off force
under a bit on bottom beyond the jets'.

References
----------
.. [1] Burkhardt, J. A. (1961). Wellbore pressure surges produced by pipe movement. JPT 13(6),
   595-605.
.. [2] Bourgoyne et al. (1986). Applied Drilling Engineering, chapter 4.
.. [3] Sparks, C. P. (1984). The influence of tension, pressure and weight on pipe and riser
   deformations and stresses. J. Energy Resour. Technol. 106(1), 46-54 (effective tension).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError
from tdmon.model.fluid_terms import FluidTerms
from tdmon.model.hydraulics import (
    AnnularSections,
    SurgeSwab,
    bit_pressure_drop,
    critical_trip_speed,
    jet_impact_force,
    pipe_pressure_gradient,
    surge_swab,
)
from tdmon.model.rheology import Rheology
from tdmon.model.string import GRAVITY
from tdmon.model.well import HoleGrid, Well, hole_grid

__all__ = ["FluidForces", "HydraulicModel", "StringInHole", "TripSpeedLimits"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class StringInHole:
    """The string in the hole at one bit depth, as pieces of one element and one component,
    from the bit up.

    Attributes
    ----------
    top, bottom : MD of each piece's ends [m]
    element : the hole-grid element of each piece
    component : the string component of each piece (bit-up index)
    hole_diameter, outer_diameter, inner_diameter : [m]
    """

    top: Array
    bottom: Array
    element: NDArray[np.int64]
    component: NDArray[np.int64]
    hole_diameter: Array
    outer_diameter: Array
    inner_diameter: Array

    @property
    def length(self) -> Array:
        """[m]"""
        return np.asarray(self.bottom - self.top)


@dataclass(frozen=True)
class FluidForces:
    """The fluid's part at one bit depth, one block speed and one pump rate.

    Attributes
    ----------
    terms : what the torque-and-drag march takes (`FluidTerms`)
    surge_at_bit, surge_at_shoe : frictional annular pressure at the bit and at the casing shoe
        [Pa]: surge (and circulation) positive, swab negative; NaN at the shoe of a well
        without casing
    static_at_bit, static_at_shoe : hydrostatic annular pressure there [Pa]
    tvd_at_bit, tvd_at_shoe : [m]
    bit_pressure_drop : across the nozzles [Pa] (0 without circulation; NaN when unknown)
    string_loss : frictional pressure loss down the string's bore while circulating [Pa]
    bore_flow : flow entering the string at the bit, relative to it [m^3/s], positive up
    """

    terms: FluidTerms
    surge_at_bit: float
    surge_at_shoe: float
    static_at_bit: float
    static_at_shoe: float
    tvd_at_bit: float
    tvd_at_shoe: float
    bit_pressure_drop: float
    string_loss: float
    bore_flow: float

    @property
    def density_at_bit(self) -> float:
        """Equivalent density of the annular pressure at the bit [kg/m^3] (ECD, or the
        static one plus surge or minus swab)."""
        return _equivalent(self.static_at_bit + self.surge_at_bit, self.tvd_at_bit)

    @property
    def density_at_shoe(self) -> float:
        """Equivalent density at the casing shoe [kg/m^3] (NaN without casing)."""
        return _equivalent(self.static_at_shoe + self.surge_at_shoe, self.tvd_at_shoe)


@dataclass(frozen=True)
class TripSpeedLimits:
    """The fastest trips the pressure window allows [m/s] (``inf``: none reaches its limit
    below the fastest looked at; 0: the static mud is outside the window already; NaN: the
    limit is not configured or there is no rheology).

    Attributes
    ----------
    running_in : surge reaching the fracture density at the shoe or at the bit
    pulling_out : swab reaching the pore density at the bit
    """

    running_in: float
    pulling_out: float


def _equivalent(pressure: float, tvd: float) -> float:
    return pressure / (GRAVITY * tvd) if tvd > 0.0 else math.nan


class HydraulicModel:
    """A well prepared for the fluid's forces at any bit depth, block speed and pump rate.

    Parameters
    ----------
    well : the well; its ``hydraulics`` (`tdmon.model.hydraulics.WellHydraulics`) gives the
        rheology, the bit and the pressure window
    grid : its hole grid, when already built (a `WellModel`'s); default ``hole_grid(well)``
    """

    def __init__(self, well: Well, grid: HoleGrid | None = None) -> None:
        self.well = well
        self.grid = hole_grid(well) if grid is None else grid
        self.hydraulics = well.hydraulics
        components = well.string.components
        self._component_top = well.string.component_tops()
        # a component known by its buoyed weight only: its tool joint's diameter, no bore
        self._outer = np.array([c.contact_diameter if math.isnan(c.outer_diameter)
                                else c.outer_diameter for c in components])
        self._inner = np.array([0.0 if math.isnan(c.inner_diameter) else c.inner_diameter
                                for c in components])
        cased = [s.bottom for s in well.sections if s.kind == "cased"]
        self.shoe = max(cased) if cased else None
        fluid = well.fluid
        self._outside = fluid.density
        self._inside = fluid.density if fluid.inside_density is None else fluid.inside_density
        self._element_dtvd = np.diff(self.grid.tvd)
        self._element_length = np.diff(self.grid.md)

    @property
    def n_elements(self) -> int:
        """Elements of the hole grid."""
        return self.grid.n_elements

    def string_in_hole(self, bit_depth: float) -> StringInHole:
        """The string in the hole with the bit at ``bit_depth`` [m], cut at the grid's nodes and
        the components' ends, from the bit up."""
        md = self.grid.md
        top = max(float(md[0]), bit_depth - float(self._component_top[-1]))
        joints = bit_depth - self._component_top[:-1]
        cuts = np.concatenate([md[(md > top) & (md < bit_depth)],
                               joints[(joints > top) & (joints < bit_depth)], [top, bit_depth]])
        cuts = np.unique(cuts)[::-1]  # from the bit up
        bottom, upper = cuts[:-1], cuts[1:]
        middle = 0.5 * (bottom + upper)
        element = np.clip(np.searchsorted(md, middle) - 1, 0, self.n_elements - 1)
        component = np.minimum(np.searchsorted(self._component_top, bit_depth - middle),
                               self._component_top.size - 1)
        return StringInHole(upper, bottom, element.astype(np.int64),
                            component.astype(np.int64),
                            self.grid.element_hole_diameter[element], self._outer[component],
                            self._inner[component])

    def _densities(self, values: ArrayLike | None) -> Array | None:
        if values is None:
            return None
        array = np.asarray(values, dtype=np.float64)
        if array.shape != (self.n_elements,):
            raise ModelError(f"densities must have one value per hole-grid element "
                             f"({self.n_elements}), got shape {array.shape}")
        return array

    def _static(self, depth: float, outside: Array | None) -> tuple[float, float]:
        """Hydrostatic annular pressure [Pa] and TVD [m] at MD ``depth``."""
        md = self.grid.md
        tvd = float(np.interp(depth, md, self.grid.tvd))
        if outside is None:
            return self._outside * GRAVITY * tvd, tvd
        share = np.clip((depth - md[:-1]) / self._element_length, 0.0, 1.0)
        return float(GRAVITY * np.sum(outside * self._element_dtvd * share)), tvd

    def forces(self, bit_depth: float, pipe_speed: float, *, flow_rate: float = 0.0,
               standpipe_pressure: float | None = None, surface_loss: float = 0.0,
               outside_density: ArrayLike | None = None,
               inside_density: ArrayLike | None = None) -> FluidForces:
        """The fluid's forces and pressures at one moment.

        Parameters
        ----------
        bit_depth : [m]
        pipe_speed : the string's speed [m/s], positive running in (the block's speed)
        flow_rate : pump rate down the string [m^3/s]
        standpipe_pressure : measured [Pa]; gives the bit's pressure drop when its nozzles
            are not known (less the modelled string and annulus losses and ``surface_loss``)
        surface_loss : pressure loss of the surface lines between the gauge and the string
            [Pa]
        outside_density, inside_density : per element [kg/m^3] (`tdmon.model.fluid_state`),
            or None: the well's fluid

        Returns
        -------
        FluidForces
        """
        outside = self._densities(outside_density)
        inside = self._densities(inside_density)
        pieces = self.string_in_hole(float(bit_depth))
        sections, group = self._sections(pieces, outside, inside)
        rheology = self.hydraulics.rheology
        flow = max(float(flow_rate), 0.0)
        axial: Array | None = None
        surge = SurgeSwab(np.zeros(sections.length.size), 0.0, 0.0)
        string_loss = 0.0
        if rheology is not None and (pipe_speed != 0.0 or flow > 0.0):
            surge = surge_swab(sections, rheology, float(pipe_speed), flow_rate=flow,
                               closed=self.hydraulics.float_valve,
                               nozzle_area=self.hydraulics.nozzle_area,
                               discharge_coefficient=self.hydraulics.discharge_coefficient)
            axial = self._per_element(pieces, -surge.gradient[group] * np.pi / 4.0
                                      * pieces.outer_diameter * pieces.hole_diameter)
            if flow > 0.0:
                string_loss = self._string_loss(rheology, sections, flow)
        drop = self._bit_drop(flow, sections, surge.pressure, string_loss, standpipe_pressure,
                              surface_loss)
        bit_force = 0.0
        if flow > 0.0 and drop > 0.0:
            bit_force = -float(jet_impact_force(
                flow, float(sections.inside_density[0]), drop,
                self.hydraulics.discharge_coefficient)) - self.hydraulics.pump_open_area * drop
        static_bit, tvd_bit = self._static(float(bit_depth), outside)
        shoe_surge, static_shoe, tvd_shoe = math.nan, math.nan, math.nan
        if self.shoe is not None:
            above = pieces.bottom <= self.shoe + 1e-9
            reach = np.clip(self.shoe - pieces.top, 0.0, pieces.length)
            shoe_surge = float(np.sum(np.where(above, pieces.length, reach)
                                      * surge.gradient[group]))
            static_shoe, tvd_shoe = self._static(self.shoe, outside)
        terms = FluidTerms(axial=axial, bit_force=bit_force, outside_density=outside,
                           inside_density=inside)
        return FluidForces(terms, surge.pressure, shoe_surge, static_bit, static_shoe, tvd_bit,
                           tvd_shoe, drop, string_loss, surge.bore_flow)

    def _sections(self, pieces: StringInHole, outside: Array | None,
                  inside: Array | None) -> tuple[AnnularSections, NDArray[np.intp]]:
        """The pieces as annular sections, neighbours of one geometry and density joined (a
        string has a few: the hydraulics then costs little however fine the grid), and the
        section of each piece."""
        n = pieces.top.size
        rho_o = np.full(n, self._outside) if outside is None else outside[pieces.element]
        rho_i = np.full(n, self._inside) if inside is None else inside[pieces.element]
        table = np.vstack([pieces.hole_diameter, pieces.outer_diameter, pieces.inner_diameter,
                           rho_o, rho_i])
        starts = np.flatnonzero(np.concatenate([[True], np.any(table[:, 1:] != table[:, :-1],
                                                               axis=0)]))
        group = np.cumsum(np.isin(np.arange(n), starts)) - 1
        first = table[:, starts]
        return AnnularSections(np.add.reduceat(pieces.length, starts), first[0], first[1],
                               first[2], first[3], first[4]), group

    def _per_element(self, pieces: StringInHole, per_metre: Array) -> Array:
        """Per-metre values of the pieces as per-metre values of their elements (each
        element's over the part of it the string covers; 0 where it covers none)."""
        n = self.n_elements
        total = np.bincount(pieces.element, weights=per_metre * pieces.length, minlength=n)
        covered = np.bincount(pieces.element, weights=pieces.length, minlength=n)
        return np.asarray(np.divide(total, covered, out=np.zeros(n), where=covered > 0.0))

    def _string_loss(self, rheology: Rheology, sections: AnnularSections,
                     flow: float) -> float:
        """Friction of the pumps' flow down the bore [Pa] (the part of the string in the hole;
        the drill pipe above the rotary table is not counted)."""
        area = sections.bore_area
        moving = area > 0.0
        velocity = np.divide(flow, area, out=np.zeros_like(area), where=moving)
        gradient = pipe_pressure_gradient(rheology, sections.inside_density, velocity,
                                          sections.inner_diameter)
        return float(np.sum(gradient * sections.length))

    def _bit_drop(self, flow: float, sections: AnnularSections, annulus: float,
                  string_loss: float, standpipe_pressure: float | None,
                  surface_loss: float) -> float:
        """The bit's pressure drop [Pa]: the nozzles' (given their area), else the standpipe
        pressure's share left after the modelled losses; 0 without flow, NaN when unknown."""
        if flow <= 0.0:
            return 0.0
        hydraulics = self.hydraulics
        if hydraulics.nozzle_area is not None:
            return float(bit_pressure_drop(flow, float(sections.inside_density[0]),
                                           hydraulics.nozzle_area,
                                           hydraulics.discharge_coefficient))
        if standpipe_pressure is None or hydraulics.rheology is None:
            return math.nan
        return max(float(standpipe_pressure) - surface_loss - string_loss - annulus, 0.0)

    def trip_speed_limits(self, bit_depth: float, *, outside_density: ArrayLike | None = None,
                          inside_density: ArrayLike | None = None,
                          max_speed: float = 5.0) -> TripSpeedLimits:
        """The trip speeds at which surge reaches the fracture density (at the shoe or the
        bit, whichever first) and swab the pore density (at the bit) [m/s], found by Brent's
        method on `forces` (`tdmon.model.hydraulics.critical_trip_speed`)."""
        hydraulics = self.hydraulics
        if hydraulics.rheology is None:
            return TripSpeedLimits(math.nan, math.nan)
        def at(speed: float) -> FluidForces:
            return self.forces(bit_depth, speed, outside_density=outside_density,
                               inside_density=inside_density)

        at_rest = at(0.0)
        running_in = pulling_out = math.nan
        if hydraulics.fracture_density is not None:
            limits = []
            for where in ("bit", "shoe"):
                static = getattr(at_rest, f"static_at_{where}")
                tvd = getattr(at_rest, f"tvd_at_{where}")
                if not math.isfinite(static):
                    continue
                allowed = hydraulics.fracture_density * GRAVITY * tvd - static
                name = f"surge_at_{where}"

                def surge(speed: float, name: str = name) -> float:
                    return float(getattr(at(speed), name))

                limits.append(critical_trip_speed(surge, allowed, max_speed=max_speed))
            running_in = min(limits)
        if hydraulics.pore_density is not None:
            allowed = at_rest.static_at_bit - hydraulics.pore_density * GRAVITY * at_rest.tvd_at_bit
            pulling_out = critical_trip_speed(
                lambda v: -at(-v).surge_at_bit, allowed,
                max_speed=max_speed)
        return TripSpeedLimits(running_in, pulling_out)
