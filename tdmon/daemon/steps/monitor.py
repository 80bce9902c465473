"""The monitor step: modelled hook loads and torque at the current bit depth, the broomstick
band, and residuals of the measured values against the curve for the current operation.

The physics is behind :class:`LoadModel` so the step can be tested with any callable. The
production model, :class:`GridLoadModel`, evaluates torque and drag once on a bit-depth grid at
start-up and interpolates linearly on the hot path (two microseconds per frame, where one
torque-and-drag evaluation costs milliseconds); a frame at the same bit depth as the one before
(in slips, standing still) gets the same loads back without interpolating again.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from tdmon.calib.drilling import (
    DrillingState,
    bit_torque_pessier,
    downhole_wob,
    track,
)
from tdmon.calib.measurement import SensorEstimate
from tdmon.daemon.pipeline import Emit, Frame
from tdmon.daemon.steps.fluids import FluidEffect
from tdmon.vocabulary import CURVE_FOR_STATE, ROTATING_STATES, Operation

# The vocabulary's map as a plain dict keyed by state name: a frame carries its state as a
# str, and a dict lookup is the cheapest on this per-frame path.
_CURVE_FOR_STATE: dict[str, Operation] = {state.value: curve
                                           for state, curve in CURVE_FOR_STATE.items()}


@dataclass(frozen=True, slots=True)
class ModelledLoads:
    """Modelled surface loads at one bit depth: hook loads [N], torque [N m], band [N]."""

    bit_depth: float
    pick_up: float
    slack_off: float
    rotating: float
    torque_rotating: float
    band_mu: tuple[float, ...]
    band_pick_up: tuple[float, ...]
    band_slack_off: tuple[float, ...]
    # on bottom: the change of the rotating hook load [-] and torque [m] per newton on the bit
    # (no bit torque), the slopes of the drilling curve (docs/drilling.md)
    hookload_per_wob: float = -1.0
    torque_per_wob: float = 0.0


class LoadModel(Protocol):
    """Modelled loads at a bit depth [m]; None where the model does not reach."""

    def loads(self, bit_depth: float) -> ModelledLoads | None: ...


#: f(bit_depths [m], mu) -> (pick_up [N], slack_off [N], rotating [N], torque [N m]) arrays
CurveFunction = Callable[[NDArray[np.float64], float],
                         tuple[NDArray[np.float64], NDArray[np.float64],
                               NDArray[np.float64], NDArray[np.float64]]]


class GridLoadModel:
    """Loads precomputed on a bit-depth grid, linearly interpolated.

    ``curves`` rows: pick-up, slack-off, rotating hook load and rotating torque at the design
    ``mu``, then pick-up for each band mu, then slack-off for each band mu. ``wob_slopes``
    (optional) rows: the on-bottom hook load's and torque's change per newton of weight on
    bit [-], [m] (`ModelledLoads.hookload_per_wob`, ``torque_per_wob``; without them -1 and 0).
    """

    def __init__(self, depths: NDArray[np.float64], curves: NDArray[np.float64],
                 band_mu: Sequence[float], wob_slopes: NDArray[np.float64] | None = None
                 ) -> None:
        if depths.ndim != 1 or depths.size < 2 or np.any(np.diff(depths) <= 0):
            raise ValueError("grid depths must be increasing, at least two")
        if curves.shape != (4 + 2 * len(band_mu), depths.size):
            raise ValueError("curves do not match the grid and band")
        if wob_slopes is not None:
            if wob_slopes.shape != (2, depths.size):
                raise ValueError("the weight-on-bit slopes do not match the grid")
            curves = np.vstack([curves, wob_slopes])
        self._slopes = wob_slopes is not None
        self.depths = depths
        self._depth_list = depths.tolist()
        self.curves = curves  # with the slopes' two rows last when given
        self.band_mu = tuple(float(m) for m in band_mu)
        # every curve's value per grid depth as Python floats: interpolating a dozen values in
        # Python is several times faster than slicing, scaling and adding NumPy columns, and
        # gives the same numbers (the same multiplications and addition, in float64); paired
        # per grid interval (each curve's values at its two ends) once here, not zipped on
        # every frame (an interpolation 3.1 -> 2.7 us)
        columns: list[list[float]] = curves.T.tolist()
        self._intervals: list[list[tuple[float, float]]] = [
            list(zip(lower, upper, strict=True)) for lower, upper in pairwise(columns)]
        self._last: ModelledLoads | None = None

    @classmethod
    def from_function(
        cls, curve: CurveFunction, depths: NDArray[np.float64] | Sequence[float], mu: float,
        band_mu: Sequence[float],
    ) -> GridLoadModel:
        """Evaluate ``curve`` once per friction factor on the grid."""
        grid = np.asarray(depths, dtype=np.float64)
        pick_up, slack_off, rotating, torque = curve(grid, mu)
        rows = [pick_up, slack_off, rotating, torque]
        band = [curve(grid, m) for m in band_mu]
        rows += [b[0] for b in band] + [b[1] for b in band]
        return cls(grid, np.vstack([np.asarray(r, dtype=np.float64) for r in rows]), band_mu)

    def loads(self, bit_depth: float) -> ModelledLoads | None:
        last = self._last
        if last is not None and last.bit_depth == bit_depth and type(last.bit_depth) is type(
                bit_depth):
            return last  # immutable, and a function of the bit depth alone
        depths = self._depth_list
        if not depths[0] <= bit_depth <= depths[-1]:
            return None
        index = min(bisect.bisect_right(depths, bit_depth) - 1, len(depths) - 2)
        lo, hi = depths[index], depths[index + 1]
        weight = (bit_depth - lo) / (hi - lo)
        keep = 1.0 - weight
        values = [lower * keep + upper * weight for lower, upper in self._intervals[index]]
        n = len(self.band_mu)
        loads = ModelledLoads(bit_depth, values[0], values[1], values[2], values[3],
                              self.band_mu, tuple(values[4:4 + n]),
                              tuple(values[4 + n:4 + 2 * n]),
                              *(values[4 + 2 * n:] if self._slopes else ()))
        self._last = loads
        return loads


#: What the hook-load sensor reads of the model's loads: the calibration's current estimate of
#: the measurement (:class:`tdmon.calib.measurement.SensorEstimate`) with the model's own block
#: weight [N], or None where the sensor reads the load on the hook as modelled.
SensorReading = Callable[[], "tuple[SensorEstimate, float] | None"]


def as_read(loads: ModelledLoads, estimate: SensorEstimate, model_block_weight: float
            ) -> ModelledLoads:
    """``loads`` as the rig's hook-load sensor reads them (docs/hookload.md): pick-up curves
    hoisting, slack-off curves lowering, the rotating load with the block still, each
    ``f(motion) (B + F) + o`` with ``F`` the modelled string load (the model's hook load less
    its block weight ``model_block_weight`` [N]); the torque as it is."""

    def read(load: float, motion: int) -> float:
        return estimate.reading(load - model_block_weight, motion)

    return ModelledLoads(loads.bit_depth, read(loads.pick_up, 1), read(loads.slack_off, -1),
                         read(loads.rotating, 0), loads.torque_rotating, loads.band_mu,
                         tuple(read(v, 1) for v in loads.band_pick_up),
                         tuple(read(v, -1) for v in loads.band_slack_off),
                         loads.hookload_per_wob, loads.torque_per_wob)


@dataclass(frozen=True, slots=True)
class DrillingView:
    """The drilling part of one frame's ``model`` message (docs/drilling.md); None where not
    known.

    Attributes
    ----------
    hookload : the drilling curve: the modelled hook load on bottom with ``wob``, as the
        sensor reads it lowering [N]
    torque : the modelled surface torque on bottom with ``wob`` and ``bit_torque`` [N m]
    wob, wob_source : the weight on bit the curve uses [N] and whose ("downhole", "surface")
    wob_surface, wob_downhole : the rig's surface and the MWD's downhole weight on bit [N]
    wob_estimated, wob_estimated_std : the weight at the bit from the hook load
        (`tdmon.calib.drilling.downhole_wob`) and its standard deviation [N]
    bit_torque, bit_torque_source : [N m] and whose (``BIT_TORQUE_SOURCES``)
    """

    hookload: float | None
    torque: float | None
    wob: float | None
    wob_source: str | None
    wob_surface: float | None
    wob_downhole: float | None
    wob_estimated: float | None
    wob_estimated_std: float | None
    bit_torque: float | None
    bit_torque_source: str | None

    def message(self) -> dict[str, Any]:
        """The ``drilling`` field of the ``model`` message."""
        return {"wob_N": self.wob, "wob_source": self.wob_source,
                "wob_surface_N": self.wob_surface, "wob_downhole_N": self.wob_downhole,
                "wob_estimated_N": self.wob_estimated,
                "wob_estimated_std_N": self.wob_estimated_std,
                "bit_torque_Nm": self.bit_torque, "bit_torque_source": self.bit_torque_source}


class DrillingMonitor:
    """The monitor's drilling: tags and the bit torque of each (`tdmon.calib.drilling.track`),
    the weight at the bit from the hook load, and the drilling curve at the frame's weight on
    bit and bit torque.

    ``bit`` (diameter [m], specific coefficient of sliding friction [-]) gives the bit torque
    by Pessier and Fear's model before a tag's torque step is known (None: not known then);
    ``settle`` [s] is how long after a tag its torque step is averaged."""

    def __init__(self, bit: tuple[float, float] | None = None, settle: float = 30.0) -> None:
        self.bit = bit
        self.settle = settle
        self.state = DrillingState()

    def on_frame(self, frame: Frame, loads: ModelledLoads,
                 reading: tuple[SensorEstimate, float] | None) -> DrillingView | None:
        """Follow one frame; its drilling view when it is drilling (None otherwise)."""
        values = frame.values
        drilling = frame.state == "drilling"
        mwd = values.get("downhole_wob")
        surface = values.get("wob")
        wob = mwd if mwd is not None else surface
        change = loads.torque_per_wob * wob if drilling and wob is not None else 0.0
        hookload = values.get("hookload")
        self.state = track(self.state, frame.t, frame.state, frame.steady, loads.bit_depth,
                           values.get("hole_depth"), hookload, values.get("torque"),
                           string_torque_change=change, settle=self.settle)
        if not drilling:
            return None
        bit_torque, source = self._bit_torque(values.get("downhole_torque"), wob)
        estimated = std = None
        if hookload is not None and reading is None:
            estimated = (hookload - loads.rotating) / loads.hookload_per_wob
        elif hookload is not None and reading is not None:
            estimate, block = reading
            estimated, std = downhole_wob(hookload, loads.rotating - block, estimate,
                                          load_per_wob=loads.hookload_per_wob)
        curve = torque = None
        if wob is not None:
            curve = loads.rotating + loads.hookload_per_wob * wob
            if reading is not None:
                curve = reading[0].reading(curve - reading[1], -1)
            if bit_torque is not None:
                torque = loads.torque_rotating + loads.torque_per_wob * wob + bit_torque
        return DrillingView(curve, torque, wob,
                            None if wob is None else "downhole" if mwd is not None else "surface",
                            surface, mwd, estimated, std, bit_torque, source)

    def _bit_torque(self, downhole: float | None, wob: float | None
                    ) -> tuple[float | None, str | None]:
        if downhole is not None:
            return downhole, "downhole"
        if self.state.bit_torque is not None:
            return self.state.bit_torque, "tag"
        if self.bit is not None and wob is not None:
            return bit_torque_pessier(wob, *self.bit), "model"
        return None, None


def with_fluid(loads: ModelledLoads, effect: FluidEffect) -> ModelledLoads:
    """``loads`` with what the fluid terms change on each curve (the fluid step's
    `tdmon.daemon.steps.fluids.FluidEffect` of the frame: viscous drag at the trip speed,
    densities along the string, the force at the bit while circulating); the band's curves
    take their operation's change."""
    hookload, torque = effect.curve_hookload, effect.curve_torque
    up, down = hookload["pick_up"], hookload["slack_off"]
    return ModelledLoads(loads.bit_depth, loads.pick_up + up, loads.slack_off + down,
                         loads.rotating + hookload["rotating"],
                         loads.torque_rotating + torque["rotating"], loads.band_mu,
                         tuple(v + up for v in loads.band_pick_up),
                         tuple(v + down for v in loads.band_slack_off))


class MonitorStep:
    """Step: emit ``model`` for every frame with a fresh bit depth inside the model's reach.

    ``sensor`` (None: the hook-load channel is the load on the hook) gives what is known of
    the hook-load measurement now; the modelled hook loads are then shown as that sensor
    reads them, so that the residual is the measured reading against the modelled one.
    ``drilling`` follows the drilling frames (`DrillingMonitor`; one with no bit model by
    default): theirs are compared with the drilling curve."""

    name = "monitor"

    def __init__(self, model: LoadModel, sensor: SensorReading | None = None,
                 drilling: DrillingMonitor | None = None) -> None:
        self.model = model
        self.sensor = sensor
        self.drilling = drilling if drilling is not None else DrillingMonitor()
        self.skipped_no_depth = 0
        self.skipped_out_of_range = 0

    def on_frame(self, frame: Frame, emit: Emit) -> None:
        bit_depth = frame.values.get("bit_depth")
        if bit_depth is None:
            self.skipped_no_depth += 1
            return
        loads = self.model.loads(bit_depth)
        if loads is None:
            self.skipped_out_of_range += 1
            return
        fluid = frame.results.get("fluids")
        if fluid is not None:
            loads = with_fluid(loads, fluid["effect"])
        reading = self.sensor() if self.sensor is not None else None
        drilling = self.drilling.on_frame(frame, loads, reading)
        if reading is not None:
            loads = as_read(loads, *reading)
        emit("model", model_message(frame, loads, drilling))

    def close(self, emit: Emit) -> None:
        """Nothing buffered."""


def model_message(frame: Frame, loads: ModelledLoads, drilling: DrillingView | None = None
                  ) -> dict[str, Any]:
    """The ``model`` daemon message for one frame (docs/architecture.md); a drilling frame's
    (``drilling`` given) has the drilling curve and is compared with it (docs/drilling.md)."""
    hookload = frame.values.get("hookload")
    torque = frame.values.get("torque")
    curve = _CURVE_FOR_STATE.get(frame.state)
    modelled: dict[str, Any] = {"pick_up": loads.pick_up, "slack_off": loads.slack_off,
                                "rotating": loads.rotating}
    modelled_torque: dict[str, Any] = {"rotating": loads.torque_rotating}
    if drilling is not None:
        modelled["drilling"] = drilling.hookload
        modelled_torque["drilling"] = drilling.torque
        hookload_residual = (None if hookload is None or drilling.hookload is None
                             else hookload - drilling.hookload)
        torque_residual = (None if torque is None or drilling.torque is None
                           else torque - drilling.torque)
    else:
        hookload_residual = (None if hookload is None or curve is None
                             else hookload - modelled[curve])
        torque_residual = (torque - loads.torque_rotating
                           if torque is not None and frame.state in ROTATING_STATES else None)
    message = {
        "t": frame.t,
        "bit_depth_m": loads.bit_depth,
        "hookload_N": modelled,
        "torque_Nm": modelled_torque,
        "band": {"mu": list(loads.band_mu), "pick_up_N": list(loads.band_pick_up),
                 "slack_off_N": list(loads.band_slack_off)},
        "measured": {"hookload_N": hookload, "torque_Nm": torque},
        "residual": {"hookload_N": hookload_residual, "torque_Nm": torque_residual},
    }
    if drilling is not None:
        message["drilling"] = drilling.message()
    return message
