"""What the live mu(T) calibration gets from the well file: the annulus temperatures (computed
once, at start-up), the law to calibrate, the section it applies to (docs/back-calculation.md,
"Daemon composition")."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tdmon.errors import ConfigError
from tdmon.model.friction import FrictionModel

if TYPE_CHECKING:
    from tdmon.config.daemon import DaemonConfig
    from tdmon.config.well_file import WellFile

log = logging.getLogger(__name__)

__all__ = ["MuTSetup", "mu_t_setup"]


@dataclass(frozen=True)
class MuTSetup:
    """What the live mu(T) calibration gets from the well file (docs/back-calculation.md).

    ``temperature`` is the annulus temperature per hole-grid element [degC] (None without a
    ``[temperature]`` table; also used for the profile view); ``law`` the prior law (family
    mode) or the lab fit (scale mode), None when the calibration is off, and then ``note``
    says why. ``mask`` selects the elements of the calibrated section (None: all); the other
    elements keep ``base_mu``, the well file's friction.
    """

    temperature: NDArray[np.float64] | None
    law: FrictionModel | None
    mode: str = "family"
    mask: NDArray[np.bool_] | None = None
    base_mu: float | NDArray[np.float64] = 0.0
    prior_std: list[float] | None = None
    note: str | None = None
    friction: NDArray[np.float64] | None = None


def _section_index(config: DaemonConfig, well_file: WellFile) -> int:
    sections = well_file.config.hole
    wanted = config.calibration.mu_t_section
    if wanted is None:
        return len(sections) - 1
    if isinstance(wanted, int):
        if not -len(sections) <= wanted < len(sections):
            raise ConfigError(str(config.source_file), "calibration.mu_t_section",
                              f"the well file has {len(sections)} hole sections, no {wanted}")
        return wanted % len(sections)
    names = [section.name for section in sections]
    if wanted not in names:
        raise ConfigError(str(config.source_file), "calibration.mu_t_section",
                          f"no hole section named '{wanted}' (sections: {', '.join(names)})")
    return names.index(wanted)


def mu_t_setup(config: DaemonConfig, well_file: WellFile, grid: Any) -> MuTSetup:
    """Annulus temperatures (computed once, at start-up) and the law to calibrate.

    A family law is calibrated in its own coefficients; a constant friction becomes the
    linear law ``a + b T`` with ``b = 0`` as the prior, since a constant has no temperature
    dependence to calibrate.
    """
    calibration = config.calibration
    well_config, path = well_file.config, well_file.path
    try:
        friction: NDArray[np.float64] | None = well_config.element_friction(well_file.well, path)
    except ConfigError as exc:
        log.warning("no friction profile from the well file: %s", exc)
        friction = None
    temperature = None
    if well_config.temperature is not None:
        temperature = np.asarray(
            well_config.annulus_temperature(well_file.well, grid.element_mid_md, path).annulus,
            dtype=np.float64)
    if calibration.mu_t == "off":
        return MuTSetup(temperature, None, friction=friction,
                        note="mu(T) calibration is off ([calibration] mu_t = 'off')")
    if temperature is None:
        return MuTSetup(None, None, friction=friction,
                        note=f"mu(T) calibration is off: the well file {path.name} has no "
                             f"[temperature] table")
    index = _section_index(config, well_file)
    section = well_config.hole[index]
    if calibration.mu_t == "scale":
        assert calibration.lab_fit is not None  # checked when the config was read
        law = calibration.lab_fit.friction_model()
    elif section.friction is None:
        law = FrictionModel("linear", {"a": config.monitor.mu, "b": 0.0})
    else:
        law = section.friction.friction_model()
        if law.family == "constant":
            law = FrictionModel("linear", {"a": float(law.coefficients["mu"]), "b": 0.0})
    n_params = 1 if calibration.mu_t == "scale" else len(law.coefficients)
    prior_std = calibration.mu_t_prior_std
    if prior_std is not None and len(prior_std) != n_params:
        raise ConfigError(str(config.source_file), "calibration.mu_t_prior_std",
                          f"give {n_params} values, one per parameter of "
                          f"{law.describe()} ({calibration.mu_t} mode)")
    mask = np.asarray(grid.element_section == index)
    base: float | NDArray[np.float64] = (friction if friction is not None
                                         else config.monitor.mu)
    return MuTSetup(temperature, law, calibration.mu_t, None if mask.all() else mask, base,
                    prior_std, friction=friction)
