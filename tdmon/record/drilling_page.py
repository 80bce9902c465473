"""The report's drilling figure (docs/drilling.md): against bit depth, the weight on bit at the
surface, from the hook load (with one standard deviation) and from the MWD where sent; the
drilling torque measured against the drilling curve; the friction of the drilling windows.

Pure on the recorded messages: ``drilling_series`` gathers the drilling frames' values, which
the report's figure and the Rerun views draw.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

__all__ = ["DrillingSeries", "drilling_series", "drilling_windows"]

Array = NDArray[np.float64]


def _num(value: Any) -> float:
    return float(value) if isinstance(value, int | float) else math.nan


class DrillingSeries(NamedTuple):
    """The drilling frames of a recording, in time order, SI (NaN where not known)."""

    t: Array
    bit_depth: Array
    wob_surface: Array
    wob_downhole: Array
    wob_estimated: Array
    wob_estimated_std: Array
    torque_measured: Array
    torque_modelled: Array
    hookload_residual: Array


def drilling_series(models: Sequence[dict[str, Any]]) -> DrillingSeries:
    """The drilling frames' values of the ``model`` messages ``models``."""
    frames = sorted((m for m in models if "drilling" in m), key=lambda m: _num(m.get("t")))

    def column(pick: Any) -> Array:
        return np.array([_num(pick(m)) for m in frames], dtype=np.float64)

    return DrillingSeries(
        column(lambda m: m.get("t")), column(lambda m: m.get("bit_depth_m")),
        column(lambda m: m["drilling"].get("wob_surface_N")),
        column(lambda m: m["drilling"].get("wob_downhole_N")),
        column(lambda m: m["drilling"].get("wob_estimated_N")),
        column(lambda m: m["drilling"].get("wob_estimated_std_N")),
        column(lambda m: m["measured"].get("torque_Nm")),
        column(lambda m: m["torque_Nm"].get("drilling")),
        column(lambda m: m["residual"].get("hookload_N")))


def drilling_windows(estimates: Sequence[dict[str, Any]]) -> tuple[Array, Array, Array]:
    """The drilling windows' bit depth [m], friction and its standard deviation [-]."""
    rows = [(_num(e.get("bit_depth_m")), _num(e.get("mu")), _num(e.get("mu_std")))
            for e in estimates if e.get("kind") == "window" and e.get("operation") == "drilling"
            and e.get("mu") is not None]
    if not rows:
        return np.empty(0), np.empty(0), np.empty(0)
    depth, mu, std = (np.array(c, dtype=np.float64) for c in zip(*rows, strict=True))
    return depth, mu, std
