"""Mud temperature in a circulating well: geotherm, Kabir/Apak analytic, Apak empirical, numerical.

All quantities are SI with temperatures in degC: depths [m], gradient [K/m], flow rate [m^3/s],
time [s], radii [m], heat-transfer coefficients [W/(m^2 K)], conductivities [W/(m K)], specific
heats [J/(kg K)], densities [kg/m^3], viscosity [Pa s].

Four models share one result type, :class:`WellboreTemperature`:

* ``"geothermal"``: static mud at the formation temperature, linear in TVD (eq. 7 in [1]);
* ``"apak"``: the forward-circulation solution of Kabir et al. [2] as used by Apak [3] and the
  thesis [1] (eq. 6, 52, 53, Table 26), evaluated with x = TVD as the thesis does;
* ``"apak-empirical"``: Apak's regression correlations (eq. 54-56 in [1], field units);
* ``"numerical"``: the same two energy balances as ``"apak"`` integrated along MD with the
  geotherm taken at each point's TVD (a boundary-value problem), for deviated wells.

References
----------
.. [1] Thesis "Torque and Drag Friction Model: Implemented Friction Factor Dependency of
   Temperature" (University of Stavanger), sections 3.3 and 4.4.
.. [2] Kabir, C.S., Hasan, A.R., Kouba, G.E., Ameen, M.M. (1996). Determining circulating fluid
   temperature in drilling, workover, and well-control operations. SPE Drilling & Completion
   11(2), 74-79.
.. [3] Apak, E.C. (2006). A study on heat transfer inside the wellbore during drilling
   operations. MSc thesis, Middle East Technical University.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

__all__ = [
    "TEMPERATURE_MODELS",
    "CirculationParameters",
    "Geotherm",
    "HeatTransfer",
    "KabirCoefficients",
    "TemperatureModel",
    "WellboreTemperature",
    "apak_empirical_temperature",
    "apak_temperature",
    "dimensionless_temperature",
    "dittus_boelter",
    "geothermal_temperature",
    "heat_transfer",
    "kabir_coefficients",
    "numerical_temperature",
    "temperature_profile",
]

TemperatureModel = Literal["geothermal", "apak", "apak-empirical", "numerical"]
TEMPERATURE_MODELS: tuple[str, ...] = ("geothermal", "apak", "apak-empirical", "numerical")

# field-unit factors for the empirical correlations (eq. 54-56), exact definitions
_M_PER_FT = 0.3048
_S_PER_H = 3600.0
_M3_PER_GAL = 3.785411784e-3
_S_PER_MIN = 60.0


@dataclass(frozen=True)
class Geotherm:
    """Undisturbed formation temperature, linear in true vertical depth.

    Attributes
    ----------
    surface_temperature : float
        Surface earth temperature T_s [degC].
    gradient : float
        Geothermal gradient G [K/m].
    """

    surface_temperature: float
    gradient: float

    def __post_init__(self) -> None:
        _require_finite("surface_temperature", self.surface_temperature)
        _require_finite("geothermal gradient", self.gradient)


@dataclass(frozen=True)
class CirculationParameters:
    """Inputs of the circulating-mud models (Table 10 in [1]), SI with temperatures in degC.

    Only ``inlet_temperature``, ``flow_rate`` and ``circulation_time`` are always needed. The
    analytic and numerical models also need the radii and the formation properties; the fluid
    and pipe properties are needed only when the heat-transfer coefficients U_p and U_a are
    not given. A missing input raises :class:`~tdmon.errors.ModelError` where it is needed.

    Attributes
    ----------
    inlet_temperature : float
        Mud temperature entering the drill pipe T_pi [degC].
    flow_rate : float
        Volumetric circulation rate q [m^3/s].
    circulation_time : float
        Time since circulation started t [s].
    pipe_inner_radius, pipe_outer_radius : float or None
        Drill-pipe radii r_pi, r_po [m]; r_po is the radius in A (as in Table 11).
    hole_radius : float or None
        Wellbore (bit) radius r_w [m]: outer wall of the annulus flow area and the radius of
        the dimensionless time t_D.
    casing_radius : float or None
        Radius r_c [m] at which the annulus exchanges heat with the formation (r_ci in
        Table 10), used in B.
    fluid_density : float or None
        Mud density rho [kg/m^3].
    fluid_specific_heat : float or None
        Mud specific heat c_f [J/(kg K)].
    fluid_conductivity : float or None
        Mud thermal conductivity k_f [W/(m K)].
    fluid_viscosity : float or None
        Mud dynamic viscosity [Pa s].
    pipe_conductivity : float or None
        Drill-pipe wall thermal conductivity k_p [W/(m K)].
    formation_conductivity : float or None
        Formation thermal conductivity K [W/(m K)].
    formation_specific_heat : float or None
        Formation specific heat c [J/(kg K)].
    formation_density : float or None
        Formation density rho_f [kg/m^3].
    pipe_heat_transfer : float or None
        Overall heat-transfer coefficient across the pipe wall U_p [W/(m^2 K)]; computed
        when None.
    annulus_heat_transfer : float or None
        Annulus heat-transfer coefficient U_a [W/(m^2 K)]; computed when None.
    """

    inlet_temperature: float
    flow_rate: float
    circulation_time: float
    pipe_inner_radius: float | None = None
    pipe_outer_radius: float | None = None
    hole_radius: float | None = None
    casing_radius: float | None = None
    fluid_density: float | None = None
    fluid_specific_heat: float | None = None
    fluid_conductivity: float | None = None
    fluid_viscosity: float | None = None
    pipe_conductivity: float | None = None
    formation_conductivity: float | None = None
    formation_specific_heat: float | None = None
    formation_density: float | None = None
    pipe_heat_transfer: float | None = None
    annulus_heat_transfer: float | None = None

    def __post_init__(self) -> None:
        _require_finite("inlet_temperature", self.inlet_temperature)
        _require_positive("flow_rate", self.flow_rate, "mud must circulate down the pipe")
        _require_positive("circulation_time", self.circulation_time,
                          "the formation solution is transient in time")
        for name in ("pipe_inner_radius", "pipe_outer_radius", "hole_radius", "casing_radius",
                     "fluid_density", "fluid_specific_heat", "fluid_conductivity",
                     "fluid_viscosity", "pipe_conductivity", "formation_conductivity",
                     "formation_specific_heat", "formation_density", "pipe_heat_transfer",
                     "annulus_heat_transfer"):
            value = getattr(self, name)
            if value is not None:
                _require_positive(name, value)
        if (self.pipe_inner_radius is not None and self.pipe_outer_radius is not None
                and self.pipe_inner_radius >= self.pipe_outer_radius):
            raise ModelError(f"pipe_inner_radius {self.pipe_inner_radius} m must be smaller "
                             f"than pipe_outer_radius {self.pipe_outer_radius} m")
        if (self.hole_radius is not None and self.pipe_outer_radius is not None
                and self.hole_radius <= self.pipe_outer_radius):
            raise ModelError(f"hole_radius {self.hole_radius} m must be larger than "
                             f"pipe_outer_radius {self.pipe_outer_radius} m (no annulus)")

    def need(self, name: str, purpose: str) -> float:
        """Return input ``name`` or raise ModelError saying which model needs it."""
        value = getattr(self, name)
        if value is None:
            raise ModelError(f"{purpose} needs '{name}', which is not given")
        return float(value)


@dataclass(frozen=True)
class HeatTransfer:
    """Heat-transfer coefficients of the circulating mud (Table 26 in [1]).

    Attributes
    ----------
    pipe : float
        U_p [W/(m^2 K)].
    annulus : float
        U_a [W/(m^2 K)].
    dimensionless_time : float
        t_D = alpha t / r_w^2 [-].
    dimensionless_temperature : float
        T_D(t_D) [-].
    h_pipe, h_annulus, reynolds_pipe, reynolds_annulus, prandtl : float or None
        Film coefficients [W/(m^2 K)] and dimensionless groups when U_p and U_a were computed
        (None when they were given).
    """

    pipe: float
    annulus: float
    dimensionless_time: float
    dimensionless_temperature: float
    h_pipe: float | None = None
    h_annulus: float | None = None
    reynolds_pipe: float | None = None
    reynolds_annulus: float | None = None
    prandtl: float | None = None


@dataclass(frozen=True)
class KabirCoefficients:
    """Coefficients of the Kabir et al. solution (Table 26 in [1]); lengths in m.

    Attributes
    ----------
    A, B : float
        Model coefficients [1/m].
    theta1, theta2 : float
        Roots (B +/- sqrt(B^2 + 4AB))/2 [1/m].
    C1, C2 : float or None
        Integration constants [K]; None for the numerical model, which has none.
    heat_transfer : HeatTransfer
        U_p, U_a, t_D, T_D and, when computed, the film coefficients.
    """

    A: float
    B: float
    theta1: float
    theta2: float
    C1: float | None
    C2: float | None
    heat_transfer: HeatTransfer


@dataclass(frozen=True)
class WellboreTemperature:
    """Mud and formation temperature along the well.

    Attributes
    ----------
    model : str
        Model name (one of :data:`TEMPERATURE_MODELS`).
    md, tvd : ndarray
        Measured and true vertical depth of the points [m].
    pipe, annulus, formation : ndarray
        Mud in the drill pipe, mud in the annulus, undisturbed formation [degC].
    inlet_temperature : float or None
        Mud-in temperature used [degC] (None for the geotherm).
    coefficients : KabirCoefficients or None
        Diagnostics of the analytic and numerical models.
    maximum_temperature : float or None
        Apak's correlated maximum mud temperature (eq. 56) [degC], empirical model only.
    """

    model: str
    md: NDArray[np.float64]
    tvd: NDArray[np.float64]
    pipe: NDArray[np.float64]
    annulus: NDArray[np.float64]
    formation: NDArray[np.float64]
    inlet_temperature: float | None = None
    coefficients: KabirCoefficients | None = None
    maximum_temperature: float | None = None

    def to_dict(self) -> dict[str, object]:
        """JSON-ready dict in SI with units in the keys (lists, no NaN).

        Keys: ``model``, ``md_m``, ``tvd_m``, ``pipe_C``, ``annulus_C``, ``formation_C``,
        ``inlet_temperature_C``, ``maximum_temperature_C`` and ``coefficients`` (A_per_m,
        B_per_m, theta1_per_m, theta2_per_m, C1_K, C2_K, U_p_W_m2K, U_a_W_m2K, t_D, T_D and,
        when computed, h_p_W_m2K, h_a_W_m2K, Re_p, Re_a, Pr) or None.
        """
        coefficients: dict[str, float | None] | None = None
        if self.coefficients is not None:
            k, ht = self.coefficients, self.coefficients.heat_transfer
            coefficients = {
                "A_per_m": k.A, "B_per_m": k.B, "theta1_per_m": k.theta1,
                "theta2_per_m": k.theta2, "C1_K": k.C1, "C2_K": k.C2,
                "U_p_W_m2K": ht.pipe, "U_a_W_m2K": ht.annulus, "t_D": ht.dimensionless_time,
                "T_D": ht.dimensionless_temperature, "h_p_W_m2K": ht.h_pipe,
                "h_a_W_m2K": ht.h_annulus, "Re_p": ht.reynolds_pipe, "Re_a": ht.reynolds_annulus,
                "Pr": ht.prandtl,
            }
        return {
            "model": self.model,
            "md_m": np.atleast_1d(self.md).tolist(),
            "tvd_m": np.atleast_1d(self.tvd).tolist(),
            "pipe_C": np.atleast_1d(self.pipe).tolist(),
            "annulus_C": np.atleast_1d(self.annulus).tolist(),
            "formation_C": np.atleast_1d(self.formation).tolist(),
            "inlet_temperature_C": self.inlet_temperature,
            "maximum_temperature_C": self.maximum_temperature,
            "coefficients": coefficients,
        }


def _require_finite(name: str, value: float) -> None:
    if not math.isfinite(value):
        raise ModelError(f"{name} must be a finite number, got {value}")


def _require_positive(name: str, value: float, why: str = "") -> None:
    if not math.isfinite(value) or value <= 0.0:
        reason = f" ({why})" if why else ""
        raise ModelError(f"{name} must be positive, got {value}{reason}")


def _depths(values: ArrayLike, name: str) -> NDArray[np.float64]:
    array = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise ModelError(f"{name} contains non-finite values")
    if np.any(array < 0.0):
        raise ModelError(f"{name} must not be negative (depth is measured down from surface)")
    return array


def geothermal_temperature(tvd: ArrayLike, surface_temperature: float,
                           geothermal_gradient: float) -> NDArray[np.float64]:
    """Undisturbed formation temperature T = T_s + G x.

    Parameters
    ----------
    tvd : array_like
        True vertical depth x [m].
    surface_temperature : float
        T_s [degC].
    geothermal_gradient : float
        G [K/m].

    Returns
    -------
    ndarray
        Formation temperature [degC], same shape as ``tvd``.

    Notes
    -----
    Eq. 7 in [1]; the thesis uses it as the mud temperature of Kaarstad et al.

    References
    ----------
    .. [1] Thesis, section 2 (see module references).
    """
    x = _depths(tvd, "tvd")
    return surface_temperature + geothermal_gradient * x


def dittus_boelter(reynolds: float, prandtl: float, conductivity: float,
                   diameter: float) -> float:
    """Film heat-transfer coefficient h = 0.023 Re^0.8 Pr^0.4 k / D [W/(m^2 K)].

    Parameters
    ----------
    reynolds, prandtl : float
        Reynolds and Prandtl numbers [-].
    conductivity : float
        Fluid thermal conductivity k [W/(m K)].
    diameter : float
        (Hydraulic) diameter D [m].

    Notes
    -----
    Table 26 in [1]. The correlation is for fully turbulent flow (Re > 1e4); below that it
    overestimates h, which the tdmon docs point out for the Table 10 inputs.
    """
    return 0.023 * reynolds**0.8 * prandtl**0.4 * conductivity / diameter


def dimensionless_temperature(dimensionless_time: float) -> float:
    """Formation dimensionless temperature T_D(t_D) of Hasan and Kabir.

    Parameters
    ----------
    dimensionless_time : float
        t_D = alpha t / r_w^2 [-], positive.

    Returns
    -------
    float
        T_D [-]: (0.4063 + 0.5 ln t_D)(1 + 0.6/t_D) for t_D > 1.5, otherwise
        1.1281 sqrt(t_D) (1 - 0.3 sqrt(t_D)).

    Notes
    -----
    Table 26 in [1], from [2].
    """
    _require_positive("dimensionless time t_D", dimensionless_time)
    t_d = dimensionless_time
    if t_d > 1.5:
        return (0.4063 + 0.5 * math.log(t_d)) * (1.0 + 0.6 / t_d)
    root = math.sqrt(t_d)
    return 1.1281 * root * (1.0 - 0.3 * root)


def heat_transfer(circulation: CirculationParameters) -> HeatTransfer:
    """U_p, U_a, t_D and T_D for the circulating mud (Table 26 in [1]).

    Given U_p and U_a are used as they are; otherwise both come from Dittus-Boelter film
    coefficients with Re = rho v D / mu and Pr = mu c_f / k_f, on the pipe bore (D = 2 r_pi)
    and on the annulus hydraulic diameter D_h = 2 (r_w - r_po), and

        U_p = (1/h_p + r_pi/k_p ln(r_po/r_pi) + r_po/(r_pi h_a))^-1,    U_a = h_a.

    Parameters
    ----------
    circulation : CirculationParameters
        Inputs [SI].

    Returns
    -------
    HeatTransfer

    Notes
    -----
    Formation diffusivity alpha = K / (c rho_f) [m^2/s], t_D = alpha t / r_w^2. U_p is written
    as printed in Table 26 of [1] (Apak's form); a wall-resistance sum referred to one radius
    would use r_pi/(r_po h_a) in the last term, which for drill pipe differs by a few percent.
    """
    purpose = "the Kabir/Apak temperature model"
    k_form = circulation.need("formation_conductivity", purpose)
    diffusivity = k_form / (circulation.need("formation_specific_heat", purpose)
                            * circulation.need("formation_density", purpose))
    r_w = circulation.need("hole_radius", purpose)
    t_d = diffusivity * circulation.circulation_time / r_w**2
    big_t_d = dimensionless_temperature(t_d)
    if circulation.pipe_heat_transfer is not None and circulation.annulus_heat_transfer is not None:
        return HeatTransfer(circulation.pipe_heat_transfer, circulation.annulus_heat_transfer,
                            t_d, big_t_d)
    purpose = "computing U_p and U_a (give pipe_heat_transfer and annulus_heat_transfer to skip)"
    rho = circulation.need("fluid_density", purpose)
    viscosity = circulation.need("fluid_viscosity", purpose)
    k_fluid = circulation.need("fluid_conductivity", purpose)
    r_pi = circulation.need("pipe_inner_radius", purpose)
    r_po = circulation.need("pipe_outer_radius", purpose)
    k_pipe = circulation.need("pipe_conductivity", purpose)
    prandtl = viscosity * circulation.need("fluid_specific_heat", purpose) / k_fluid
    q = circulation.flow_rate
    d_pipe = 2.0 * r_pi
    re_pipe = rho * (q / (math.pi * r_pi**2)) * d_pipe / viscosity
    d_annulus = 2.0 * (r_w - r_po)
    re_annulus = rho * (q / (math.pi * (r_w**2 - r_po**2))) * d_annulus / viscosity
    h_p = dittus_boelter(re_pipe, prandtl, k_fluid, d_pipe)
    h_a = dittus_boelter(re_annulus, prandtl, k_fluid, d_annulus)
    u_p = circulation.pipe_heat_transfer
    if u_p is None:
        u_p = 1.0 / (1.0 / h_p + r_pi / k_pipe * math.log(r_po / r_pi) + r_po / (r_pi * h_a))
    u_a = circulation.annulus_heat_transfer if circulation.annulus_heat_transfer else h_a
    return HeatTransfer(u_p, u_a, t_d, big_t_d, h_p, h_a, re_pipe, re_annulus, prandtl)


def kabir_coefficients(circulation: CirculationParameters) -> KabirCoefficients:
    """A, B, theta1 and theta2 of the Kabir et al. solution (C1, C2 left None).

    Parameters
    ----------
    circulation : CirculationParameters
        Inputs [SI].

    Returns
    -------
    KabirCoefficients
        With A = 2 pi r_po U_p / (m c_f), B = 2 pi r_c U_a K / (m c_f (K + r_c U_a T_D)),
        m = rho q, theta1,2 = (B +/- sqrt(B^2 + 4AB))/2 [1/m].

    Notes
    -----
    Table 26 in [1]; the mud's heat capacity rate m c_f is per unit time [W/K].
    """
    purpose = "the Kabir/Apak temperature model"
    ht = heat_transfer(circulation)
    capacity_rate = (circulation.need("fluid_density", purpose) * circulation.flow_rate
                     * circulation.need("fluid_specific_heat", purpose))
    r_po = circulation.need("pipe_outer_radius", purpose)
    r_c = circulation.need("casing_radius", purpose)
    k_form = circulation.need("formation_conductivity", purpose)
    a = 2.0 * math.pi * r_po * ht.pipe / capacity_rate
    b = (2.0 * math.pi * r_c * ht.annulus * k_form
         / (capacity_rate * (k_form + r_c * ht.annulus * ht.dimensionless_temperature)))
    root = math.sqrt(b * b + 4.0 * a * b)
    return KabirCoefficients(a, b, (b + root) / 2.0, (b - root) / 2.0, None, None, ht)


def apak_temperature(depth: ArrayLike, total_depth: float, geotherm: Geotherm,
                     circulation: CirculationParameters, *,
                     inlet_temperature: float | None = None) -> WellboreTemperature:
    """Kabir et al. forward-circulation mud temperatures in pipe and annulus (Apak's model).

    Parameters
    ----------
    depth : array_like
        Depth x of the points [m], 0 <= x <= ``total_depth``; TVD as in the thesis.
    total_depth : float
        Depth H where the mud leaves the bit [m].
    geotherm : Geotherm
        T_s [degC] and G [K/m].
    circulation : CirculationParameters
        Inputs [SI].
    inlet_temperature : float, optional
        Measured mud-in temperature [degC] replacing ``circulation.inlet_temperature``.

    Returns
    -------
    WellboreTemperature
        ``md`` and ``tvd`` both equal ``depth``; coefficients with C1, C2.

    Notes
    -----
    Pipe (eq. 52 in [1]) and annulus (eq. 6/53 in [1], with theta2 in the second bracket; the
    thesis prints theta1 there, a typo):

        T_p = C1 e^(theta1 x) + C2 e^(theta2 x) + G x + T_s - G/A
        T_a = (1 + theta1/A) C1 e^(theta1 x) + (1 + theta2/A) C2 e^(theta2 x) + G x + T_s

    with C1, C2 from T_p(0) = T_pi and T_p(H) = T_a(H) (Table 26). The terms are evaluated with
    e^(theta1 H) factored out so that every exponential has a non-positive argument: no
    overflow for large theta1 H.
    """
    x = _depths(depth, "depth")
    big_h = float(total_depth)
    _require_positive("total_depth", big_h, "the bit must be below surface")
    if np.any(x > big_h * (1.0 + 1e-12)):
        raise ModelError(f"depth points below total_depth {big_h} m: mud does not circulate there")
    t_in = circulation.inlet_temperature if inlet_temperature is None else float(inlet_temperature)
    _require_finite("inlet_temperature", t_in)
    k = kabir_coefficients(circulation)
    g, t_s = geotherm.gradient, geotherm.surface_temperature
    drive = t_in - t_s + g / k.A
    # denominator theta1 e^(t1 H) - theta2 e^(t2 H) = e^(t1 H) * scaled
    scaled = k.theta1 - k.theta2 * math.exp((k.theta2 - k.theta1) * big_h)
    c1_top = (-drive * k.theta2 * math.exp(k.theta2 * big_h) - g) / scaled  # C1 e^(theta1 H)
    c2 = (drive * k.theta1 + g * math.exp(-k.theta1 * big_h)) / scaled
    term1 = c1_top * np.exp(k.theta1 * (x - big_h))  # C1 e^(theta1 x)
    term2 = c2 * np.exp(k.theta2 * x)                    # C2 e^(theta2 x)
    formation = t_s + g * x
    pipe = term1 + term2 + formation - g / k.A
    annulus = (1.0 + k.theta1 / k.A) * term1 + (1.0 + k.theta2 / k.A) * term2 + formation
    c1 = c1_top * math.exp(-k.theta1 * big_h)  # underflows to 0, never overflows
    coefficients = KabirCoefficients(k.A, k.B, k.theta1, k.theta2, c1, c2, k.heat_transfer)
    _check_finite(pipe, annulus, "apak")
    return WellboreTemperature("apak", x.copy(), x.copy(), pipe, annulus, formation, t_in,
                               coefficients)


def numerical_temperature(md: ArrayLike, survey_md: ArrayLike, survey_tvd: ArrayLike,
                          geotherm: Geotherm, circulation: CirculationParameters, *,
                          total_md: float | None = None,
                          inlet_temperature: float | None = None,
                          tolerance: float = 1e-6) -> WellboreTemperature:
    """Pipe and annulus mud temperatures from the energy balances integrated along MD.

    Parameters
    ----------
    md : array_like
        Measured depth of the output points [m], within [0, ``total_md``].
    survey_md, survey_tvd : array_like
        Trajectory: TVD [m] at increasing MD stations [m], starting at MD 0; TVD between
        stations is interpolated linearly (use a fine survey, e.g. the hole grid).
    geotherm : Geotherm
        T_s [degC], G [K/m] (the formation temperature is linear in TVD).
    circulation : CirculationParameters
        Inputs [SI].
    total_md : float, optional
        MD of the bit, where the mud turns [m]; default the last survey station.
    inlet_temperature : float, optional
        Measured mud-in temperature [degC] replacing ``circulation.inlet_temperature``.
    tolerance : float
        Residual tolerance of :func:`scipy.integrate.solve_bvp` [-].

    Returns
    -------
    WellboreTemperature
        Coefficients with A, B, theta1, theta2 and C1 = C2 = None.

    Notes
    -----
    With s the MD and T_f(s) = T_s + G TVD(s), the balances of [2] (pipe flow down, annulus up)

        dT_p/ds = A (T_a - T_p)
        dT_a/ds = A (T_a - T_p) - B (T_f(s) - T_a)

    with T_p(0) = T_pi and T_p(H) = T_a(H). For a vertical well TVD = s and the solution is
    eq. 52-53 of [1]; for a deviated well the mud travels further (MD) through a formation
    that warms only with TVD.
    """
    s_md = _depths(survey_md, "survey_md")
    s_tvd = _depths(survey_tvd, "survey_tvd")
    points = _depths(md, "md")
    if s_md.ndim != 1 or s_md.shape != s_tvd.shape or s_md.size < 2:
        raise ModelError("survey_md and survey_tvd must be 1-D arrays of the same length >= 2")
    if np.any(np.diff(s_md) <= 0.0):
        raise ModelError("survey_md must increase strictly")
    if s_md[0] != 0.0:
        raise ModelError("the survey must start at MD 0 (the surface)")
    big_h = float(s_md[-1] if total_md is None else total_md)
    _require_positive("total_md", big_h, "the bit must be below surface")
    if big_h > s_md[-1] * (1.0 + 1e-12):
        raise ModelError(f"total_md {big_h} m is below the last survey station {s_md[-1]} m")
    if np.any(points > big_h * (1.0 + 1e-12)):
        raise ModelError(f"md points below total_md {big_h} m: mud does not circulate there")
    t_in = circulation.inlet_temperature if inlet_temperature is None else float(inlet_temperature)
    _require_finite("inlet_temperature", t_in)
    k = kabir_coefficients(circulation)
    g, t_s = geotherm.gradient, geotherm.surface_temperature

    def formation(s: NDArray[np.float64]) -> NDArray[np.float64]:
        return t_s + g * np.interp(s, s_md, s_tvd)

    # xi = s / H in [0, 1] keeps the system well scaled whatever the well length
    a_h, b_h = k.A * big_h, k.B * big_h

    def rhs(xi: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        exchange = a_h * (y[1] - y[0])
        return np.vstack((exchange, exchange - b_h * (formation(xi * big_h) - y[1])))

    def boundary(ya: NDArray[np.float64], yb: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.array([ya[0] - t_in, yb[0] - yb[1]])

    stations = s_md[s_md < big_h] / big_h
    nodes = max(50, int(4 * max(abs(k.theta1), abs(k.theta2)) * big_h))
    mesh = np.unique(np.concatenate((np.linspace(0.0, 1.0, nodes), stations, [1.0])))
    guess_f = formation(mesh * big_h)
    guess = np.vstack((t_in + (guess_f - t_s) * 0.5, guess_f))
    from scipy.integrate import solve_bvp  # 0.46 s to import: only the numerical model pays it

    solution = solve_bvp(rhs, boundary, mesh, guess, tol=tolerance, max_nodes=200_000)
    if not solution.success:
        raise ModelError(f"numerical temperature model did not converge: {solution.message}")
    pipe, annulus = solution.sol(points / big_h)
    tvd = np.interp(points, s_md, s_tvd)
    _check_finite(pipe, annulus, "numerical")
    coefficients = KabirCoefficients(k.A, k.B, k.theta1, k.theta2, None, None, k.heat_transfer)
    return WellboreTemperature("numerical", points.copy(), tvd, np.asarray(pipe, np.float64),
                               np.asarray(annulus, np.float64), t_s + g * tvd, t_in,
                               coefficients)


def apak_empirical_temperature(depth: ArrayLike, geotherm: Geotherm, *,
                               inlet_temperature: float, flow_rate: float,
                               circulation_time: float) -> WellboreTemperature:
    """Apak's empirical correlations for pipe, annulus and maximum mud temperature.

    Parameters
    ----------
    depth : array_like
        Depth x [m] (TVD).
    geotherm : Geotherm
        T_s [degC], G [K/m].
    inlet_temperature : float
        T_pi [degC].
    flow_rate : float
        q [m^3/s].
    circulation_time : float
        t [s].

    Returns
    -------
    WellboreTemperature
        Pipe and annulus from eq. 54-55, ``maximum_temperature`` from eq. 56 [degC].

    Notes
    -----
    Eq. 54-56 in [1], regressions in field units: temperatures [degF], t [h], x [ft],
    G [degF/ft]. The thesis gives no unit for q; tdmon assumes US gallons per minute
    [gal/min], the usual pump-rate unit: it gives the flow-rate terms a plausible size (-0.0166 q
    is a few degF for 100-500 gal/min; in gal/h, the unit of Table 10, it would be -209 degF at
    12600 gal/h) and a maximum temperature below the formation's for the Table 10 inputs (in
    gal/h eq. 56 would be 60^0.0879 = 1.43 times lower). Even so, the linear correlations do not
    return T_pi at x = 0 and exceed the formation temperature at depth for the Table 10 inputs:
    they are regressions valid only inside Apak's parameter study, kept for comparison.

        T_p = T_pi - 0.3207 t + 0.0465 x + 1193.65 G - 0.0166 q - 1.0401 T_s
        T_a = T_p - 0.00945 t + 0.000006 x + 47.869 G - 0.00387 q - 0.05112 T_s
        T_max = 0.7238 t^-0.0488 x^0.8153 G^0.7279 q^-0.0879 T_pi^0.0857 T_s^0.3622
    """
    x_m = _depths(depth, "depth")
    _require_finite("inlet_temperature", inlet_temperature)
    _require_positive("flow_rate", flow_rate, "mud must circulate down the pipe")
    _require_positive("circulation_time", circulation_time,
                      "the correlation is fitted for circulating wells")
    t_h = circulation_time / _S_PER_H
    x_ft = x_m / _M_PER_FT
    g_f = geotherm.gradient * 1.8 * _M_PER_FT
    q_gpm = flow_rate * _S_PER_MIN / _M3_PER_GAL
    t_pi = inlet_temperature * 1.8 + 32.0
    t_s = geotherm.surface_temperature * 1.8 + 32.0
    pipe_f = t_pi - 0.3207 * t_h + 0.0465 * x_ft + 1193.65 * g_f - 0.0166 * q_gpm - 1.0401 * t_s
    annulus_f = (pipe_f - 0.00945 * t_h + 0.000006 * x_ft + 47.869 * g_f - 0.00387 * q_gpm
                 - 0.05112 * t_s)
    if g_f <= 0.0 or t_pi <= 0.0 or t_s <= 0.0:
        raise ModelError("eq. 56 (maximum temperature) needs a positive geothermal gradient and "
                         "inlet and surface temperatures above 0 degF")
    maximum: float | None = None
    if x_ft.size:
        maximum_f = (0.7238 * t_h**-0.0488 * float(np.max(x_ft))**0.8153 * g_f**0.7279
                     * q_gpm**-0.0879 * t_pi**0.0857 * t_s**0.3622)
        maximum = (maximum_f - 32.0) / 1.8
    pipe = (pipe_f - 32.0) / 1.8
    annulus = (annulus_f - 32.0) / 1.8
    return WellboreTemperature("apak-empirical", x_m.copy(), x_m.copy(), pipe, annulus,
                               geotherm.surface_temperature + geotherm.gradient * x_m,
                               float(inlet_temperature), None, maximum)


def temperature_profile(model: str, md: ArrayLike, survey_md: ArrayLike, survey_tvd: ArrayLike,
                        geotherm: Geotherm, circulation: CirculationParameters | None = None, *,
                        total_md: float | None = None,
                        inlet_temperature: float | None = None) -> WellboreTemperature:
    """Evaluate a temperature model by name at measured depths of a well.

    Parameters
    ----------
    model : {"geothermal", "apak", "apak-empirical", "numerical"}
        Model name.
    md : array_like
        Measured depths of the output points [m] (e.g. the hole-grid element MDs).
    survey_md, survey_tvd : array_like
        Trajectory stations [m], MD increasing from 0.
    geotherm : Geotherm
        T_s [degC], G [K/m].
    circulation : CirculationParameters, optional
        Required by every model but ``"geothermal"``.
    total_md : float, optional
        MD of the bit where the mud turns [m]; default the last survey station.
    inlet_temperature : float, optional
        Measured mud-in temperature [degC], replacing the configured one.

    Returns
    -------
    WellboreTemperature
        ``md`` as given, ``tvd`` interpolated on the survey.

    Notes
    -----
    The analytic models take x = TVD and H = TVD of the bit, as the thesis does for its
    deviated example; ``"numerical"`` integrates along MD (see :func:`numerical_temperature`).
    """
    points = _depths(md, "md")
    s_md = _depths(survey_md, "survey_md")
    s_tvd = _depths(survey_tvd, "survey_tvd")
    if s_md.ndim != 1 or s_md.shape != s_tvd.shape or s_md.size < 2:
        raise ModelError("survey_md and survey_tvd must be 1-D arrays of the same length >= 2")
    if np.any(np.diff(s_md) <= 0.0):
        raise ModelError("survey_md must increase strictly")
    tvd = np.interp(points, s_md, s_tvd)
    if model == "geothermal":
        formation = geothermal_temperature(tvd, geotherm.surface_temperature, geotherm.gradient)
        return WellboreTemperature("geothermal", points.copy(), tvd, formation.copy(),
                                   formation.copy(), formation)
    if model not in TEMPERATURE_MODELS:
        raise ModelError(f"unknown temperature model '{model}' "
                         f"(expected one of {', '.join(TEMPERATURE_MODELS)})")
    if circulation is None:
        raise ModelError(f"temperature model '{model}' needs the circulation inputs")
    if model == "numerical":
        return numerical_temperature(points, s_md, s_tvd, geotherm, circulation,
                                     total_md=total_md, inlet_temperature=inlet_temperature)
    bottom_md = float(s_md[-1] if total_md is None else total_md)
    if np.any(points > bottom_md * (1.0 + 1e-12)):
        raise ModelError(f"md points below total_md {bottom_md} m: mud does not circulate there")
    bottom_tvd = float(np.interp(bottom_md, s_md, s_tvd))
    if model == "apak-empirical":
        t_in = circulation.inlet_temperature if inlet_temperature is None else inlet_temperature
        result = apak_empirical_temperature(tvd, geotherm, inlet_temperature=t_in,
                                            flow_rate=circulation.flow_rate,
                                            circulation_time=circulation.circulation_time)
    else:
        result = apak_temperature(tvd, bottom_tvd, geotherm, circulation,
                                  inlet_temperature=inlet_temperature)
    return WellboreTemperature(result.model, points.copy(), tvd, result.pipe, result.annulus,
                               result.formation, result.inlet_temperature, result.coefficients,
                               result.maximum_temperature)


def _check_finite(pipe: NDArray[np.float64], annulus: NDArray[np.float64], model: str) -> None:
    if not (np.all(np.isfinite(pipe)) and np.all(np.isfinite(annulus))):
        raise ModelError(f"the {model} temperature model produced non-finite temperatures; "
                         "check the inputs (radii, flow rate, properties)")
