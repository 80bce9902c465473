"""Operating limits of the drill string: yield, combined tension and torsion, buckling, make-up
torque; the safe operating window and the flags raised when modelled loads cross it.

Buckling limits are compared with the effective (buoyed) axial force, the one the
torque-and-drag march produces; yield limits with the true axial force, which adds the
hydrostatic pressure on the pipe's end areas (Lubinski's effective-force relation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.model.string import GRAVITY, StringComponent
from tdmon.model.survey import interpolate_survey
from tdmon.model.torque_drag import Loads
from tdmon.model.well import HoleGrid, Well, hole_grid
from tdmon.vocabulary import Operation

__all__ = [
    "Limit",
    "LimitFlag",
    "OperatingWindow",
    "check_limits",
    "combined_tensile_limit",
    "helical_buckling_load",
    "operating_window",
    "radial_clearance",
    "sinusoidal_buckling_load",
    "tensile_limit",
    "true_axial_force",
]

FloatArray = NDArray[np.float64]


class Limit(StrEnum):
    """Which limit a flag is about."""

    TENSILE = "tensile"
    COMBINED = "combined"
    COMPRESSIVE_YIELD = "compressive_yield"
    SINUSOIDAL_BUCKLING = "sinusoidal_buckling"
    HELICAL_BUCKLING = "helical_buckling"
    MAKEUP_TORQUE = "makeup_torque"


def tensile_limit(area: ArrayLike, yield_strength: ArrayLike,
                  safety_factor: float = 1.0) -> FloatArray:
    """Tensile limit of a pipe body [N].

    Parameters
    ----------
    area : steel cross-section [m2]
    yield_strength : [Pa]
    safety_factor : [-]

    Notes
    -----
    ``F_y = A sigma_y / SF``: eq. 28 of the seed thesis (section 4.1).
    """
    return np.asarray(np.asarray(area, dtype=np.float64) * np.asarray(yield_strength)
                      / safety_factor, dtype=np.float64)


def combined_tensile_limit(
    area: ArrayLike,
    yield_strength: ArrayLike,
    torque: ArrayLike,
    outer_diameter: ArrayLike,
    inner_diameter: ArrayLike,
    *,
    tangential_stress: ArrayLike = 0.0,
    safety_factor: float = 1.0,
) -> FloatArray:
    """Tensile limit of a pipe body carrying torque at the same time [N].

    Parameters
    ----------
    area : steel cross-section [m2]
    yield_strength : [Pa]
    torque : [N m]
    outer_diameter, inner_diameter : [m]
    tangential_stress : hoop stress sigma_theta [Pa] (0 without pressure difference)
    safety_factor : [-], applied as in eq 28

    Notes
    -----
    ``F_a = A (sigma_y + tau^2 / (sigma_theta - sigma_y)) / SF`` with the shear stress at the
    outer fibre ``tau = T r_o / J``, ``J = pi/32 (D^4 - d^4)``: eq. 29 of the seed thesis, the
    maximum-principal-stress criterion solved for the axial stress. The thesis gives eq 29
    without a safety factor; it is applied here as in eq 28 so both lines share one margin.
    Where torsion alone reaches yield the limit is 0.
    """
    outer = np.asarray(outer_diameter, dtype=np.float64)
    inner = np.asarray(inner_diameter, dtype=np.float64)
    polar_moment = np.pi / 32.0 * (outer**4 - inner**4)
    shear = np.abs(np.asarray(torque, dtype=np.float64)) * 0.5 * outer / polar_moment
    sigma_y = np.asarray(yield_strength, dtype=np.float64)
    axial_stress = sigma_y + shear**2 / (np.asarray(tangential_stress) - sigma_y)
    limit = np.asarray(area, dtype=np.float64) * axial_stress / safety_factor
    return np.asarray(np.maximum(limit, 0.0), dtype=np.float64)


def radial_clearance(hole_diameter: ArrayLike, pipe_diameter: ArrayLike) -> FloatArray:
    """Radial clearance between pipe and hole, ``(D_hole - D_pipe) / 2`` [m]."""
    return np.asarray(0.5 * (np.asarray(hole_diameter, dtype=np.float64)
                             - np.asarray(pipe_diameter, dtype=np.float64)))


def sinusoidal_buckling_load(
    youngs_modulus: ArrayLike,
    moment_of_inertia: ArrayLike,
    weight: ArrayLike,
    inclination: ArrayLike,
    clearance: ArrayLike,
) -> FloatArray:
    """Compressive load at which sinusoidal buckling starts (Dawson and Paslay) [N].

    Parameters
    ----------
    youngs_modulus : [Pa]
    moment_of_inertia : second moment of area of the pipe [m4]
    weight : buoyed weight per length [N/m]
    inclination : [rad]
    clearance : radial clearance [m] (see `radial_clearance`)

    Notes
    -----
    ``F_sin = sqrt(4 E I w sin(a) / r)``: eq. 30 of the seed thesis, after [1]. The load goes to
    0 in vertical hole, where any compression buckles the pipe (the criterion is meant for
    inclined hole); a flag there says the string is in compression without wall support.

    References
    ----------
    .. [1] Dawson, R. and Paslay, P. R. (1984). Drillpipe buckling in inclined holes. JPT 36(10),
       1734-1738.
    """
    stiffness = np.asarray(youngs_modulus, dtype=np.float64) * np.asarray(moment_of_inertia)
    lateral = np.asarray(weight, dtype=np.float64) * np.abs(np.sin(np.asarray(inclination)))
    return np.asarray(np.sqrt(4.0 * stiffness * lateral / np.asarray(clearance)))


def helical_buckling_load(sinusoidal_load: ArrayLike,
                          helical_factor: float = math.sqrt(2)) -> FloatArray:
    """Compressive load at which helical buckling starts [N].

    Notes
    -----
    ``F_hel = k F_sin`` with ``k = sqrt(2)`` in eq. 31 of the seed thesis. Chen and Cheatham's
    full helical load ``2 (2 sqrt 2 - 1) sqrt(E I w sin a / r)`` is ``k = 2 sqrt 2 - 1 ~ 1.83``
    times eq 30 (a ratio sometimes misquoted as 2 (2 sqrt 2 - 1), which is 3.66). The factor is a
    setting (`tdmon.model.well.LimitSettings.helical_factor`).
    """
    return np.asarray(helical_factor * np.asarray(sinusoidal_load, dtype=np.float64))


def true_axial_force(
    effective_force: ArrayLike,
    tvd: ArrayLike,
    outside_density: float,
    inside_density: float,
    outer_diameter: ArrayLike,
    inner_diameter: ArrayLike,
) -> FloatArray:
    """True (wall) axial force from the effective force [N], tension positive.

    Notes
    -----
    ``F_true = F_eff + p_i A_i - p_o A_o`` with hydrostatic ``p = rho g TVD`` and the areas of the
    outer and inner diameters (Lubinski's effective force read backwards): a string hanging in
    mud has zero effective force at its end but a true compression of ``p A_steel``.
    """
    depth = np.asarray(tvd, dtype=np.float64)
    area_outer = np.pi / 4.0 * np.asarray(outer_diameter, dtype=np.float64) ** 2
    area_inner = np.pi / 4.0 * np.asarray(inner_diameter, dtype=np.float64) ** 2
    p_outside = outside_density * GRAVITY * depth
    p_inside = inside_density * GRAVITY * depth
    return np.asarray(np.asarray(effective_force) + p_inside * area_inner
                      - p_outside * area_outer, dtype=np.float64)


@dataclass(frozen=True)
class OperatingWindow:
    """Limit lines along the string at one bit depth (NaN where a property is not given).

    Attributes
    ----------
    md : node MD, surface to bit [m]
    tensile : tensile limit (eq 28) [N], true force
    combined : tensile limit with the torque of ``torque_operation`` (eq 29) [N], true force
    sinusoidal_buckling : compressive load at sinusoidal buckling (eq 30) [N], effective force
    helical_buckling : compressive load at helical buckling (eq 31) [N], effective force
    makeup_torque : make-up torque of the connections [N m]
    torque_operation : operation whose torque entered ``combined``
    """

    md: FloatArray
    tensile: FloatArray
    combined: FloatArray
    sinusoidal_buckling: FloatArray
    helical_buckling: FloatArray
    makeup_torque: FloatArray
    torque_operation: str


@dataclass(frozen=True)
class LimitFlag:
    """A limit crossed by one operation's loads.

    Attributes
    ----------
    limit : which limit
    operation : the operation whose loads cross it
    md : where the excess is largest [m]
    load : load there (true force for yield, compressive effective force for buckling, torque
        for make-up) [N or N m]
    limit_value : the limit there [N or N m]
    excess : ``load - limit_value`` there [N or N m]
    md_top, md_bottom : MD range of all nodes beyond the limit [m]
    """

    limit: Limit
    operation: str
    md: float
    load: float
    limit_value: float
    excess: float
    md_top: float
    md_bottom: float


@dataclass(frozen=True)
class _NodeProperties:
    area: FloatArray
    outer: FloatArray
    inner: FloatArray
    yield_strength: FloatArray
    makeup: FloatArray
    tvd: FloatArray
    sinusoidal: FloatArray


#: the per-component properties `_node_properties` reads, in `_component_table`'s order
_COMPONENT_PROPERTIES = ("contact_diameter", "youngs_modulus", "moment_of_inertia", "area",
                         "outer_diameter", "inner_diameter", "yield_strength", "makeup_torque")


@lru_cache(maxsize=16)
def _component_table(components: tuple[StringComponent, ...], density: float,
                     inside_density: float | None) -> tuple[FloatArray, ...]:
    """Per component (bit up): the buoyed weight in the fluid [N/m], then the properties of
    `_COMPONENT_PROPERTIES`, NaN where not given; read-only arrays. A string's are the same
    at every bit depth: the calibration's limit check asks once per window, and built each
    time they were nine list comprehensions over the components' properties."""
    columns = [[c.buoyed_weight_in(density, inside_density) for c in components],
               *([getattr(c, name) for c in components] for name in _COMPONENT_PROPERTIES)]
    table = tuple(np.array([np.nan if v is None else v for v in values], dtype=np.float64)
                  for values in columns)
    for array in table:
        array.flags.writeable = False
    return table


def _node_properties(well: Well, loads: Loads, grid: HoleGrid | None) -> _NodeProperties:
    index = loads.component
    (weight, contact_diameter, youngs_modulus, moment_of_inertia, area, outer, inner,
     yield_strength, makeup) = (np.asarray(values[index]) for values in _component_table(
        well.string.components, well.fluid.density, well.fluid.inside_density))
    if grid is None:
        grid = hole_grid(well)
    element = np.clip(np.searchsorted(grid.md, loads.md, side="left") - 1, 0, grid.n_elements - 1)
    hole_diameter = grid.element_hole_diameter[element]
    clearance = radial_clearance(hole_diameter, contact_diameter)
    # the loads carry it when they come from `WellModel.loads` (the same interpolation)
    inclination = (loads.inclination if loads.inclination is not None
                   else interpolate_survey(well.survey, loads.md).inclination)
    sinusoidal = sinusoidal_buckling_load(youngs_modulus, moment_of_inertia, weight,
                                          inclination, np.maximum(clearance, 1e-6))
    return _NodeProperties(area=area, outer=outer, inner=inner, yield_strength=yield_strength,
                           makeup=makeup, tvd=loads.tvd, sinusoidal=sinusoidal)


def operating_window(well: Well, loads: Loads, *, torque_operation: str = Operation.ROTATING,
                     grid: HoleGrid | None = None) -> OperatingWindow:
    """Limit lines along the string at the bit depth of ``loads``.

    Parameters
    ----------
    well : the well (string properties, hole diameters, fluid, limit settings)
    loads : from `tdmon.model.torque_drag.torque_drag`; gives the nodes and the torque
    torque_operation : operation whose torque profile enters the combined limit
    grid : ``hole_grid(well)`` when the caller has it (a `WellModel`'s ``grid``): building it
        is half the cost of a call

    Returns
    -------
    OperatingWindow
    """
    nodes = _node_properties(well, loads, grid)
    safety = well.limits.safety_factor
    return OperatingWindow(
        md=loads.md,
        tensile=tensile_limit(nodes.area, nodes.yield_strength, safety),
        combined=combined_tensile_limit(nodes.area, nodes.yield_strength,
                                        loads.torque[torque_operation], nodes.outer,
                                        nodes.inner, safety_factor=safety),
        sinusoidal_buckling=nodes.sinusoidal,
        helical_buckling=helical_buckling_load(nodes.sinusoidal, well.limits.helical_factor),
        makeup_torque=nodes.makeup,
        torque_operation=torque_operation,
    )


def _flag(limit: Limit, operation: str, md: FloatArray, load: FloatArray,
          limit_value: FloatArray) -> LimitFlag | None:
    with np.errstate(invalid="ignore"):
        crossed = np.isfinite(limit_value) & (load > limit_value)
    if not crossed.any():
        return None
    excess = np.where(crossed, load - limit_value, -np.inf)
    worst = int(np.argmax(excess))
    where = md[crossed]
    return LimitFlag(limit=limit, operation=operation, md=float(md[worst]),
                     load=float(load[worst]), limit_value=float(limit_value[worst]),
                     excess=float(excess[worst]), md_top=float(where.min()),
                     md_bottom=float(where.max()))


def check_limits(well: Well, loads: Loads) -> tuple[LimitFlag, ...]:
    """Every limit crossed by any operation of ``loads``.

    Yield (tensile, combined with that operation's torque, compressive) is checked on the true
    axial force; buckling on the compressive effective force; make-up torque on the torque.

    Parameters
    ----------
    well : the well
    loads : from `tdmon.model.torque_drag.torque_drag`

    Returns
    -------
    tuple of LimitFlag, one per (limit, operation) crossed, empty when all is within limits
    """
    nodes = _node_properties(well, loads, None)
    safety = well.limits.safety_factor
    inside = well.fluid.inside_density
    inside_density = well.fluid.density if inside is None else inside
    tensile = tensile_limit(nodes.area, nodes.yield_strength, safety)
    helical = helical_buckling_load(nodes.sinusoidal, well.limits.helical_factor)
    flags: list[LimitFlag | None] = []
    for operation, effective in loads.axial_force.items():
        torque = np.abs(loads.torque[operation])
        true_force = true_axial_force(effective, nodes.tvd, well.fluid.density, inside_density,
                                      nodes.outer, nodes.inner)
        combined = combined_tensile_limit(nodes.area, nodes.yield_strength, torque, nodes.outer,
                                          nodes.inner, safety_factor=safety)
        combined = np.where(torque > 0.0, combined, np.nan)
        compression = -effective
        flags += [
            _flag(Limit.TENSILE, operation, loads.md, true_force, tensile),
            _flag(Limit.COMBINED, operation, loads.md, true_force, combined),
            _flag(Limit.COMPRESSIVE_YIELD, operation, loads.md, -true_force, tensile),
            _flag(Limit.SINUSOIDAL_BUCKLING, operation, loads.md, compression, nodes.sinusoidal),
            _flag(Limit.HELICAL_BUCKLING, operation, loads.md, compression, helical),
            _flag(Limit.MAKEUP_TORQUE, operation, loads.md, torque, nodes.makeup),
        ]
    return tuple(flag for flag in flags if flag is not None)
