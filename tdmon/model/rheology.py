"""Drilling-fluid rheology: Bingham plastic and power law, from Fann readings or PV and YP.

A mud report gives the Fann (rotational viscometer, R1-B1 rotor-bob, F1 spring) dial readings
at 600 and 300 rpm, or the plastic viscosity (PV) and yield point (YP) worked out from them.
Two models are read from those numbers, as API RP 13D and Bourgoyne et al. (1986, chapter 4)
read them:

``"bingham"`` (Bingham plastic)
    ``tau = tau_y + mu_p gamma``: ``PV = theta_600 - theta_300`` [cP] and
    ``YP = theta_300 - PV`` [lbf/100 ft^2] (eq. 4.47a-b in [2]; the field convention, which
    takes one dial unit as 1 lbf/100 ft^2).
``"power_law"``
    ``tau = K gamma^n``: ``n = 3.32 log10(theta_600 / theta_300)`` and
    ``K = 5.11 theta_300 / 511^n`` [dyne s^n / cm^2] (API RP 13D [1]: one dial unit of the
    F1 spring is 1.067 lbf/100 ft^2 = 5.11 dyne/cm^2 = 0.511 Pa, and 300 rpm shears at
    511 1/s); from PV and YP: ``theta_600 = 2 PV + YP``, ``theta_300 = PV + YP``.

Everything here is SI: viscosities [Pa s], stresses [Pa], ``K`` [Pa s^n]. A mud whose
rheology is not known has none (``None`` where a `Rheology` is taken): tdmon then models no
viscous drag (docs/hydraulics.md).

References
----------
.. [1] API RP 13D, Rheology and Hydraulics of Oil-well Drilling Fluids (6th ed., 2010),
   section 7 (the power-law readings) and the F1 spring constant.
.. [2] Bourgoyne, A. T., Millheim, K. K., Chenevert, M. E. and Young, F. S. (1986). Applied
   Drilling Engineering. SPE Textbook Series vol. 2, chapter 4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Literal, get_args

from tdmon.errors import ModelError

__all__ = [
    "DIAL_STRESS",
    "FIELD_YIELD_POINT",
    "RHEOLOGY_MODELS",
    "Rheology",
    "RheologyModel",
    "from_fann",
    "from_pv_yp",
]

RheologyModel = Literal["bingham", "power_law"]
RHEOLOGY_MODELS: Final[tuple[str, ...]] = get_args(RheologyModel)
"""The rheological models tdmon reads a mud report into."""

DIAL_STRESS: Final = 0.4788026 * 1.067
"""Shear stress of one Fann dial unit (R1-B1 rotor-bob, F1 spring) [Pa]: 1.067 lbf/100 ft^2
(API RP 13D; 1 lbf/100 ft^2 = 0.4788026 Pa)."""

FIELD_YIELD_POINT: Final = 0.4788026
"""One unit of the field yield point, 1 lbf/100 ft^2, in Pa (the field convention reads one dial
unit as one lbf/100 ft^2)."""

_CENTIPOISE: Final = 1e-3  # [Pa s]
_RATE_300: Final = 511.0  # shear rate of the viscometer at 300 rpm [1/s] (1.703 x 300)


@dataclass(frozen=True)
class Rheology:
    """A drilling fluid's rheology, in SI.

    Attributes
    ----------
    model : ``"bingham"`` or ``"power_law"``
    plastic_viscosity : mu_p of the Bingham model [Pa s] (NaN for a power law)
    yield_point : tau_y of the Bingham model [Pa] (NaN for a power law)
    flow_index : n of the power law [-] (NaN for a Bingham plastic)
    consistency : K of the power law [Pa s^n] (NaN for a Bingham plastic)
    """

    model: RheologyModel
    plastic_viscosity: float = math.nan
    yield_point: float = math.nan
    flow_index: float = math.nan
    consistency: float = math.nan

    def __post_init__(self) -> None:
        if self.model == "bingham":
            if not (self.plastic_viscosity > 0.0 and math.isfinite(self.plastic_viscosity)):
                raise ModelError(f"plastic viscosity must be > 0 Pa s, got "
                                 f"{self.plastic_viscosity}")
            if not (self.yield_point >= 0.0 and math.isfinite(self.yield_point)):
                raise ModelError(f"yield point must be >= 0 Pa, got {self.yield_point}")
        elif self.model == "power_law":
            if not (0.0 < self.flow_index <= 1.5):
                raise ModelError(f"flow index n must be in (0, 1.5], got {self.flow_index}")
            if not (self.consistency > 0.0 and math.isfinite(self.consistency)):
                raise ModelError(f"consistency index K must be > 0 Pa s^n, got "
                                 f"{self.consistency}")
        else:
            raise ModelError(f"unknown rheology model {self.model!r}: use one of "
                             f"{', '.join(RHEOLOGY_MODELS)}")

    @classmethod
    def bingham(cls, plastic_viscosity: float, yield_point: float) -> Rheology:
        """A Bingham plastic of ``plastic_viscosity`` [Pa s] and ``yield_point`` [Pa]."""
        return cls("bingham", plastic_viscosity=float(plastic_viscosity),
                   yield_point=float(yield_point))

    @classmethod
    def power_law(cls, flow_index: float, consistency: float) -> Rheology:
        """A power-law fluid of ``flow_index`` n [-] and ``consistency`` K [Pa s^n]."""
        return cls("power_law", flow_index=float(flow_index), consistency=float(consistency))


def from_fann(theta_600: float, theta_300: float, model: RheologyModel = "bingham") -> Rheology:
    """The rheology of a mud from its Fann 600 and 300 rpm dial readings [dial units].

    Parameters
    ----------
    theta_600, theta_300 : viscometer dial readings at 600 and 300 rpm [-]
    model : ``"bingham"`` or ``"power_law"``

    Notes
    -----
    Bingham plastic: ``mu_p = (theta_600 - theta_300)`` cP and
    ``tau_y = (2 theta_300 - theta_600)`` lbf/100 ft^2 (eq. 4.47 in [2]). Power law:
    ``n = 3.32 log10(theta_600 / theta_300)``, ``K = 0.511 theta_300 / 511^n`` Pa s^n
    (API RP 13D [1]). A reading pair that gives no fluid of the model (``theta_600 <=
    theta_300``, a negative yield point) is refused.

    References
    ----------
    .. [1] API RP 13D (2010), section 7.
    .. [2] Bourgoyne et al. (1986), Applied Drilling Engineering, section 4.3.
    """
    high, low = float(theta_600), float(theta_300)
    if not (high > low > 0.0 and math.isfinite(high)):
        raise ModelError(f"Fann readings need theta_600 > theta_300 > 0, got {high:g} and "
                         f"{low:g}")
    if model == "bingham":
        if 2.0 * low - high < 0.0:
            raise ModelError(f"Fann readings {high:g} and {low:g} give a negative yield point: "
                             "use the power law")
        return Rheology.bingham((high - low) * _CENTIPOISE, (2.0 * low - high) * FIELD_YIELD_POINT)
    if model == "power_law":
        n = 3.32 * math.log10(high / low)
        return Rheology.power_law(n, DIAL_STRESS * low / _RATE_300**n)
    raise ModelError(f"unknown rheology model {model!r}: use one of {', '.join(RHEOLOGY_MODELS)}")


def from_pv_yp(plastic_viscosity: float, yield_point: float,
               model: RheologyModel = "bingham") -> Rheology:
    """The rheology of a mud from its plastic viscosity [Pa s] and yield point [Pa].

    The Bingham plastic takes them as they are; the power law goes back to the dial readings
    they came from (``theta_600 = 2 PV + YP``, ``theta_300 = PV + YP`` with PV in cP and YP in
    lbf/100 ft^2) and reads those (`from_fann`).
    """
    pv, yp = float(plastic_viscosity), float(yield_point)
    if model == "bingham":
        return Rheology.bingham(pv, yp)
    pv_field, yp_field = pv / _CENTIPOISE, yp / FIELD_YIELD_POINT
    return from_fann(2.0 * pv_field + yp_field, pv_field + yp_field, model)
