"""Drilling hydraulics for the torque-and-drag model: frictional pressure gradients in the pipe and
the annulus, the flow a moving string drives (Burkhardt's clinging constant), surge and swab,
the trip speed that reaches a pressure limit, and the bit's pressure drop and jet force.

Pure functions of floats and numpy arrays, SI throughout (Pa, m, m/s, m^3/s, kg/m^3). The
rheology is a `tdmon.model.rheology.Rheology`. Velocities are signed along an axis of the
caller's choice, and a gradient is the frictional pressure drop per metre along that axis, with
the sign of the velocity (so along the upward axis, a flow up the annulus gives a positive
gradient: the pressure rises with depth). Where the string is (which component at which depth) is
`tdmon.model.fluid_force`'s business; here a string is a list of annular sections.

Flow regime (Bourgoyne et al. 1986, section 4.6-4.7, in SI): laminar pipe flow of a Bingham
plastic ``dp/dL = 32 mu_p v / d^2 + 16 tau_y / (3 d)`` (eq. 4.59, the Buckingham equation
without its fourth-power plug term) and of a power law ``4 K / d ((3n + 1) / (4n) 8 v / d)^n``;
the annulus as a slot of gap ``d2 - d1``: ``48 mu_p v / (d2 - d1)^2 + 6 tau_y / (d2 - d1)``
(eq. 4.77) and ``4 K / (d2 - d1) ((2n + 1) / (3n) 12 v / (d2 - d1))^n``. Turbulent flow:
Fanning ``dp/dL = 2 f rho v^2 / d``, the Blasius ``f = 0.0791 Re^-0.25`` with ``Re = rho v d /
mu_p`` for the Bingham plastic (eq. 4.66) and Dodge and Metzner's (1959) implicit ``f`` of the
generalised Reynolds number for the power law (eq. 4.69-4.70), on the equivalent diameter
``0.816 (d2 - d1)`` in the annulus (eq. 4.79). The Reynolds number of a Bingham plastic uses its
apparent viscosity (``mu_p + tau_y d / (6 v)`` in the pipe, ``mu_p + tau_y (d2 - d1) / (8 v)``
in the annulus, which turn the laminar equations into Newtonian ones). The flow is laminar
below `REYNOLDS_CRITICAL`; above it the larger of the laminar and turbulent gradients is taken,
so that the gradient rises with the velocity (a bracketed root solve needs that).

References
----------
.. [1] Bourgoyne, A. T., Millheim, K. K., Chenevert, M. E. and Young, F. S. (1986). Applied
   Drilling Engineering. SPE Textbook Series vol. 2, chapter 4.
.. [2] Burkhardt, J. A. (1961). Wellbore pressure surges produced by pipe movement. JPT 13(6),
   595-605 (SPE 1546-G).
.. [3] Dodge, D. W. and Metzner, A. B. (1959). Turbulent flow of non-Newtonian systems. AIChE
   Journal 5(2), 189-204.
.. [4] Guo, B. and Liu, G. (2011). Applied Drilling Circulation Systems. Gulf Professional
   Publishing, section 2.7 (surge and swab; the clinging-constant fits, eq. 2.81-2.82).
.. [5] API RP 13D (2010), Rheology and Hydraulics of Oil-well Drilling Fluids.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError
from tdmon.model.rheology import Rheology

__all__ = [
    "DISCHARGE_COEFFICIENT",
    "EQUIVALENT_DIAMETER_FACTOR",
    "REGIMES",
    "REYNOLDS_CRITICAL",
    "AnnularSections",
    "Regime",
    "SurgeSwab",
    "WellHydraulics",
    "annulus_pressure_gradient",
    "bit_pressure_drop",
    "clinging_constant",
    "critical_trip_speed",
    "effective_annular_velocity",
    "jet_impact_force",
    "nozzle_area",
    "pipe_pressure_gradient",
    "surge_swab",
]

REYNOLDS_CRITICAL: Final = 2100.0
"""Reynolds number below which the flow is taken as laminar [-] (Bourgoyne et al. 1986,
section 4.6)."""

EQUIVALENT_DIAMETER_FACTOR: Final = 0.816
"""Equivalent diameter of an annulus in turbulent flow over its gap ``d2 - d1`` [-]
(Crittendon's criterion as Bourgoyne et al. 1986 use it, eq. 4.79)."""

DISCHARGE_COEFFICIENT: Final = 0.95
"""Discharge coefficient of bit nozzles [-] (Bourgoyne et al. 1986, eq. 4.31)."""

Regime = Literal["auto", "laminar", "turbulent"]
REGIMES: Final[tuple[str, ...]] = get_args(Regime)
"""``"auto"`` chooses by the Reynolds number (the module's notes); the others force one (a
published example that states its regime)."""

_BLASIUS: Final = 0.0791
_TINY: Final = 1e-12

Array = NDArray[np.float64]


def _floats(value: ArrayLike) -> Array:
    return np.asarray(value, dtype=np.float64)


def _laminar(rheology: Rheology, speed: Array, gap: Array, annulus: bool) -> Array:
    """Laminar gradient [Pa/m] at ``speed`` >= 0 in a pipe of diameter ``gap`` or a slot of
    gap ``gap`` (``annulus``)."""
    safe = np.where(gap > 0.0, gap, 1.0)
    if rheology.model == "bingham":
        mu, tau = rheology.plastic_viscosity, rheology.yield_point
        if annulus:
            return np.asarray(48.0 * mu * speed / safe**2 + 6.0 * tau / safe)
        return np.asarray(32.0 * mu * speed / safe**2 + 16.0 * tau / (3.0 * safe))
    n, k = rheology.flow_index, rheology.consistency
    if annulus:
        rate = (2.0 * n + 1.0) / (3.0 * n) * 12.0 * speed / safe
    else:
        rate = (3.0 * n + 1.0) / (4.0 * n) * 8.0 * speed / safe
    return np.asarray(4.0 * k / safe * rate**n)


def _reynolds(rheology: Rheology, density: Array, speed: Array, gap: Array,
              annulus: bool) -> Array:
    """Reynolds number of the flow [-]: on the apparent viscosity (Bingham plastic) or the
    Metzner-Reed generalised form (power law), on the equivalent diameter in an annulus."""
    diameter = EQUIVALENT_DIAMETER_FACTOR * gap if annulus else gap
    moving = np.maximum(speed, _TINY)
    if rheology.model == "bingham":
        tau = rheology.yield_point
        apparent = rheology.plastic_viscosity + tau * gap / ((8.0 if annulus else 6.0) * moving)
        return np.asarray(density * speed * diameter / apparent)
    n, k = rheology.flow_index, rheology.consistency
    shape = ((3.0 * n + 1.0) / (4.0 * n)) ** n * 8.0 ** (n - 1.0)
    return np.asarray(density * moving ** (2.0 - n) * diameter**n / (k * shape))


def _fanning_dodge_metzner(reynolds: Array, n: float) -> Array:
    """Fanning friction factor of a power-law fluid in turbulent flow [-]: Dodge and Metzner's
    ``1/sqrt(f) = 4/n^0.75 log10(Re f^(1 - n/2)) - 0.395/n^1.2``, solved by fixed point
    (a contraction: 25 passes leave it converged to double precision at Re >= 2100)."""
    a = 4.0 / n**0.75
    b = 0.395 / n**1.2
    log_re = np.log10(np.maximum(reynolds, REYNOLDS_CRITICAL))
    x = np.full_like(log_re, 10.0)  # x = 1/sqrt(f)
    for _ in range(25):
        x = a * (log_re - (1.0 - 0.5 * n) * 2.0 * np.log10(x)) - b
    return np.asarray(1.0 / x**2)


def _turbulent(rheology: Rheology, density: Array, speed: Array, gap: Array, annulus: bool,
               reynolds: Array) -> Array:
    """Turbulent gradient [Pa/m], Fanning ``2 f rho v^2 / d`` on the (equivalent) diameter."""
    diameter = np.where(gap > 0.0, EQUIVALENT_DIAMETER_FACTOR * gap if annulus else gap, 1.0)
    if rheology.model == "bingham":
        plastic = density * speed * diameter / rheology.plastic_viscosity
        fanning = _BLASIUS / np.maximum(plastic, 1.0) ** 0.25
    else:
        fanning = _fanning_dodge_metzner(reynolds, rheology.flow_index)
    return np.asarray(2.0 * fanning * density * speed**2 / diameter)


def _gradient(rheology: Rheology, density: ArrayLike, velocity: ArrayLike, gap: ArrayLike,
              annulus: bool, regime: Regime) -> Array:
    v = _floats(velocity)
    rho = _floats(density)
    g = _floats(gap)
    speed = np.abs(v)
    laminar = _laminar(rheology, speed, g, annulus)
    reynolds = _reynolds(rheology, rho, speed, g, annulus)
    if regime == "laminar":
        turbulent_flow = np.zeros(reynolds.shape, dtype=bool)
    elif regime == "turbulent":
        turbulent_flow = np.ones(reynolds.shape, dtype=bool)
        laminar = _turbulent(rheology, rho, speed, g, annulus, reynolds)
    elif regime == "auto":
        turbulent_flow = reynolds >= REYNOLDS_CRITICAL
    else:
        raise ModelError(f"unknown flow regime {regime!r}: use one of {', '.join(REGIMES)}")
    if regime == "auto" and np.any(turbulent_flow):
        turbulent = _turbulent(rheology, rho, speed, g, annulus, reynolds)
        laminar = np.where(turbulent_flow, np.maximum(laminar, turbulent), laminar)
    return np.asarray(np.where((speed > 0.0) & (g > 0.0), np.sign(v) * laminar, 0.0))


def pipe_pressure_gradient(rheology: Rheology, density: ArrayLike, velocity: ArrayLike,
                           diameter: ArrayLike, regime: Regime = "auto") -> Array:
    """Frictional pressure gradient of flow in a pipe [Pa/m], with the sign of ``velocity``.

    Parameters
    ----------
    rheology : the fluid's rheology
    density : [kg/m^3]
    velocity : mean velocity relative to the pipe wall [m/s], along some axis
    diameter : inner diameter [m]
    regime : ``"auto"`` (by the Reynolds number), ``"laminar"`` or ``"turbulent"``

    Returns
    -------
    the pressure drop per metre along that axis [Pa/m]

    Notes
    -----
    Laminar: ``32 mu_p v / d^2 + 16 tau_y / (3 d)`` (Bingham plastic, eq. 4.59 in [1]) or
    ``4 K / d ((3n + 1) / (4n) 8 v / d)^n`` (power law, eq. 4.64a); turbulent:
    ``2 f rho v^2 / d`` (see the module's notes). 0 where the velocity is 0.

    References
    ----------
    .. [1] Bourgoyne et al. (1986), Applied Drilling Engineering, section 4.6.
    """
    return _gradient(rheology, density, velocity, diameter, False, regime)


def annulus_pressure_gradient(rheology: Rheology, density: ArrayLike, velocity: ArrayLike,
                              hole_diameter: ArrayLike, pipe_diameter: ArrayLike,
                              regime: Regime = "auto") -> Array:
    """Frictional pressure gradient of flow in a concentric annulus [Pa/m], slot approximation,
    with the sign of ``velocity``.

    Parameters
    ----------
    rheology : the fluid's rheology
    density : [kg/m^3]
    velocity : mean (or effective, `effective_annular_velocity`) velocity [m/s], along some axis
    hole_diameter, pipe_diameter : d2 and d1 [m]
    regime : ``"auto"`` (by the Reynolds number), ``"laminar"`` or ``"turbulent"``

    Returns
    -------
    the pressure drop per metre along that axis [Pa/m]

    Notes
    -----
    Laminar: ``48 mu_p v / (d2 - d1)^2 + 6 tau_y / (d2 - d1)`` (Bingham plastic, eq. 4.77 in
    [1]) or ``4 K / (d2 - d1) ((2n + 1) / (3n) 12 v / (d2 - d1))^n`` (power law, eq. 4.78a);
    turbulent on ``0.816 (d2 - d1)``. 0 where the velocity or the gap is 0.

    References
    ----------
    .. [1] Bourgoyne et al. (1986), Applied Drilling Engineering, section 4.7.
    """
    gap = _floats(hole_diameter) - _floats(pipe_diameter)
    return _gradient(rheology, density, velocity, gap, True, regime)


def clinging_constant(diameter_ratio: ArrayLike, turbulent: ArrayLike = False) -> Array:
    """Burkhardt's clinging constant K [-]: the share of the pipe's speed that the fluid it
    drags adds to the annular velocity.

    Parameters
    ----------
    diameter_ratio : alpha = pipe outer diameter over hole diameter [-]
    turbulent : whether the annular flow is turbulent

    Notes
    -----
    Laminar flow: the Newtonian solution of a concentric annulus whose inner wall slides at
    ``v_p`` (Couette flow with ``u = v_p ln(r / r2) / ln(alpha)``) carries
    ``K = (alpha^2 - 1 - 2 alpha^2 ln alpha) / (2 (1 - alpha^2) ln alpha)`` of it over the
    annulus area: 0 for a thin wire, 1/2 for a narrow slot; it is Burkhardt's laminar curve
    [1] (Guo and Liu's fit ``0.275 alpha + 0.25``, eq. 2.81 in [2], is within 0.005 of it for
    0.4 < alpha < 0.75 and 0.017 for 0.3 < alpha < 0.9). Turbulent flow:
    ``K = 0.1 alpha + 0.41``, Guo and Liu's fit of Burkhardt's turbulent curve (eq. 2.82 in
    [2]).

    References
    ----------
    .. [1] Burkhardt (1961), JPT 13(6), 595-605, Fig. 6.
    .. [2] Guo and Liu (2011), Applied Drilling Circulation Systems, section 2.7.
    """
    alpha = np.clip(_floats(diameter_ratio), 0.0, 1.0)
    safe = np.clip(alpha, 1e-6, 1.0 - 1e-6)
    log = np.log(safe)
    laminar = (safe**2 - 1.0 - 2.0 * safe**2 * log) / (2.0 * (1.0 - safe**2) * log)
    laminar = np.where(alpha <= 0.0, 0.0, np.where(alpha >= 1.0 - 1e-6, 0.5, laminar))
    return np.asarray(np.where(np.asarray(turbulent, dtype=bool), 0.1 * alpha + 0.41, laminar))


def effective_annular_velocity(rheology: Rheology, density: ArrayLike, annular_flow: ArrayLike,
                               pipe_velocity: float, hole_diameter: ArrayLike,
                               pipe_diameter: ArrayLike,
                               clinging: float | None = None) -> Array:
    """The mean velocity of a stationary-wall annular flow with the same friction [m/s].

    Parameters
    ----------
    rheology, density : the fluid [-, kg/m^3]
    annular_flow : volume flow through the annulus [m^3/s], along some axis
    pipe_velocity : the string's velocity along the same axis [m/s]
    hole_diameter, pipe_diameter : d2, d1 [m]
    clinging : a clinging constant to use instead of Burkhardt's (e.g. 0.45, a common field
        value) [-]

    Notes
    -----
    ``v_e = q_a / A_a - K v_pipe`` (Burkhardt [1]): the moving pipe drags ``K v_pipe A_a`` of
    fluid along, so the pressure gradient drives ``q_a - K v_pipe A_a``. When the string moves
    against the flow it drives (surge, swab) the two add: ``|v_e| = |q_a| / A_a + K |v_p|``
    (eq. 2.80 in [2]). K is the laminar one (`clinging_constant`) unless the flow at that
    velocity is turbulent, then the turbulent one.

    References
    ----------
    .. [1] Burkhardt (1961), JPT 13(6), 595-605.
    .. [2] Guo and Liu (2011), Applied Drilling Circulation Systems, section 2.7.
    """
    d2 = _floats(hole_diameter)
    d1 = _floats(pipe_diameter)
    area = np.pi / 4.0 * (d2**2 - d1**2)
    mean = _floats(annular_flow) / np.where(area > 0.0, area, np.inf)
    if clinging is not None:
        return np.asarray(mean - clinging * pipe_velocity)
    ratio = d1 / np.where(d2 > 0.0, d2, np.inf)
    velocity = mean - clinging_constant(ratio) * pipe_velocity
    reynolds = _reynolds(rheology, _floats(density), np.abs(velocity), d2 - d1, annulus=True)
    turbulent = reynolds >= REYNOLDS_CRITICAL
    if np.any(turbulent):
        velocity = mean - clinging_constant(ratio, turbulent) * pipe_velocity
    return np.asarray(velocity)


def nozzle_area(diameters: ArrayLike) -> float:
    """Total flow area of a bit's nozzles [m^2] from their diameters [m] (a nozzle of n/32 in is
    ``n / 32 * 0.0254`` m)."""
    d = _floats(diameters)
    return float(np.pi / 4.0 * np.sum(d**2))


def bit_pressure_drop(flow_rate: ArrayLike, density: ArrayLike, nozzle_area: float,
                      discharge_coefficient: float = DISCHARGE_COEFFICIENT) -> Array:
    """Pressure drop across the bit's nozzles [Pa], with the sign of ``flow_rate``.

    Notes
    -----
    ``dp_b = rho q^2 / (2 C_d^2 A_t^2)`` (eq. 4.31 in [1]; in field units
    ``8.311e-5 rho q^2 / (C_d^2 A_t^2)``).

    References
    ----------
    .. [1] Bourgoyne et al. (1986), Applied Drilling Engineering, section 4.5.
    """
    if not nozzle_area > 0.0:
        raise ModelError(f"nozzle area must be > 0 m^2, got {nozzle_area}")
    q = _floats(flow_rate)
    return np.asarray(_floats(density) * q * np.abs(q)
                      / (2.0 * discharge_coefficient**2 * nozzle_area**2))


def jet_impact_force(flow_rate: ArrayLike, density: ArrayLike, bit_drop: ArrayLike,
                     discharge_coefficient: float = DISCHARGE_COEFFICIENT) -> Array:
    """The jets' momentum flux [N]: what the bit's nozzles push on the fluid, and so the force
    the fluid pushes the string up with at the bit.

    Notes
    -----
    ``F_j = rho q v_n = C_d q sqrt(2 rho dp_b)`` (the hydraulic impact force, eq. 4.34 in [1];
    in field units ``0.01823 C_d q sqrt(rho dp_b)``), with ``v_n = C_d sqrt(2 dp_b / rho)`` the
    nozzle velocity. For a string hanging off bottom it is the whole of what the flow through
    the bit changes in the effective force at the bit (docs/hydraulics.md).

    References
    ----------
    .. [1] Bourgoyne et al. (1986), Applied Drilling Engineering, section 4.5.
    """
    q = np.abs(_floats(flow_rate))
    drop = np.maximum(_floats(bit_drop), 0.0)
    return np.asarray(discharge_coefficient * q * np.sqrt(2.0 * _floats(density) * drop))


@dataclass(frozen=True)
class AnnularSections:
    """The string in the hole as sections of one geometry each, any order.

    Attributes
    ----------
    length : [m]
    hole_diameter : d2 [m]
    outer_diameter : the pipe's, d1 [m]
    inner_diameter : the pipe's bore [m] (0 for a solid section)
    density : fluid density in the annulus [kg/m^3]
    inside_density : fluid density in the bore [kg/m^3]
    """

    length: Array
    hole_diameter: Array
    outer_diameter: Array
    inner_diameter: Array
    density: Array
    inside_density: Array

    @property
    def outer_area(self) -> Array:
        """pi/4 d1^2 [m^2]."""
        return np.asarray(np.pi / 4.0 * self.outer_diameter**2)

    @property
    def annular_area(self) -> Array:
        """pi/4 (d2^2 - d1^2) [m^2]."""
        return np.asarray(np.pi / 4.0 * (self.hole_diameter**2 - self.outer_diameter**2))

    @property
    def bore_area(self) -> Array:
        """pi/4 d_i^2 [m^2]."""
        return np.asarray(np.pi / 4.0 * self.inner_diameter**2)


@dataclass(frozen=True)
class SurgeSwab:
    """The annular flow a moving (and circulating) string drives.

    Attributes
    ----------
    gradient : frictional pressure gradient in the annulus per section [Pa/m], positive where
        the pressure rises with depth (surge, or circulation up the annulus)
    bore_flow : flow entering the string at the bit, relative to the pipe [m^3/s], positive up
        the bore (negative: the pumps' rate going down)
    pressure : the frictional annular pressure at the bottom of the sections, sum of gradient
        times length [Pa] (surge positive, swab negative)
    """

    gradient: Array
    bore_flow: float
    pressure: float


def _annulus_gradients(sections: AnnularSections, rheology: Rheology, pipe_speed: float,
                       bore_flow: float, clinging: float | None, regime: Regime) -> Array:
    """Annular gradients [Pa/m] with ``bore_flow`` [m^3/s] entering the string at the bit."""
    # along the upward axis: the annulus carries up what passes down (steel and bore) less what
    # enters the bore; a flow up raises the pressure below, dp/dz > 0 with z down
    flow_up = pipe_speed * sections.outer_area - bore_flow
    velocity = effective_annular_velocity(rheology, sections.density, flow_up, -pipe_speed,
                                          sections.hole_diameter, sections.outer_diameter,
                                          clinging)
    return np.asarray(annulus_pressure_gradient(rheology, sections.density, velocity,
                                                sections.hole_diameter, sections.outer_diameter,
                                                regime))


def surge_swab(sections: AnnularSections, rheology: Rheology, pipe_speed: float, *,
               flow_rate: float = 0.0, closed: bool = True, nozzle_area: float | None = None,
               clinging: float | None = None,
               discharge_coefficient: float = DISCHARGE_COEFFICIENT,
               regime: Regime = "auto") -> SurgeSwab:
    """The frictional annular pressure of a string moving at ``pipe_speed`` [m/s] (positive
    running in) while the pumps deliver ``flow_rate`` [m^3/s] down the string.

    Parameters
    ----------
    sections : the string in the hole, from the bit to surface (`AnnularSections`)
    rheology : the mud's
    pipe_speed : [m/s], positive down (surge), negative up (swab)
    flow_rate : pump rate down the string [m^3/s]; when > 0 it sets the flow through the bit
    closed : a float valve (or a closed end) keeps fluid from entering the string at the bit
    nozzle_area : the bit's total flow area [m^2] (None: an open-ended string)
    clinging : a clinging constant instead of Burkhardt's [-]
    discharge_coefficient : of the nozzles [-]
    regime : of the annular and bore flow (``"auto"``: by the Reynolds number)

    Notes
    -----
    At a depth where the string's outer area is ``A_o`` the annulus carries, up,
    ``q_a = v_p A_o - Q_b`` [1]: the steel and bore of the string passing that depth, less
    what enters the bore at the bit (``Q_b``, up the bore). A closed string takes none
    (``Q_b = 0``); the pumps set ``Q_b = -q_pump``; an open string takes the share that gives
    both paths the same frictional pressure at the bit (Burkhardt [2], Bourgoyne et al. [1]
    section 4.10): ``sum(g_a L) = sum(g_pipe L) + dp_bit``, the bore's gradient on the
    velocity relative to the pipe ``Q_b / A_i`` and ``dp_bit`` the nozzles' (`bit_pressure_drop`),
    solved by Brent's method between no inflow and the inflow that stops every annular flow.
    The hydrostatic columns inside and outside are taken as balanced (the U-tube is
    `tdmon.model.fluid_state`'s). The annular gradient at each section comes from the effective
    velocity `effective_annular_velocity`.

    References
    ----------
    .. [1] Bourgoyne et al. (1986), Applied Drilling Engineering, section 4.10 (surge
       pressures due to pipe movement).
    .. [2] Burkhardt (1961), JPT 13(6), 595-605.
    """
    speed = float(pipe_speed)
    if flow_rate > 0.0:
        bore = -float(flow_rate)
    elif closed or speed == 0.0:
        bore = 0.0
    else:
        bore = _open_string_inflow(sections, rheology, speed, nozzle_area, clinging,
                                   discharge_coefficient, regime)
    gradient = _annulus_gradients(sections, rheology, speed, bore, clinging, regime)
    return SurgeSwab(gradient, bore, float(np.sum(gradient * sections.length)))


def _open_string_inflow(sections: AnnularSections, rheology: Rheology, speed: float,
                        nozzle_area: float | None, clinging: float | None,
                        discharge_coefficient: float, regime: Regime) -> float:
    """The flow up the bore of an open string that balances the two paths' friction [m^3/s]."""
    bore_area = sections.bore_area
    if not np.any(bore_area > 0.0):
        return 0.0
    relative = np.where(bore_area > 0.0, bore_area, np.inf)

    def imbalance(bore_flow: float) -> float:
        annulus = np.sum(_annulus_gradients(sections, rheology, speed, bore_flow, clinging,
                                            regime) * sections.length)
        # the bore carries bore_flow up relative to the pipe: the pressure at its bottom exceeds
        # the surface's by the friction of that upward flow
        inside = np.sum(pipe_pressure_gradient(rheology, sections.inside_density,
                                               bore_flow / relative,
                                               sections.inner_diameter, regime)
                        * sections.length)
        nozzles = 0.0 if nozzle_area is None else float(bit_pressure_drop(
            bore_flow, float(sections.inside_density[0]), nozzle_area, discharge_coefficient))
        return float(annulus - inside - nozzles)

    # past this inflow the annular flow runs the other way everywhere (K < 0.6 in
    # `clinging_constant`): the imbalance changes sign in between
    k = 0.6 if clinging is None else max(clinging, 0.6)
    most = speed * float(np.max(sections.outer_area + k * sections.annular_area))
    low, high = min(0.0, most), max(0.0, most)
    if imbalance(low) * imbalance(high) > 0.0:
        return 0.0
    from scipy.optimize import brentq  # lazy: model.well imports this module

    return float(brentq(imbalance, low, high, xtol=1e-12, rtol=1e-10))


def critical_trip_speed(pressure_at: Callable[[float], float], allowed: float, *,
                        max_speed: float = 5.0) -> float:
    """The trip speed [m/s] at which the surge or swab pressure reaches ``allowed`` [Pa].

    Parameters
    ----------
    pressure_at : the size of the surge or swab pressure [Pa] at a trip speed [m/s] (> 0),
        rising with it (`surge_swab`'s pressure, as a magnitude)
    allowed : the margin to the pore or fracture pressure [Pa]
    max_speed : the fastest trip looked at [m/s]

    Returns
    -------
    the speed, found by Brent's method between 0 and ``max_speed``; 0 when the margin is gone
    already (``allowed <= 0``) and ``inf`` when not even ``max_speed`` uses it up.
    """
    if not allowed > 0.0:
        return 0.0
    if pressure_at(max_speed) < allowed:
        return math.inf
    from scipy.optimize import brentq  # lazy: model.well imports this module

    return float(brentq(lambda v: pressure_at(v) - allowed, 0.0, max_speed, xtol=1e-6))


@dataclass(frozen=True)
class WellHydraulics:
    """What the hydraulics of a well need beyond its geometry and fluid density.

    Attributes
    ----------
    rheology : the mud's rheology, or None: not known, and then no viscous drag, no annular
        friction and no surge or swab are modelled (docs/hydraulics.md)
    nozzle_area : the bit's total flow area [m^2], or None (not known: the bit's pressure drop
        then comes from the standpipe pressure, if given; an open string without it is taken
        as open-ended)
    float_valve : a float valve above the bit: no fluid enters the string from below (a closed
        string for surge and swab)
    discharge_coefficient : of the nozzles [-]
    pump_open_area : area on which the pressure drop across the bit pushes pressure-actuated
        tools open (jars, shock subs) [m^2]; 0 when there are none
    pore_density, fracture_density : the open hole's pore and fracture pressures as equivalent
        densities [kg/m^3], or None: the limits of the trip speed
    """

    rheology: Rheology | None = None
    nozzle_area: float | None = None
    float_valve: bool = False
    discharge_coefficient: float = DISCHARGE_COEFFICIENT
    pump_open_area: float = 0.0
    pore_density: float | None = None
    fracture_density: float | None = None

    def __post_init__(self) -> None:
        if self.nozzle_area is not None and not self.nozzle_area > 0.0:
            raise ModelError(f"nozzle area must be > 0 m^2, got {self.nozzle_area}")
        if not 0.0 < self.discharge_coefficient <= 1.0:
            raise ModelError(f"discharge coefficient must be in (0, 1], got "
                             f"{self.discharge_coefficient}")
        if not self.pump_open_area >= 0.0:
            raise ModelError(f"pump-open area must be >= 0 m^2, got {self.pump_open_area}")
        if (self.pore_density is not None and self.fracture_density is not None
                and not self.pore_density < self.fracture_density):
            raise ModelError(f"pore density ({self.pore_density:g} kg/m^3) must be below the "
                             f"fracture density ({self.fracture_density:g} kg/m^3)")
