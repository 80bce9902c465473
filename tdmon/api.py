"""tdmon's Python API (docs/api.md): recordings as DataFrames, replays, batches, well models.

Exported from ``tdmon`` itself (``tdmon.read_recording``, ``tdmon.replay``, ``tdmon.batch``,
``tdmon.load_well``, ``tdmon.evaluate_loads``); these names and their keyword arguments are
kept stable. Heavy libraries (pandas, numba, Dask) load when a function first needs them.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from tdmon.record.frames import Recording, read_recording
from tdmon.replay.run import replay_file as replay

if TYPE_CHECKING:
    import numpy as np
    import pandas as pd
    from numpy.typing import ArrayLike, NDArray

    from tdmon.config.well import WellConfig
    from tdmon.model.well import Well
    from tdmon.replay.batch import BatchResult, Progress

__all__ = ["Recording", "WellFile", "batch", "evaluate_loads", "load_well", "read_recording",
           "replay"]


def batch(
    recordings: Sequence[str | os.PathLike[str]],
    out: str | os.PathLike[str],
    *,
    config: str | os.PathLike[str] | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: Progress | None = None,
) -> BatchResult:
    """Replay many recordings on Dask distributed and write the fleet summary (``tdmon batch``).

    Parameters
    ----------
    recordings : the replays (MCAP files), as the workers see them
    out : output folder: ``recordings/``, ``summary/*.parquet`` and ``summary.html``
    config : daemon file for every recording; None: each replay's expectations name one
    scheduler : address of a running Dask scheduler; None: a local cluster of processes
    workers : processes of the local cluster (default: one per core, at most one per recording)
    progress : called after each recording with its outcome, the number done and the total

    Returns
    -------
    BatchResult
        ``outcomes`` (one per recording, ``error`` set for a failed one), ``files`` written,
        and ``tables()``, the summary as DataFrames.

    Notes
    -----
    The local cluster starts worker processes by spawning: a script that calls this at module
    level needs the ``if __name__ == "__main__":`` guard.
    """
    from tdmon.replay.batch import run_batch

    return run_batch(recordings, out, config=config, scheduler=scheduler, workers=workers,
                     progress=progress)


@dataclass(frozen=True)
class WellFile:
    """A well file read and built.

    Attributes
    ----------
    path : the file
    name : the well's name (``[well] name``)
    model : the model layer's well (survey, hole sections, string, fluid, block weight)
    friction : friction factor per element of ``tdmon.model.well.hole_grid(model)`` from the
        file: a section's number, or its law mu(T) at the annulus temperature [-]
    config : the validated file (``tdmon.config.well.WellConfig``)
    """

    path: Path
    name: str
    model: Well
    friction: NDArray[np.float64]
    config: WellConfig

    def __repr__(self) -> str:
        # the model's arrays and the whole validated file are a few thousand characters: the
        # repr says which well it is and its size; the fields hold the rest
        model = self.model
        friction = self.friction
        return (f"WellFile({str(self.path)!r}, name={self.name!r}, "
                f"string {model.string.length:.1f} m, hole {model.sections[-1].bottom:.1f} m, "
                f"{friction.size} elements, friction {friction.min():.3g}-{friction.max():.3g})")


def load_well(path: str | os.PathLike[str]) -> WellFile:
    """Read a well file (TOML; docs/configuration.md) and build its model.

    Raises
    ------
    ConfigError
        One line naming the file and key of a mistake.
    """
    from tdmon.config.well import load_well as load_well_config

    source = Path(path)
    config = load_well_config(source)
    model = config.to_model(source)
    return WellFile(path=source, name=config.well.name, model=model,
                    friction=config.element_friction(model, source), config=config)


def evaluate_loads(
    well: WellFile | Well,
    depths: float | ArrayLike,
    mu: float | ArrayLike | None = None,
    operation: str | None = None,
    *,
    method: Literal["soft-string", "aadnoy"] = "soft-string",
    wob: float = 0.0,
    bit_torque: float = 0.0,
) -> pd.DataFrame:
    """Modelled hook load and surface torque at each bit depth (``tdmon model loads``).

    Parameters
    ----------
    well : from :func:`load_well`, or a model-layer ``Well``
    depths : bit depth(s) [m MD]
    mu : friction factor: a number for every element, an array with one per element of
        ``hole_grid``, or None for the well file's friction (``WellFile.friction``; for a bare
        ``Well``, each section's ``friction``)
    operation : ``static``, ``rotating``, ``pick_up``, ``slack_off`` or ``on_bottom``; None:
        every one
    method : ``"soft-string"`` or ``"aadnoy"`` (docs/torque-drag.md)
    wob : weight on bit for ``on_bottom`` [N]
    bit_torque : torque at the bit for ``on_bottom`` [N m]

    Returns
    -------
    pandas.DataFrame
        One row per depth and operation: ``bit_depth_m``, ``operation``, ``hookload_N``
        (including the block weight), ``surface_torque_Nm``.

    Raises
    ------
    ModelError
        A depth below the string or the hole, an unknown operation or method, a friction
        factor outside 0-1 (the rule of the well files and ``tdmon model loads --mu``).
    """
    import numpy as np
    import pandas as pd

    from tdmon.errors import ModelError
    from tdmon.model.torque_drag import WellModel
    from tdmon.vocabulary import Operation

    if operation is not None and operation not in {o.value for o in Operation}:
        raise ModelError(f"unknown operation {operation!r}: use one of "
                         f"{', '.join(o.value for o in Operation)}")
    model = well.model if isinstance(well, WellFile) else well
    friction = well.friction if mu is None and isinstance(well, WellFile) else _friction(mu)
    evaluator = WellModel(model)
    rows = []
    for depth in np.atleast_1d(np.asarray(depths, dtype=float)):
        loads = evaluator.loads(float(depth), friction, method=method, wob=wob,
                                bit_torque=bit_torque)
        rows += [{"bit_depth_m": loads.bit_depth, "operation": name, "hookload_N": hookload,
                  "surface_torque_Nm": loads.surface_torque[name]}
                 for name, hookload in loads.hookload.items()
                 if operation is None or name == operation]
    return pd.DataFrame(rows, columns=["bit_depth_m", "operation", "hookload_N",
                                       "surface_torque_Nm"])


def _friction(mu: float | ArrayLike | None) -> float | ArrayLike | None:
    """``mu`` checked as the command line and the well files check a friction factor.

    Raises
    ------
    ModelError
        A value that is not a number, or outside 0 to ``tdmon.config.common.MAX_FRICTION``.
    """
    import numpy as np

    from tdmon.config.common import MAX_FRICTION, check_friction
    from tdmon.errors import ModelError

    if mu is None:
        return None
    if np.ndim(mu) == 0:
        try:
            return check_friction(mu)  # type: ignore[arg-type]
        except ValueError as exc:
            raise ModelError(f"mu: {exc}") from None
    try:
        values = np.asarray(mu, dtype=float)
    except (TypeError, ValueError):
        raise ModelError("mu: expected friction factors (numbers)") from None
    bad = np.flatnonzero(~((values >= 0.0) & (values <= MAX_FRICTION)))
    if bad.size:
        raise ModelError(f"mu: friction factor {values.flat[bad[0]]:g} (element {bad[0]}) is "
                         f"outside 0-{MAX_FRICTION:g}")
    return values
