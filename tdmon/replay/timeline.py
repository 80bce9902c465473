"""The rig motion of a scenario: its phases as a piecewise-linear timeline of rig states.

Trips, reaming and drilling move the string by at most the block travel left; when the block
reaches the end of its travel a connection in slips brings the empty block back. Each segment
of the :class:`Timeline` is one rig state with the bit, the hole bottom and the block moving
linearly, and constant rotation, flow and weight on bit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tdmon.config.scenario import PHASE_KINDS
from tdmon.errors import ModelError
from tdmon.replay.spec import Array, Phase, Scenario
from tdmon.vocabulary import RigState

__all__ = ["STATES", "Position", "Timeline", "build_timeline"]

STATES: Final[tuple[RigState, ...]] = tuple(s for s in RigState if s is not RigState.UNKNOWN)
"""Rig states a simulated session can be in (``unknown`` is the daemon's, never a truth)."""

_TIMED_STATE: Final[Mapping[str, RigState]] = MappingProxyType({
    "static": RigState.STATIC, "circulate": RigState.CIRCULATING,
    "rotate": RigState.ROTATING_OFF_BOTTOM, "slips": RigState.IN_SLIPS})
"""The rig state of each phase that lasts a duration."""

_MOVING_STATE: Final[Mapping[str, RigState]] = MappingProxyType({
    "trip_out": RigState.PICK_UP, "trip_in": RigState.SLACK_OFF, "ream": RigState.REAMING,
    "back_ream": RigState.BACK_REAMING})
"""The rig state of each phase that moves the bit to a depth (drilling aside)."""

# Blocks closer than this [m] to the end of their travel need a connection before moving on.
_MIN_TRAVEL = 0.5


class Position(NamedTuple):
    """Segment index and bit depth, hole depth, block position [m] at some times."""

    segment: NDArray[np.int64]
    bit_depth: Array
    hole_depth: Array
    block_position: Array


@dataclass(frozen=True)
class Timeline:
    """Piecewise-linear rig motion: segment ``i`` runs from ``t0[i]`` to ``t1[i]`` [s] in
    ``state[i]`` with bit, hole and block moving linearly between their ``*0`` and ``*1`` values
    [m]; rotation [rad/s], flow [m^3/s], weight on bit [N] and the density of the mud pumped
    in [kg/m^3] (NaN: the well's mud) are constant in a segment."""

    t0: Array
    t1: Array
    state: tuple[RigState, ...]
    bit0: Array
    bit1: Array
    hole0: Array
    hole1: Array
    block0: Array
    block1: Array
    rpm: Array
    flow: Array
    wob: Array
    density: Array

    @property
    def duration(self) -> float:
        """Length of the session [s]."""
        return float(self.t1[-1]) if self.t1.size else 0.0

    def segment_at(self, t: Array) -> NDArray[np.int64]:
        """Index of the segment each time [s] falls in (a boundary belongs to the later one)."""
        index = np.searchsorted(self.t1, t, side="right")
        return np.clip(index, 0, self.t1.size - 1).astype(np.int64)

    def at(self, t: Array) -> Position:
        """Where the bit, the hole bottom and the block are at times ``t`` [s]."""
        i = self.segment_at(t)
        span = self.t1[i] - self.t0[i]
        frac = np.where(span > 0, (t - self.t0[i]) / np.where(span > 0, span, 1.0), 0.0)
        frac = np.clip(frac, 0.0, 1.0)
        return Position(
            segment=i,
            bit_depth=self.bit0[i] + frac * (self.bit1[i] - self.bit0[i]),
            hole_depth=self.hole0[i] + frac * (self.hole1[i] - self.hole0[i]),
            block_position=self.block0[i] + frac * (self.block1[i] - self.block0[i]),
        )

    def speed(self, i: NDArray[np.int64]) -> Array:
        """Bit speed of segments ``i``, positive going deeper [m/s]."""
        span = self.t1[i] - self.t0[i]
        return np.where(span > 0, (self.bit1[i] - self.bit0[i]) / np.where(span > 0, span, 1.0),
                        0.0)


class _Builder:
    """Appends segments while tracking where bit, hole and block are."""

    def __init__(self, scenario: Scenario) -> None:
        self.rig = scenario.rig
        self.t = 0.0
        self.bit = scenario.bit_depth
        self.hole = scenario.hole_depth
        self.block = scenario.block_position
        self.rows: list[tuple[float, float, RigState, float, float, float, float, float, float,
                              float, float, float, float]] = []

    @property
    def block_high(self) -> float:
        return self.rig.block_low + self.rig.stand_length

    def add(self, duration: float, state: RigState, *, bit: float | None = None,
            hole: float | None = None, block: float | None = None, rpm: float = 0.0,
            flow: float = 0.0, wob: float = 0.0, density: float | None = None) -> None:
        bit1 = self.bit if bit is None else bit
        hole1 = self.hole if hole is None else hole
        block1 = self.block if block is None else block
        if duration <= 0.0:
            return
        self.rows.append((self.t, self.t + duration, state, self.bit, bit1, self.hole, hole1,
                          self.block, block1, rpm, flow, wob,
                          math.nan if density is None else density))
        self.t += duration
        self.bit, self.hole, self.block = bit1, hole1, block1

    def connection(self, slips_time: float, going_deeper: bool) -> None:
        # In slips the empty block travels back to where the next stand starts: up when the
        # string goes deeper, down when it comes out.
        target = self.block_high if going_deeper else self.rig.block_low
        self.add(slips_time, RigState.IN_SLIPS, block=target)

    def move(self, phase: Phase, target: float, state: RigState, drilling: bool = False) -> None:
        deeper = target > self.bit
        while abs(target - self.bit) > 1e-6:
            travel = (self.block - self.rig.block_low) if deeper else (self.block_high - self.block)
            if travel < _MIN_TRAVEL:
                if self.rig.stand_length < 2 * _MIN_TRAVEL:
                    raise ModelError(f"stand length {self.rig.stand_length:g} m leaves the block "
                                     "no travel")
                self.connection(phase.slips_time, deeper)
                continue
            step = min(abs(target - self.bit), travel)
            bit = self.bit + step if deeper else self.bit - step
            block = self.block - step if deeper else self.block + step
            self.add(step / phase.speed, state, bit=bit, block=block,
                     hole=bit if drilling else None, rpm=phase.rpm, flow=phase.flow,
                     wob=phase.wob if drilling else 0.0, density=phase.density)


def build_timeline(scenario: Scenario) -> Timeline:  # noqa: C901  (complex today; simplify when next touched)
    """The rig motion of a scenario's phases.

    Trips, reaming and drilling move the string by at most the block travel left; when the block
    reaches the end of its travel a connection in slips (``slips_time``) brings the empty block
    back. ``drill`` starts with the bit on bottom and advances bit and hole depth together.

    Raises
    ------
    ModelError
        A phase that cannot be done (target on the wrong side, bit above the hole bottom when
        drilling, bit below the hole, zero speed).
    """
    builder = _Builder(scenario)
    if not scenario.rig.block_low - 1e-9 <= scenario.block_position <= builder.block_high + 1e-9:
        raise ModelError(f"block position {scenario.block_position:g} m is outside its travel "
                         f"({scenario.rig.block_low:g} to {builder.block_high:g} m)")
    if scenario.bit_depth > scenario.hole_depth + 1e-9:
        raise ModelError(f"bit depth {scenario.bit_depth:g} m is below the hole depth "
                         f"{scenario.hole_depth:g} m")
    for number, phase in enumerate(scenario.phases):
        where = f"phase {number + 1} ({phase.kind})"
        kind = phase.kind
        timed_state = _TIMED_STATE.get(kind)
        if timed_state is not None:
            rpm = phase.rpm if kind == "rotate" else 0.0
            flow = phase.flow if kind != "slips" else 0.0
            builder.add(phase.duration, timed_state, rpm=rpm, flow=flow, density=phase.density)
            continue
        if phase.to is None or phase.speed <= 0.0:
            raise ModelError(f"{where}: needs 'to' and a positive speed")
        if kind == "drill":
            if abs(builder.bit - builder.hole) > 1e-6:
                raise ModelError(f"{where}: the bit ({builder.bit:g} m) must be on bottom "
                                 f"({builder.hole:g} m); ream down first")
            if phase.to <= builder.hole:
                raise ModelError(f"{where}: 'to' ({phase.to:g} m) must be below the hole depth "
                                 f"({builder.hole:g} m)")
            builder.move(phase, phase.to, RigState.DRILLING, drilling=True)
            continue
        down = kind in ("trip_in", "ream")
        if (down and phase.to <= builder.bit) or (not down and phase.to >= builder.bit):
            raise ModelError(f"{where}: 'to' ({phase.to:g} m) must be "
                             f"{'below' if down else 'above'} the bit ({builder.bit:g} m)")
        if phase.to > builder.hole + 1e-6:
            raise ModelError(f"{where}: 'to' ({phase.to:g} m) is below the hole depth "
                             f"({builder.hole:g} m); drill it")
        moving_state = _MOVING_STATE.get(kind)
        if moving_state is None:
            raise ModelError(f"{where}: unknown phase kind (one of {', '.join(PHASE_KINDS)})")
        builder.move(phase, phase.to, moving_state)
    if not builder.rows:
        raise ModelError("the scenario has no phase with a duration")
    columns = list(zip(*builder.rows, strict=True))

    def floats(k: int) -> Array:
        return np.asarray(columns[k], dtype=np.float64)

    return Timeline(t0=floats(0), t1=floats(1), state=tuple(RigState(s) for s in columns[2]),
                    bit0=floats(3), bit1=floats(4), hole0=floats(5), hole1=floats(6),
                    block0=floats(7), block1=floats(8), rpm=floats(9), flow=floats(10),
                    wob=floats(11), density=floats(12))
