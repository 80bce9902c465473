"""Drill string: components from the bit up, weight per length and buoyancy.

The torque-and-drag kernels only need, per metre of string, the buoyed weight ``w`` [N/m], the
radius at which wall friction acts [m] and, for the limits, the steel cross-section. A component
may give its weight in air (buoyed here with the well's fluid), its buoyed weight directly (used
as is, as in the thesis's Example 7.1), or neither (computed from its dimensions, eq 41).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

__all__ = [
    "GRAVITY",
    "STEEL_DENSITY",
    "DrillString",
    "StringComponent",
    "buoyancy_factor",
    "buoyancy_factor_two_fluids",
    "weight_per_length",
]

STEEL_DENSITY = 7850.0
"""Density of drill-string steel [kg/m3] (the thesis's 7.85 s.g., Table 4)."""

GRAVITY = 9.80665
"""Standard gravity [m/s2]."""


def weight_per_length(
    outer_diameter: ArrayLike,
    inner_diameter: ArrayLike,
    steel_density: float = STEEL_DENSITY,
) -> NDArray[np.float64]:
    """Weight in air of a plain steel tube per unit length [N/m].

    Parameters
    ----------
    outer_diameter, inner_diameter : [m]
    steel_density : [kg/m3]

    Notes
    -----
    ``w = pi/4 (D^2 - d^2) rho_s g``: eq. 41 in [1] without its buoyancy factor, which
    `buoyancy_factor` supplies. Tool joints and upsets are not included; give the weight
    explicitly for a string where they matter (they add some 5-10 % on drill pipe).

    References
    ----------
    .. [1] Author of the seed thesis (2017). Torque and Drag Friction Model: Implemented Friction
       Factor Dependency of Temperature. MSc thesis, University of Stavanger.
    """
    outer = np.asarray(outer_diameter, dtype=np.float64)
    inner = np.asarray(inner_diameter, dtype=np.float64)
    return np.asarray(np.pi / 4.0 * (outer**2 - inner**2) * steel_density * GRAVITY)


def buoyancy_factor(
    mud_density: ArrayLike, steel_density: float = STEEL_DENSITY
) -> NDArray[np.float64]:
    """Buoyancy factor for the same fluid inside and outside the string [-].

    Parameters
    ----------
    mud_density : [kg/m3]
    steel_density : [kg/m3]

    Notes
    -----
    ``beta = 1 - rho_m / rho_s``: eq. 35 in [1]. Buoyed weight = beta x weight in air.

    References
    ----------
    .. [1] The seed thesis, section 4.2.2 (Buoyancy).
    """
    return np.asarray(1.0 - np.asarray(mud_density, dtype=np.float64) / steel_density)


def buoyancy_factor_two_fluids(
    outside_density: ArrayLike,
    inside_density: ArrayLike,
    outer_diameter: ArrayLike,
    inner_diameter: ArrayLike,
    steel_density: float = STEEL_DENSITY,
) -> NDArray[np.float64]:
    """Buoyancy factor with different fluids in the annulus and inside the string [-].

    Parameters
    ----------
    outside_density : annulus fluid density [kg/m3]
    inside_density : density of the fluid inside the string [kg/m3]
    outer_diameter, inner_diameter : of the tube [m]
    steel_density : [kg/m3]

    Notes
    -----
    ``beta = 1 - (rho_o r_o^2 - rho_i r_i^2) / (rho_s (r_o^2 - r_i^2))``: eq. 36 in [1] (which
    prints both radii as ``r``; the outer one goes with the outside fluid). With equal
    densities it reduces to eq. 35.

    References
    ----------
    .. [1] The seed thesis, section 4.2.2 (Buoyancy).
    """
    outer_sq = np.asarray(outer_diameter, dtype=np.float64) ** 2
    inner_sq = np.asarray(inner_diameter, dtype=np.float64) ** 2
    rho_o = np.asarray(outside_density, dtype=np.float64)
    rho_i = np.asarray(inside_density, dtype=np.float64)
    displaced = rho_o * outer_sq - rho_i * inner_sq
    return np.asarray(1.0 - displaced / (steel_density * (outer_sq - inner_sq)))


@dataclass(frozen=True)
class StringComponent:
    """One uniform part of the drill string (drill pipe, heavy-weight, collars, BHA).

    Attributes
    ----------
    name : label, e.g. ``"5in DP"``
    length : [m]
    outer_diameter, inner_diameter : tube body [m]; both NaN when not known, for a component
        given by its buoyed weight (its torque radius is then the tool joint's; the steel
        cross-section and the limits that need it are NaN, i.e. not checked)
    weight_in_air : [N/m], buoyed with the well's fluid; optional
    buoyed_weight : [N/m], used as is; optional. When neither weight is given the weight in air
        comes from eq 41 (`weight_per_length`).
    tool_joint_diameter : [m]; when given, wall friction acts at this radius (torque) and the
        buckling clearance uses it
    yield_strength : minimum yield strength of the steel [Pa]
    makeup_torque : connection make-up torque [N m]
    youngs_modulus : [Pa]
    """

    name: str
    length: float
    outer_diameter: float
    inner_diameter: float
    weight_in_air: float | None = None
    buoyed_weight: float | None = None
    tool_joint_diameter: float | None = None
    yield_strength: float | None = None
    makeup_torque: float | None = None
    youngs_modulus: float = 2.06e11

    def __post_init__(self) -> None:
        if not (math.isfinite(self.length) and self.length > 0.0):
            raise ModelError(
                f"string component '{self.name}': length must be > 0, got {self.length}"
            )
        unknown = math.isnan(self.outer_diameter) and math.isnan(self.inner_diameter)
        if unknown and self.buoyed_weight is None:
            raise ModelError(
                f"string component '{self.name}': without its diameters it needs a buoyed weight"
            )
        if not unknown and not (self.outer_diameter > self.inner_diameter >= 0.0):
            raise ModelError(
                f"string component '{self.name}': need outer diameter > inner diameter >= 0, got "
                f"{self.outer_diameter} and {self.inner_diameter} m"
            )
        for label, value in (("weight_in_air", self.weight_in_air),
                             ("buoyed_weight", self.buoyed_weight)):
            if value is not None and not (math.isfinite(value) and value > 0.0):
                raise ModelError(
                    f"string component '{self.name}': {label} must be > 0, got {value}"
                )

    @property
    def torque_radius(self) -> float:
        """Radius at which wall friction acts [m]: tool joint if given, else the body."""
        diameter = self.tool_joint_diameter or self.outer_diameter
        return 0.5 * diameter

    @property
    def contact_diameter(self) -> float:
        """Largest diameter touching the wall [m] (tool joint if given)."""
        return self.tool_joint_diameter or self.outer_diameter

    @property
    def area(self) -> float:
        """Steel cross-section of the tube body [m2]."""
        return math.pi / 4.0 * (self.outer_diameter**2 - self.inner_diameter**2)

    @property
    def moment_of_inertia(self) -> float:
        """Second moment of area of the tube body [m4]."""
        return math.pi / 64.0 * (self.outer_diameter**4 - self.inner_diameter**4)

    def density_sensitivity(self) -> tuple[float, float]:
        """How the buoyed weight per length changes with the density of the fluid outside and
        inside [N/m per kg/m3]: ``(dw/drho_o, dw/drho_i)``.

        Eq 36 is linear in both densities: ``w = w_air (1 - (rho_o D^2 - rho_i d^2) /
        (rho_s (D^2 - d^2)))``, so ``dw/drho_o = -w_air D^2 / (rho_s (D^2 - d^2))`` and
        ``dw/drho_i = w_air d^2 / (rho_s (D^2 - d^2))`` (``-pi/4 D^2 g`` and ``pi/4 d^2 g`` for
        a plain tube, eq 41). A component given by its ``buoyed_weight`` keeps it: (0, 0).
        """
        if self.buoyed_weight is not None:
            return 0.0, 0.0
        in_air = (self.weight_in_air if self.weight_in_air is not None
                  else float(weight_per_length(self.outer_diameter, self.inner_diameter)))
        outer_sq = self.outer_diameter**2
        inner_sq = self.inner_diameter**2
        scale = in_air / (STEEL_DENSITY * (outer_sq - inner_sq))
        return -scale * outer_sq, scale * inner_sq

    def buoyed_weight_in(
        self, mud_density: float, inside_density: float | None = None
    ) -> float:
        """Buoyed weight per length in the given fluid(s) [N/m].

        ``buoyed_weight`` is returned unchanged; otherwise the weight in air (given, or eq 41)
        times the buoyancy factor of eq 35, or eq 36 when the inside density differs.
        """
        if self.buoyed_weight is not None:
            return float(self.buoyed_weight)
        in_air = (self.weight_in_air if self.weight_in_air is not None
                  else float(weight_per_length(self.outer_diameter, self.inner_diameter)))
        if inside_density is None or inside_density == mud_density:
            factor = float(buoyancy_factor(mud_density))
        else:
            factor = float(buoyancy_factor_two_fluids(
                mud_density, inside_density, self.outer_diameter, self.inner_diameter))
        return in_air * factor


@dataclass(frozen=True)
class DrillString:
    """The drill string as components ordered FROM THE BIT UP.

    The top component is the one cut to length: with the bit at depth ``D`` only the lowest
    ``D`` metres of the string are in the hole.
    """

    components: tuple[StringComponent, ...]

    def __post_init__(self) -> None:
        if not self.components:
            raise ModelError("a drill string needs at least one component")

    @property
    def length(self) -> float:
        """Total length of all components [m]."""
        return float(sum(component.length for component in self.components))

    def reaching(self, depth: float) -> DrillString:
        """This string, its top component lengthened so that the string is at least ``depth``
        [m] long (itself when it already is): what the model assumes when the tally is shorter
        than the bit depth (docs/daemon.md, model coverage)."""
        short = float(depth) - self.length
        if not short > 0.0:
            return self
        top = self.components[-1]
        return DrillString((*self.components[:-1], replace(top, length=top.length + short)))

    def component_tops(self) -> NDArray[np.float64]:
        """Distance from the bit to the top of each component [m], bit-up order."""
        return np.cumsum([component.length for component in self.components], dtype=np.float64)
