"""The friction estimator's settings, state and outputs (`tdmon.calib.estimator` updates them).

The state is frozen throughout; mappings in it are read-only views of dicts that are replaced,
never changed, and the two filter objects it holds are never changed once in a state (see
`tdmon.calib.estimator`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Final, NamedTuple

from tdmon.calib.alarms import JumpSettings
from tdmon.calib.blockweight import BlockWeightWindow, BuoyancyCheck
from tdmon.calib.cased import CasedFriction
from tdmon.calib.drilling import DrillingState
from tdmon.calib.joint import JointSettings, JointState
from tdmon.calib.mismatch import Mismatch
from tdmon.calib.mu_calibration import MuTCalibrator
from tdmon.calib.profile import FrictionProfile
from tdmon.calib.scatter import Scatter
from tdmon.calib.slips import SlipsRun
from tdmon.calib.windows import Window, WindowAccumulator, WindowSettings

__all__ = [
    "CalibrationSettings",
    "EstimatorState",
    "Output",
    "SampleState",
    "WindowState",
    "count",
    "put",
]


def _empty() -> Mapping[str, Any]:
    return MappingProxyType({})


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of the estimator (SI).

    Attributes
    ----------
    windows : window building and checking
    method : torque-and-drag method of the back-calculation
    bracket : friction range of the root solve [-]
    min_open_length : string below the shoe needed to solve open-hole friction [m]
    profile_bin : depth-bin length of the friction profile [m]
    prior_mu, prior_std : prior friction per bin [-]
    process_std : drift per window of the profile and mu(T) filters [-]
    mu_t_mode : ``"family"`` or ``"scale"`` (when a mu(T) law and temperatures are given)
    limit_warn : utilisation that raises a limit warning [-]
    jump : friction-jump settings
    learn_block_weight : feed the in-slips block weight back into the rig-state threshold
    block_weight_tolerance : relative deviation from the configured block weight reported [-]
    joint : the joint friction and weight-factor estimate (its prior, drift, mismatch alarm)
    tag_settle : a tag's bit torque is the mean torque step of its first this many seconds
        on bottom [s] (`tdmon.calib.drilling.track`)
    """

    windows: WindowSettings = field(default_factory=WindowSettings)
    method: str = "soft-string"
    bracket: tuple[float, float] = (0.0, 1.0)
    min_open_length: float = 30.0
    profile_bin: float = 30.0
    prior_mu: float = 0.25
    prior_std: float = 0.1
    process_std: float = 0.002
    mu_t_mode: str = "family"
    limit_warn: float = 0.8
    jump: JumpSettings = field(default_factory=JumpSettings)
    learn_block_weight: bool = True
    block_weight_tolerance: float = 0.05
    joint: JointSettings = field(default_factory=JointSettings)
    tag_settle: float = 30.0


class Output(NamedTuple):
    """One message to send: ``topic`` (``"estimate"`` or ``"alarm"``) and its fields."""

    topic: str
    message: dict[str, Any]


#: an empty window and no in-slips hook load, shared: values never changed once made
_NO_WINDOW: Final = WindowAccumulator()
_NO_BLOCK_WEIGHT: Final = BlockWeightWindow()
_NO_DRILLING: Final = DrillingState()


@dataclass(frozen=True, slots=True)
class SampleState:
    """What samples change: the window being built and the in-slips block weight.

    Attributes
    ----------
    accumulator : the window being built
    block_weight : the last steady in-slips hook loads and their block weight (the rig-state
        detector's threshold)
    slips : the connection in slips going on: its readings by the block's motion (None: the
        string is on the hook)
    drilling : the tags and the bit torque of the last one (`tdmon.calib.drilling`)
    """

    accumulator: WindowAccumulator = _NO_WINDOW
    block_weight: BlockWeightWindow = _NO_BLOCK_WEIGHT
    slips: SlipsRun | None = None
    drilling: DrillingState = _NO_DRILLING


@dataclass(frozen=True)
class WindowState:
    """What windows change.

    Attributes
    ----------
    profile : the local friction profile (a value: never changed once here)
    mu_t : the mu(T) calibration, None when off (a value too)
    profile_updates : windows the profile has taken [-]
    cased : per rig state, the cased-hole friction found so far
    pending : per rig state, deep windows waiting for the cased friction
    history : per rig state, the recent window frictions of the jump alarm [-]
    active_limits : kinds of the load-limit alarms of the last window (reported on onset)
    anomalous_bins : profile bins already reported as a friction anomaly
    weight_off : consecutive static hangs whose weight is off [-]
    weight_checks : the recent weight checks, oldest first
    rejected : windows rejected or not solved, per reason [-]
    joint : the joint friction and weight-factor filter (None: not started)
    scatter : per measurement kind, the recent window frictions of the between-window scatter
    mismatch : the weight-mismatch alarm's memory
    last_motion : ``pick_up``, ``slack_off`` (whose drag a hang keeps in part) or ``rotating``
        (off bottom: the drag released), the last motion (None: none yet)
    block_alarmed : the block-weight alarm has been raised (it is raised once)
    """

    profile: FrictionProfile
    mu_t: MuTCalibrator | None = None
    profile_updates: int = 0
    cased: Mapping[str, CasedFriction] = field(default_factory=_empty)
    pending: Mapping[str, tuple[Window, ...]] = field(default_factory=_empty)
    history: Mapping[str, tuple[float, ...]] = field(default_factory=_empty)
    active_limits: frozenset[str] = frozenset()
    anomalous_bins: frozenset[int] = frozenset()
    weight_off: int = 0
    weight_checks: tuple[BuoyancyCheck, ...] = ()
    rejected: Mapping[str, int] = field(default_factory=_empty)
    joint: JointState | None = None
    scatter: Mapping[str, Scatter] = field(default_factory=_empty)
    mismatch: Mismatch = field(default_factory=Mismatch)
    last_motion: str | None = None
    block_alarmed: bool = False

    def mu_cased(self, state: str) -> float | None:
        """Cased-hole friction of ``state`` found so far [-] (None: not yet)."""
        cased = self.cased.get(state)
        return None if cased is None else cased.mu


@dataclass(frozen=True, slots=True)
class EstimatorState:
    """The whole state: what samples change and what windows change."""

    samples: SampleState
    windows: WindowState


def put(mapping: Mapping[str, Any], key: str, value: Any) -> Mapping[str, Any]:
    """A new read-only mapping with ``key`` set (``mapping`` is left as it is)."""
    return MappingProxyType({**mapping, key: value})


def count(rejected: Mapping[str, int], reason: str) -> Mapping[str, int]:
    """A new read-only mapping with one more ``reason``."""
    return put(rejected, reason, rejected.get(reason, 0) + 1)
