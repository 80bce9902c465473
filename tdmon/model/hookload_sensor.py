"""The hook load as a rig's sensor reads it: sheave friction in the block and tackle, where the
sensor sits, and the inertia of the moving load.

The torque-and-drag model gives the load on the hook ``W`` [N] (string top force plus the
travelling equipment). A rig rarely weighs the hook directly:

* a **deadline** sensor (the usual "hook load" of a land rig or jack-up) measures the tension in
  the dead line and multiplies it by the number of lines ``N`` strung between crown and block.
  With a sheave factor ``k`` per turning sheave (efficiency ``e = 1/k``) the tension changes by
  ``k`` at each sheave the moving line passes, so the dead line carries less than ``W/N`` while
  hoisting and more while lowering (eq. 1-2 below);
* a **hook** load pin or a **top-drive** load cell sits below the sheaves and reads ``W`` less the
  travelling equipment above it (no sheave term).

Every sensor also reads the inertial force ``m a`` of the accelerating load and drifts in zero
(an offset, estimated in `tdmon.calib`, not modelled here).

Notes
-----
Sheave counting (the convention of API RP 9B's block-efficiency table): the ``N`` lines
between crown and travelling block pass over ``N`` turning sheaves counted from the fast line
(the fast-line sheave included); the dead-line sheave does not turn and is not counted. Line
``i`` (``i = 1`` next to the fast line) has passed ``i`` sheaves, so while hoisting its
tension is ``T_f / k^i`` and the lines sum to ``W``:

    T_fast = W (k - 1) k^N / (k^N - 1)                         (eq. 1, fast line, hoisting)
    N T_dead = W N (k - 1) / (k^N - 1)                         (eq. 2, dead line, hoisting)

and with the motion reversed (lowering) every factor ``k`` becomes ``1/k``:

    N T_dead = W N (k - 1) k^(N-1) / (k^N - 1)                 (eq. 3, dead line, lowering)

With the block still, no sheave turns and the deadline sensor reads ``W`` (within a band of
static sheave friction that these equations do not resolve). At ``k = 1.04`` and ``N = 10``
hoisting reads 0.833 ``W`` (-17 %) and lowering 1.186 ``W`` (+19 %). The dead-line and fast-line
factors of eq. 1-2 reproduce the table after API RP 9B in the Shell Well Engineers' Notebook
(B-1; tests/model/test_hookload_sensor.py). The inertial term is ``(W / g) a`` with ``a`` the
block's upward acceleration (Luke and Juvkam-Wold 1993 treat the dynamic line tensions in full).

References
----------
.. [1] API RP 9B, Application, Care, and Use of Wire Rope for Oil Field Service (block
   efficiency factors).
.. [2] Luke, G. R. and Juvkam-Wold, H. C. (1993), "The determination of true hook and line
   tension under dynamic conditions", SPE Drilling & Completion.
.. [3] SPE-21965-MS, trip monitoring with sheave friction in the hook-load measurement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tdmon.errors import ModelError

__all__ = [
    "API_SHEAVE_FACTOR",
    "GRAVITY",
    "HookloadSensor",
    "SensorLocation",
    "dead_line_factor",
    "fast_line_factor",
    "sensor_factor",
]

#: Design sheave factor per turning sheave of API RP 9B (roller bearings) [-]; efficiency 1/1.04.
API_SHEAVE_FACTOR = 1.04

#: Standard gravity [m/s^2].
GRAVITY = 9.80665


class SensorLocation(StrEnum):
    """Where the hook-load sensor sits."""

    DEADLINE = "deadline"
    """A dead-line anchor load cell times the number of lines: reads the sheave friction."""
    HOOK = "hook"
    """A load pin at the hook or block: the load below it, no sheave term."""
    TOP_DRIVE = "top_drive"
    """A load cell in the top drive: the load below it, no sheave term."""


def _check(lines: int, efficiency: float) -> None:
    if not (isinstance(lines, int | np.integer) and 1 <= lines <= 24):
        raise ModelError(f"number of lines {lines!r}: a whole number from 1 to 24")
    if not (math.isfinite(efficiency) and 0.8 <= efficiency <= 1.0):
        raise ModelError(f"sheave efficiency {efficiency!r}: from 0.8 to 1 per sheave")


def dead_line_factor(lines: int, efficiency: float, motion: int) -> float:
    """What a deadline sensor reads per unit load on the hook [-] (eq. 2 and 3).

    Parameters
    ----------
    lines : lines strung between crown and travelling block ``N`` [-]
    efficiency : efficiency per turning sheave ``e = 1/k`` [-] (1: no sheave friction)
    motion : +1 hoisting, -1 lowering, 0 block still

    Returns
    -------
    ``N T_dead / W`` [-]: below 1 hoisting, above 1 lowering, 1 still.
    """
    _check(lines, efficiency)
    if motion == 0 or efficiency == 1.0:
        return 1.0
    k = 1.0 / efficiency
    hoisting = lines * (k - 1.0) / (k**lines - 1.0)
    if motion > 0:
        return hoisting
    if motion < 0:
        return hoisting * k ** (lines - 1)
    raise ModelError(f"motion {motion!r}: +1, -1 or 0")  # pragma: no cover (NaN only)


def fast_line_factor(lines: int, efficiency: float) -> float:
    """Fast-line tension while hoisting per the even share ``W/N`` [-] (eq. 1)."""
    _check(lines, efficiency)
    if efficiency == 1.0:
        return 1.0
    k = 1.0 / efficiency
    return lines * (k - 1.0) * k**lines / (k**lines - 1.0)


def sensor_factor(location: SensorLocation | str, lines: int, efficiency: float,
                  motion: int) -> float:
    """The factor from load on the hook to the sensor's reading for a motion [-]: the
    dead-line factor for a deadline sensor, 1 for a hook pin or top-drive load cell."""
    if SensorLocation(location) is SensorLocation.DEADLINE:
        return dead_line_factor(lines, efficiency, motion)
    return 1.0


@dataclass(frozen=True)
class HookloadSensor:
    """How a rig's hook-load channel relates to the load on the hook.

    Attributes
    ----------
    location : where the sensor sits (`SensorLocation`)
    lines : lines strung between crown and travelling block [-] (deadline sensors)
    efficiency : efficiency per turning sheave [-] (1/1.04 = 0.9615 by API RP 9B's design
        factor; 0.96-0.99 in published corrections)
    above_sensor : weight of the travelling equipment above a hook pin or top-drive load cell,
        which that sensor does not read [N] (0 for a deadline sensor)

    The default, a sensor that reads the load on the hook, is what tdmon assumed before the
    measurement was modelled.
    """

    location: SensorLocation = SensorLocation.HOOK
    lines: int = 10
    efficiency: float = 1.0
    above_sensor: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "location", SensorLocation(self.location))
        _check(self.lines, self.efficiency)
        if not (math.isfinite(self.above_sensor) and self.above_sensor >= 0.0):
            raise ModelError(f"travelling equipment above the sensor {self.above_sensor!r} N: "
                             "a weight >= 0")
        if self.location is SensorLocation.DEADLINE and self.above_sensor != 0.0:
            raise ModelError("a deadline sensor reads all the travelling equipment: "
                             "above_sensor must be 0")

    @property
    def reads_sheave_friction(self) -> bool:
        """Whether hoisting and lowering read differently (a deadline sensor)."""
        return self.location is SensorLocation.DEADLINE

    def factor(self, motion: int, efficiency: float | None = None) -> float:
        """Reading per unit load on the hook for a motion (+1 hoisting, -1 lowering, 0 still),
        at this sensor's efficiency or the one given (an estimate's)."""
        return sensor_factor(self.location, self.lines,
                             self.efficiency if efficiency is None else efficiency, motion)

    def reading(self, hook_load: ArrayLike, motion: int, acceleration: ArrayLike = 0.0,
                efficiency: float | None = None) -> NDArray[np.float64]:
        """What the sensor reads [N] for a load on the hook [N] (string top force plus the
        travelling equipment), a motion, and the block's upward acceleration [m/s^2]
        (inertia ``(W / g) a``)."""
        load = np.asarray(hook_load, dtype=float)
        dynamic = load * (1.0 + np.asarray(acceleration, dtype=float) / GRAVITY)
        return self.factor(motion, efficiency) * dynamic - self.above_sensor

    def hook_load(self, reading: ArrayLike, motion: int, acceleration: ArrayLike = 0.0,
                  efficiency: float | None = None) -> NDArray[np.float64]:
        """The load on the hook [N] a reading [N] stands for (the inverse of `reading`)."""
        value = np.asarray(reading, dtype=float) + self.above_sensor
        return value / (self.factor(motion, efficiency)
                        * (1.0 + np.asarray(acceleration, dtype=float) / GRAVITY))
