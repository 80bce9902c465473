"""A well as the torque-and-drag model sees it: survey, hole sections, string, fluid, and the
element grid on which friction and loads are evaluated.

The grid (`hole_grid`) belongs to the hole, not to the string: its nodes are fixed in MD
(element spacing, survey stations and section boundaries), so a per-element quantity such as a
temperature-dependent local friction factor is computed once and reused at every bit depth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from tdmon.errors import ModelError
from tdmon.model.hookload_sensor import HookloadSensor
from tdmon.model.hydraulics import WellHydraulics
from tdmon.model.string import DrillString
from tdmon.model.survey import Survey, interpolate_survey

__all__ = [
    "Fluid",
    "HoleGrid",
    "HoleSection",
    "LimitSettings",
    "Well",
    "hole_grid",
    "section_friction",
]

# Nodes closer than this [m] are merged when the grid is built.
_NODE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class HoleSection:
    """A stretch of hole with one diameter and one kind of wall.

    Attributes
    ----------
    top, bottom : measured depth [m]
    diameter : hole or casing inner diameter [m]
    kind : ``"cased"`` or ``"open"``
    friction : friction factor [-], or None when friction comes from elsewhere (mu(T) models)
    """

    top: float
    bottom: float
    diameter: float
    kind: Literal["cased", "open"]
    friction: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.top) and math.isfinite(self.bottom) and self.bottom > self.top):
            raise ModelError(
                f"hole section {self.top}..{self.bottom} m: bottom must lie below top"
            )
        if not self.diameter > 0.0:
            raise ModelError(f"hole section {self.top}..{self.bottom} m: diameter must be > 0")
        if self.kind not in ("cased", "open"):
            raise ModelError(
                f"hole section {self.top}..{self.bottom} m: kind must be 'cased' or 'open', "
                f"got {self.kind!r}"
            )
        if self.friction is not None and not (math.isfinite(self.friction) and self.friction >= 0):
            raise ModelError(
                f"hole section {self.top}..{self.bottom} m: friction must be >= 0, "
                f"got {self.friction}"
            )


@dataclass(frozen=True)
class Fluid:
    """Drilling fluid densities [kg/m3]; ``inside_density`` None means the same fluid inside."""

    density: float
    inside_density: float | None = None


@dataclass(frozen=True)
class LimitSettings:
    """Settings of the operating limits.

    Attributes
    ----------
    safety_factor : divides the tensile limits (eq 28) [-]
    helical_factor : helical buckling load over sinusoidal (eq 31 uses sqrt 2; full helical
        buckling after Chen and Cheatham is 2 sqrt 2 - 1 ~ 1.83 times the sinusoidal load) [-]
    """

    safety_factor: float = 1.0
    helical_factor: float = math.sqrt(2)


@dataclass(frozen=True)
class Well:
    """Everything the torque-and-drag model needs about one well.

    Attributes
    ----------
    survey : minimum-curvature survey covering the hole
    string : drill string, components from the bit up
    sections : hole sections, contiguous, top down
    fluid : drilling fluid
    block_weight : travelling-block weight included in the hook load [N]
    element_length : target element length of the grid [m]
    limits : settings of the operating limits
    name : label
    hookload_sensor : how the rig's hook-load channel reads the load on the hook (sensor
        location, lines, sheave efficiency; :mod:`tdmon.model.hookload_sensor`); the default
        reads the load on the hook
    hydraulics : the mud's rheology, the bit's nozzles and float valve, the pore and fracture
        pressures (:mod:`tdmon.model.hydraulics`); the default knows none of them, and the
        model then has no fluid forces but buoyancy
    """

    survey: Survey
    string: DrillString
    sections: tuple[HoleSection, ...]
    fluid: Fluid
    block_weight: float = 0.0
    element_length: float = 10.0
    limits: LimitSettings = field(default_factory=LimitSettings)
    name: str = ""
    hookload_sensor: HookloadSensor = field(default_factory=HookloadSensor)
    hydraulics: WellHydraulics = field(default_factory=WellHydraulics)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.element_length) and self.element_length > 0.0):
            raise ModelError(f"element length must be > 0, got {self.element_length}")
        if not self.sections:
            raise ModelError("a well needs at least one hole section")
        for upper, lower in zip(self.sections[:-1], self.sections[1:], strict=True):
            if abs(lower.top - upper.bottom) > 1e-6:
                raise ModelError(
                    f"hole sections must be contiguous and ordered top down: section ending at "
                    f"{upper.bottom} m is followed by one starting at {lower.top} m"
                )
        top, bottom = self.sections[0].top, self.sections[-1].bottom
        if top < self.survey.md[0] - 1e-6 or bottom > self.survey.md[-1] + 1e-6:
            raise ModelError(
                f"hole sections {top}..{bottom} m reach beyond the survey "
                f"{self.survey.md[0]}..{self.survey.md[-1]} m"
            )

    @property
    def hole_top(self) -> float:
        """MD of the top of the hole (normally 0) [m]."""
        return float(self.sections[0].top)

    @property
    def hole_bottom(self) -> float:
        """MD of the bottom of the deepest hole section [m]."""
        return float(self.sections[-1].bottom)


@dataclass(frozen=True)
class HoleGrid:
    """Element grid of the hole, nodes top down.

    Attributes
    ----------
    md, inclination, azimuth, tvd, north, east : at the ``n + 1`` nodes [m, rad]
    dogleg : dogleg of each element (between nodes i and i+1) [rad], shape (n,)
    element_section : index into ``well.sections`` of each element, shape (n,)
    element_kind : ``"cased"`` or ``"open"`` per element, shape (n,)
    element_hole_diameter : [m], shape (n,)
    """

    md: NDArray[np.float64]
    inclination: NDArray[np.float64]
    azimuth: NDArray[np.float64]
    tvd: NDArray[np.float64]
    north: NDArray[np.float64]
    east: NDArray[np.float64]
    dogleg: NDArray[np.float64]
    element_section: NDArray[np.int64]
    element_kind: NDArray[np.str_]
    element_hole_diameter: NDArray[np.float64]

    @property
    def n_elements(self) -> int:
        """Number of elements (nodes - 1)."""
        return int(self.md.size - 1)

    @property
    def element_mid_md(self) -> NDArray[np.float64]:
        """MD of the element midpoints [m]."""
        return np.asarray(0.5 * (self.md[:-1] + self.md[1:]))


def _merge_nodes(candidates: NDArray[np.float64]) -> NDArray[np.float64]:
    nodes = np.unique(candidates)
    keep = np.concatenate([[True], np.diff(nodes) > _NODE_TOLERANCE])
    merged = nodes[keep]
    merged[-1] = nodes[-1]  # the hole bottom wins over a node just above it
    return merged


def hole_grid(well: Well) -> HoleGrid:
    """Element grid over the hole's MD range.

    Nodes are placed every ``well.element_length`` from the top of the hole, at every survey
    station inside the hole and at every section boundary, so each element lies in one section
    and on one minimum-curvature arc.

    Parameters
    ----------
    well : the well

    Returns
    -------
    HoleGrid
    """
    top, bottom = well.hole_top, well.hole_bottom
    n_regular = max(1, math.ceil((bottom - top) / well.element_length - 1e-9))
    regular = top + well.element_length * np.arange(n_regular + 1, dtype=np.float64)
    stations = well.survey.md[(well.survey.md > top) & (well.survey.md < bottom)]
    boundaries = np.array([section.bottom for section in well.sections], dtype=np.float64)
    candidates = np.concatenate([regular[regular < bottom], stations, boundaries, [top, bottom]])
    md = _merge_nodes(candidates)

    path = interpolate_survey(well.survey, md)
    mid = 0.5 * (md[:-1] + md[1:])
    bottoms = np.array([section.bottom for section in well.sections])
    section_index = np.minimum(np.searchsorted(bottoms, mid), len(well.sections) - 1)
    kinds = np.array([section.kind for section in well.sections])
    diameters = np.array([section.diameter for section in well.sections], dtype=np.float64)
    return HoleGrid(
        md=md,
        inclination=path.inclination,
        azimuth=path.azimuth,
        tvd=path.tvd,
        north=path.north,
        east=path.east,
        dogleg=path.dogleg[1:].copy(),
        element_section=section_index.astype(np.int64),
        element_kind=kinds[section_index],
        element_hole_diameter=diameters[section_index],
    )


def section_friction(well: Well, grid: HoleGrid) -> NDArray[np.float64]:
    """Friction factor of every grid element from its hole section's ``friction`` [-].

    Raises
    ------
    ModelError
        A section has no friction factor.
    """
    values = []
    for section in well.sections:
        if section.friction is None:
            raise ModelError(
                f"hole section {section.top}..{section.bottom} m has no friction factor: give "
                "one, or pass mu explicitly"
            )
        values.append(section.friction)
    return np.asarray(np.array(values, dtype=np.float64)[grid.element_section])
