"""The production :class:`~tdmon.daemon.steps.monitor.LoadModel`: torque and drag for the
configured well, evaluated once on a bit-depth grid at start-up (one compiled broomstick sweep
for the design friction factor and the band), then interpolated per frame.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from tdmon.config.daemon import DaemonConfig
from tdmon.daemon.steps.monitor import GridLoadModel
from tdmon.errors import ConfigError, ModelError

log = logging.getLogger(__name__)


def bit_depth_grid(top: float, bottom: float, step: float) -> NDArray[np.float64]:
    """Grid from just below the top of the hole to ``bottom`` [m], ``step`` apart, both ends in."""
    start = top + min(step, 1.0) * 1e-3  # the model refuses a bit exactly at the top
    depths = np.arange(start, bottom, step)
    if depths.size == 0 or bottom - depths[-1] > 1e-9:
        depths = np.append(depths, bottom)
    return depths


def grid_model(
    well: object, mu: float, band_mu: Sequence[float], method: str = "aadnoy",
    step: float = 10.0,
) -> GridLoadModel:
    """Precompute the loads of ``well`` (a ``tdmon.model.well.Well``) on a bit-depth grid."""
    from tdmon.model.broomstick import broomstick_from_model
    from tdmon.model.torque_drag import WellModel

    prepared = WellModel(well)  # type: ignore[arg-type]
    bottom = min(float(prepared.node_md[-1]), float(prepared.well.string.length))
    depths = bit_depth_grid(float(prepared.node_md[0]), bottom, step)
    cases = [mu, *band_mu]
    sweep = broomstick_from_model(prepared, depths, cases, method=method)
    n = len(band_mu)
    rows = [
        sweep.hookload["pick_up"][0], sweep.hookload["slack_off"][0],
        sweep.hookload["rotating"][0], sweep.surface_torque["rotating"][0],
        *(sweep.hookload["pick_up"][1 + i] for i in range(n)),
        *(sweep.hookload["slack_off"][1 + i] for i in range(n)),
    ]
    slopes = wob_slopes(prepared, sweep.bit_depth, mu, method)
    return GridLoadModel(sweep.bit_depth, np.vstack(rows), band_mu, slopes)


#: The weight on bit the on-bottom slopes are taken at [N] (a bit's usual weight: the torque
#: is nearly linear in the weight up to it, docs/drilling.md).
REFERENCE_WOB = 100e3


def wob_slopes(prepared: object, depths: NDArray[np.float64], mu: float, method: str
               ) -> NDArray[np.float64]:
    """The on-bottom hook load's [-] and surface torque's [m] change per newton on the bit,
    per bit depth of ``depths``, at ``mu`` (a ``tdmon.model.torque_drag.WellModel``): the
    change from rotating off bottom to on bottom with :data:`REFERENCE_WOB` and no bit
    torque, over that weight."""
    from tdmon.model.torque_drag import Operation, WellModel

    assert isinstance(prepared, WellModel)
    slopes = np.empty((2, depths.size))
    for i, depth in enumerate(depths.tolist()):
        hook_off, torque_off = prepared.evaluate(Operation.ROTATING, depth, mu, method=method)
        hook_on, torque_on = prepared.evaluate(Operation.ON_BOTTOM, depth, mu, method=method,
                                               wob=REFERENCE_WOB)
        slopes[0, i] = (hook_on - hook_off) / REFERENCE_WOB
        slopes[1, i] = (torque_on - torque_off) / REFERENCE_WOB
    return slopes


def grid_model_for_well(config: DaemonConfig, well: object | None = None) -> GridLoadModel:
    """The grid model for the daemon config's well file (or the ``Well`` already read from it)
    and ``[monitor]`` settings."""
    from tdmon.config.well import load_well_model

    assert config.well is not None
    path = config.resolve(config.well)
    started = time.perf_counter()
    if well is None:
        well = load_well_model(path)
    try:
        model = grid_model(well, config.monitor.mu, config.monitor.band_mu,
                           config.monitor.method, config.monitor.grid_step)
    except ModelError as exc:
        raise ConfigError(str(path), "", f"the well cannot be modelled: {exc}") from exc
    log.info("load model for %s: %d bit depths in %.2f s", path, model.depths.size,
             time.perf_counter() - started)
    return model
