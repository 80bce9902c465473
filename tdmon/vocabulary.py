"""The words tdmon's messages are made of: rig states, operations, alarm kinds, severities.

Every layer names these things the same way, and the JSON Schemas of the recorded messages
(`tdmon.record.schemas`) take their enumerations from here, so that a name the code can emit is
a name the schema lists. The members are ``StrEnum``: they compare equal to, hash like and
serialise as their plain string values, so a recorded or published message is unchanged.

The messages made of these words are built by `tdmon.messages`; the rig's channel names and
units are in `tdmon.channels`.

This module imports nothing of tdmon: every layer, the physics included, may use it.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import StrEnum
from types import MappingProxyType
from typing import Final

__all__ = [
    "ALARM_WORDS",
    "CALIBRATING_STATES",
    "CURVE_FOR_STATE",
    "FROZEN_ALARM_KINDS",
    "MOVING_STATES",
    "OPERATION_FOR_STATE",
    "REAMING_AXIAL_OPERATION",
    "ROTATING_STATES",
    "AlarmKind",
    "ConnectionState",
    "EstimateKind",
    "Operation",
    "RigState",
    "Severity",
]


class RigState(StrEnum):
    """What the rig is doing, as the rig-state detector classifies a sample
    (docs/back-calculation.md)."""

    IN_SLIPS = "in_slips"
    PICK_UP = "pick_up"
    SLACK_OFF = "slack_off"
    ROTATING_OFF_BOTTOM = "rotating_off_bottom"
    REAMING = "reaming"
    BACK_REAMING = "back_reaming"
    DRILLING = "drilling"
    CIRCULATING = "circulating"
    STATIC = "static"
    UNKNOWN = "unknown"


class Operation(StrEnum):
    """A load case of the torque-and-drag model.

    static: hanging still (no friction); rotating: rotating off bottom (no axial friction);
    pick_up: pulling out; slack_off: lowering; on_bottom: rotating with weight on the bit.
    """

    STATIC = "static"
    ROTATING = "rotating"
    PICK_UP = "pick_up"
    SLACK_OFF = "slack_off"
    ON_BOTTOM = "on_bottom"


class Severity(StrEnum):
    """How urgent an alarm is."""

    INFO = "info"
    WARNING = "warning"
    CRITICAL = "critical"


class EstimateKind(StrEnum):
    """What an ``estimate`` message holds: one window's friction, the friction profile along
    MD, the live mu(T) calibration, or friction and weight factor estimated jointly."""

    WINDOW = "window"
    PROFILE = "profile"
    MU_T = "mu_T"
    JOINT = "joint"


MOVING_STATES: Final = frozenset({RigState.PICK_UP, RigState.SLACK_OFF, RigState.REAMING,
                                  RigState.BACK_REAMING})
"""States in which the string moves axially."""

ROTATING_STATES: Final = frozenset({RigState.ROTATING_OFF_BOTTOM, RigState.REAMING,
                                    RigState.BACK_REAMING, RigState.DRILLING})
"""States in which the string rotates."""

OPERATION_FOR_STATE: Final[Mapping[RigState, Operation]] = MappingProxyType({
    RigState.PICK_UP: Operation.PICK_UP,
    RigState.BACK_REAMING: Operation.PICK_UP,
    RigState.SLACK_OFF: Operation.SLACK_OFF,
    RigState.REAMING: Operation.SLACK_OFF,
    RigState.ROTATING_OFF_BOTTOM: Operation.ROTATING,
    RigState.DRILLING: Operation.ON_BOTTOM,
    RigState.CIRCULATING: Operation.STATIC,
    RigState.STATIC: Operation.STATIC,
})
"""The model's load case for each rig state that hangs the string from the hook (in slips and
unknown have none). Reaming and back-reaming combine rotation with the axial motion: their
axial load case is the one of their direction of motion."""

REAMING_AXIAL_OPERATION: Final[Mapping[RigState, Operation]] = MappingProxyType({
    RigState.REAMING: Operation.SLACK_OFF,
    RigState.BACK_REAMING: Operation.PICK_UP,
})
"""Axial operation of the combined-motion states, whose friction comes from the torque with the
friction split by the motion angle psi (Aadnoy, Fazaelizadeh and Hareland 2010)."""

CURVE_FOR_STATE: Final[Mapping[RigState, Operation]] = MappingProxyType({
    state: (operation if operation in (Operation.PICK_UP, Operation.SLACK_OFF)
            else Operation.ROTATING)
    for state, operation in OPERATION_FOR_STATE.items()
})
"""Which modelled hook-load curve of the monitor (pick-up, slack-off or rotating) a measured
hook load is compared with, per rig state: the static and on-bottom hook loads are read
against the rotating (friction-free axial) curve."""

CALIBRATING_STATES: Final = frozenset({RigState.PICK_UP, RigState.SLACK_OFF,
                                       RigState.ROTATING_OFF_BOTTOM})
"""States whose steady windows calibrate a friction factor directly: pick-up and slack-off
hook load, rotating-off-bottom torque."""


class ConnectionState(StrEnum):
    """The state of a source's or publisher's connection in the ``status`` message (a retrying
    connection reports ``"retrying in N s: reason"``, see `tdmon.daemon.supervisor`)."""

    CONNECTING = "connecting"
    CONNECTED = "connected"
    FINISHED = "finished"
    CLOSED = "closed"
    RETRYING = "retrying"


class AlarmKind(StrEnum):
    """Every ``kind`` an ``alarm`` message can carry (docs/back-calculation.md, "Alarms")."""

    BAND = "band"
    FRICTION_JUMP = "friction_jump"
    LIMIT_TENSILE = "limit_tensile"
    LIMIT_SINUSOIDAL_BUCKLING = "limit_sinusoidal_buckling"
    LIMIT_HELICAL_BUCKLING = "limit_helical_buckling"
    LIMIT_MAKEUP_TORQUE = "limit_makeup_torque"
    SENSOR_STALE = "sensor_stale"
    SENSOR_HOOKLOAD_IMPLAUSIBLE = "sensor_hookload_implausible"
    SENSOR_BIT_BELOW_HOLE = "sensor_bit_below_hole"
    SENSOR_HOOKLOAD_FROZEN = "sensor_hookload_frozen"
    SENSOR_TORQUE_FROZEN = "sensor_torque_frozen"
    SENSOR_RPM_FROZEN = "sensor_rpm_frozen"
    SENSOR_BIT_DEPTH_FROZEN = "sensor_bit_depth_frozen"
    SENSOR_BLOCK_POSITION_FROZEN = "sensor_block_position_frozen"
    SENSOR_FLOW_IN_FROZEN = "sensor_flow_in_frozen"
    SENSOR_SPP_FROZEN = "sensor_spp_frozen"
    SENSOR_WOB_FROZEN = "sensor_wob_frozen"
    WINDOW_REJECTED = "window_rejected"
    BLOCK_WEIGHT = "block_weight"
    WEIGHT_CHECK = "weight_check"
    RECORDER_FAILED = "recorder_failed"
    RECORDER_RESUMED = "recorder_resumed"
    RECORDING_RECOVERED = "recording_recovered"
    DATA_LOSS = "data_loss"
    CLOCK_JUMP = "clock_jump"  # the rig clock moved; the aligner re-anchored (docs/daemon.md)
    MODEL_COVERAGE = "model_coverage"  # string shorter than the bit depth, or a new well file
    WEIGHT_MISMATCH = "weight_mismatch"  # joint friction/weight estimate (calib/mismatch.py)
    TRIP_SPEED = "trip_speed"  # surge/swab past the pore/fracture window (daemon/steps/fluids.py)


ALARM_WORDS: Final[Mapping[AlarmKind, str]] = MappingProxyType({
    AlarmKind.BAND: "hook load outside the modelled band (a trend, not a spike)",
    AlarmKind.FRICTION_JUMP: "friction factor jumped above its recent level",
    AlarmKind.LIMIT_TENSILE: "string tension near or over the tensile limit",
    AlarmKind.LIMIT_SINUSOIDAL_BUCKLING: "compression near or over sinusoidal buckling",
    AlarmKind.LIMIT_HELICAL_BUCKLING: "compression near or over helical buckling",
    AlarmKind.LIMIT_MAKEUP_TORQUE: "torque near or over the connections' make-up torque",
    AlarmKind.SENSOR_STALE: "a sensor stopped sending",
    AlarmKind.SENSOR_HOOKLOAD_IMPLAUSIBLE: "hook load reading not physically plausible",
    AlarmKind.SENSOR_BIT_BELOW_HOLE: "bit depth reading below the hole's total depth",
    AlarmKind.SENSOR_HOOKLOAD_FROZEN: "hook load reading frozen (unchanged while moving)",
    AlarmKind.SENSOR_TORQUE_FROZEN: "torque reading frozen while rotating",
    AlarmKind.SENSOR_RPM_FROZEN: "rotary speed reading frozen (unchanged while the torque says "
                                 "the string stopped)",
    AlarmKind.SENSOR_BIT_DEPTH_FROZEN: "bit depth reading frozen while the block moves the "
                                       "string",
    AlarmKind.SENSOR_BLOCK_POSITION_FROZEN: "block position reading frozen while the bit depth "
                                            "moves with the string on the hook",
    AlarmKind.SENSOR_FLOW_IN_FROZEN: "flow-in reading frozen while the standpipe pressure says "
                                     "the pumps started or stopped",
    AlarmKind.SENSOR_SPP_FROZEN: "standpipe pressure reading frozen while the flow says the "
                                 "pumps started or stopped",
    AlarmKind.SENSOR_WOB_FROZEN: "weight-on-bit reading frozen while the hook load changes on "
                                 "bottom",
    AlarmKind.WINDOW_REJECTED: "a measurement window could not give a friction factor",
    AlarmKind.BLOCK_WEIGHT: "block weight estimate disagrees with the configured one",
    AlarmKind.WEIGHT_CHECK: "string weight in slips-off hangs disagrees with the well file",
    AlarmKind.RECORDER_FAILED: "the flight recorder failed to write",
    AlarmKind.RECORDER_RESUMED: "the flight recorder writes again",
    AlarmKind.RECORDING_RECOVERED: "an unfinished recording was recovered at start-up",
    AlarmKind.DATA_LOSS: "input messages were lost",
    AlarmKind.CLOCK_JUMP: "the rig clock jumped; timing re-anchored",
    AlarmKind.MODEL_COVERAGE: "the well file's string does not reach the bit, or the well file "
                              "changed (a new run, a reload)",
    AlarmKind.WEIGHT_MISMATCH: "friction and weight estimated together find the string lighter "
                               "or heavier than the well file says",
    AlarmKind.TRIP_SPEED: "trip speed fast enough for surge or swab to leave the pore/fracture "
                          "window",
})
"""What each alarm kind means, in a drilling engineer's words (the report's and the summary's
``meaning``). Every kind has its words: ``tests/test_vocabulary.py`` fails on a kind without."""

FROZEN_ALARM_KINDS: Final[Mapping[str, AlarmKind]] = MappingProxyType({
    "hookload": AlarmKind.SENSOR_HOOKLOAD_FROZEN,
    "torque": AlarmKind.SENSOR_TORQUE_FROZEN,
    "rpm": AlarmKind.SENSOR_RPM_FROZEN,
    "bit_depth": AlarmKind.SENSOR_BIT_DEPTH_FROZEN,
    "block_position": AlarmKind.SENSOR_BLOCK_POSITION_FROZEN,
    "flow_in": AlarmKind.SENSOR_FLOW_IN_FROZEN,
    "spp": AlarmKind.SENSOR_SPP_FROZEN,
    "wob": AlarmKind.SENSOR_WOB_FROZEN,
})
"""The alarm a frozen channel raises, per channel the frozen-channel check follows
(`tdmon.calib.frozen`): ``sensor_<channel>_frozen``, as the simulator's expected alarms name
them (docs/replays.md). ``tests/test_vocabulary.py`` holds the two lists together."""

