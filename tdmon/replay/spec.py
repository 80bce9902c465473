"""What a simulated session is generated from: the rig programme, the rig, the friction
anomalies and tight spots, the sensors' noise and faults, gathered in a :class:`Scenario`.

Pure data (frozen dataclasses, SI units, times in s from the session start). A scenario TOML
(:mod:`tdmon.config.scenario`) is turned into a :class:`Scenario` by
:func:`tdmon.replay.scenario.to_scenario`; :func:`tdmon.replay.session.simulate_session`
generates the session from it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from tdmon.model.hookload_sensor import HookloadSensor
from tdmon.model.well import Well

__all__ = [
    "Array",
    "FrictionAnomaly",
    "HookloadMeasurement",
    "ModelMismatch",
    "NoiseSettings",
    "Phase",
    "RigSettings",
    "Scenario",
    "SensorFault",
    "TightSpot",
]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Phase:
    """One step of the rig programme.

    Attributes
    ----------
    kind : one of :data:`tdmon.config.scenario.PHASE_KINDS`
    duration : length of a ``static``/``circulate``/``rotate``/``slips`` phase [s]
    to : target bit depth of a trip or ream, target hole depth of ``drill`` [m]
    speed : trip or ream speed, rate of penetration for ``drill`` [m/s]
    rpm : surface rotation speed [rad/s]
    flow : pump rate [m^3/s]
    wob : weight on bit while drilling [N]
    slips_time : duration of each connection in slips [s]
    density : density of the mud pumped in this phase [kg/m^3] (a pill or a slug; None: the
        well's mud)
    """

    kind: str
    duration: float = 0.0
    to: float | None = None
    speed: float = 0.0
    rpm: float = 0.0
    flow: float = 0.0
    wob: float = 0.0
    slips_time: float = 60.0
    density: float | None = None


@dataclass(frozen=True)
class RigSettings:
    """Rig geometry and simple surface relations.

    Attributes
    ----------
    stand_length : block travel per stand [m]
    block_low : height of the travelling block above the rig floor at the bottom of its travel [m]
    spp_reference, flow_reference : stand-pipe pressure [Pa] at pump rate [m^3/s];
        ``spp = spp_reference (flow / flow_reference)^2`` (turbulent losses)
    bit_torque_factor : bit torque per weight on bit [m] (about mu_bit D_bit / 3)
    latency : delay between sampling and arrival at tdmon [s]
    break_over : extra hook load at the start of a pull from rest (static friction and the
        string's inertia) [N], decaying as ``exp(-t / break_over_time)``
    break_over_time : decay time of the break-over peak [s]
    """

    stand_length: float = 28.0
    block_low: float = 2.0
    spp_reference: float = 150e5
    flow_reference: float = 2000.0 / 60000.0
    bit_torque_factor: float = 0.02
    latency: float = 0.2
    break_over: float = 0.0
    break_over_time: float = 3.0


@dataclass(frozen=True)
class FrictionAnomaly:
    """Extra friction ``delta_mu`` [-] on the hole elements whose mid-MD lies in
    [``top``, ``bottom``] [m]."""

    top: float
    bottom: float
    delta_mu: float


@dataclass(frozen=True)
class TightSpot:
    """A restriction at MD ``md`` [m]: while the bit is between ``md`` and ``md + length`` the
    string pulls ``force`` [N] more when moving up (overpull) and sets down ``force`` when moving
    down (set-down weight)."""

    md: float
    length: float
    force: float


@dataclass(frozen=True)
class NoiseSettings:
    """Measurement imperfections of one channel.

    Attributes
    ----------
    relative : standard deviation of the Gaussian noise as a fraction of the reading [-]
    absolute : standard deviation of an additive Gaussian noise [SI unit of the channel]
    spike_rate : probability that a sample is a spike [-]
    spike_size : spike amplitude as a fraction of the channel's largest true reading [-]
    missing_rate : probability that a sample is never sent [-]
    clock_jitter : standard deviation of the error of the payload time stamp [s] (clipped to
        0.45 of the sampling interval so that a channel stays in order)
    offset : a constant zero offset added to every reading [SI unit of the channel] (a torque
        sensor reading a few hundred N m on a still string)
    """

    relative: float = 0.0
    absolute: float = 0.0
    spike_rate: float = 0.0
    spike_size: float = 0.2
    missing_rate: float = 0.0
    clock_jitter: float = 0.0
    offset: float = 0.0


@dataclass(frozen=True)
class HookloadMeasurement:
    """How the rig's hook-load channel is made of the load on the hook (the truth; the
    daemon's well file may describe the sensor differently).

    Attributes
    ----------
    sensor : where the sensor sits, the lines and the true sheave efficiency
        (:class:`tdmon.model.hookload_sensor.HookloadSensor`); the default reads the load on
        the hook
    offset_start, offset_end : zero offset of the sensor at the session's start and end [N],
        drifting linearly in between
    """

    sensor: HookloadSensor = field(default_factory=HookloadSensor)
    offset_start: float = 0.0
    offset_end: float = 0.0

    @property
    def any(self) -> bool:
        """Whether the channel differs from the load on the hook at all."""
        return (self.sensor.reads_sheave_friction and self.sensor.efficiency != 1.0) \
            or self.sensor.above_sensor != 0.0 or self.offset_start != 0.0 \
            or self.offset_end != 0.0

    def offset(self, tau: Array, duration: float) -> Array:
        """Zero offset [N] at times ``tau`` [s from the start] of a session of ``duration``."""
        share = np.clip(tau / duration, 0.0, 1.0) if duration > 0 else np.zeros_like(tau)
        return self.offset_start + share * (self.offset_end - self.offset_start)


@dataclass(frozen=True)
class SensorFault:
    """A scheduled sensor fault: ``stuck`` (the last good value repeats) or ``dropout`` (nothing
    is sent) on ``channels`` from ``start`` for ``duration`` [s after the session start]."""

    kind: str
    channels: tuple[str, ...]
    start: float
    duration: float


@dataclass(frozen=True)
class ModelMismatch:
    """How the rig's true string and fluid differ from the well file the daemon reads.

    Attributes
    ----------
    density_factor : true fluid density (inside and outside the pipe) over the well file's [-]
    fill_level : MD of the fluid level inside the pipe [m]: the pipe is empty above it, full
        below (the pipe run unfilled); None: full to surface, as the well file assumes
    extra_length : the true string is this much longer than the well file's tally [m]
    extra_component : index (from the bit) of the component whose true length is longer
    """

    density_factor: float = 1.0
    fill_level: float | None = None
    extra_length: float = 0.0
    extra_component: int = 0

    @property
    def any(self) -> bool:
        """Whether the truth differs from the well file at all."""
        return (self.density_factor != 1.0 or self.fill_level is not None
                or self.extra_length != 0.0)


@dataclass(frozen=True)
class Scenario:
    """Everything a session is generated from (SI units; times in s from the start).

    Attributes
    ----------
    name, seed : label and random seed
    start : Unix time of the first sample [s]
    prefix : topic prefix of the rig, e.g. ``"sim/example-7-1"``
    well : the model layer's well (block weight included)
    friction : base friction factor per hole-grid element, e.g. mu(T_annulus) [-]
    temperature : annulus temperature per hole-grid element [degC], or None
    mud_temp_in, mud_temp_out : mud temperatures at surface [degC] (None: channel not sent)
    method : torque-and-drag method (``"soft-string"`` or ``"aadnoy"``)
    bit_depth, hole_depth : at the start [m]
    block_position : block height above the rig floor at the start [m]
    phases : the rig programme
    rig : rig settings
    anomalies : local friction anomalies
    tight_spots : restrictions giving overpull / set-down
    sample_interval : per channel [s]; a channel left out is not sent
    noise : per channel
    faults : scheduled sensor faults
    mismatch : injected model errors; ``well`` is then the true well (fluid density and string
        changed, the fill level applied per bit depth by :class:`tdmon.replay.loads.Loads`)
    model_well : the well as the daemon's well file describes it (None: ``well``)
    measurement : how the hook-load channel reads the load on the hook (sheave friction of a
        deadline sensor, zero offset)
    """

    name: str
    seed: int
    start: float
    prefix: str
    well: Well
    friction: Array
    temperature: Array | None
    mud_temp_in: float | None
    mud_temp_out: float | None
    method: str
    bit_depth: float
    hole_depth: float
    block_position: float
    phases: tuple[Phase, ...]
    rig: RigSettings = field(default_factory=RigSettings)
    anomalies: tuple[FrictionAnomaly, ...] = ()
    tight_spots: tuple[TightSpot, ...] = ()
    sample_interval: Mapping[str, float] = field(default_factory=dict)
    noise: Mapping[str, NoiseSettings] = field(default_factory=dict)
    faults: tuple[SensorFault, ...] = ()
    mismatch: ModelMismatch = field(default_factory=ModelMismatch)
    model_well: Well | None = None
    measurement: HookloadMeasurement = field(default_factory=HookloadMeasurement)
