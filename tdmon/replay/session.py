"""A simulated rig session with a known truth: scenario in, channel arrays and truth arrays out.

Pure: no files, no clock, no global random state. :func:`simulate_session` takes a
:class:`Scenario` (built from a scenario TOML by :mod:`tdmon.replay.scenario`) and returns a
:class:`Session`: for every canonical channel the sample times, the values as a rig would send
them (noise, spikes, stuck values, dropouts, clock jitter) and the noise-free values, plus the
truth a replay is checked against (rig state, friction profile, effective friction factors,
expected alarms, injected faults).

How the loads are computed
--------------------------
The session is a list of segments (one rig state with linear bit, hole and block motion). At every
sample time the surface hook load and torque come from one call of
:meth:`tdmon.model.torque_drag.WellModel.evaluate` with the true per-element friction profile.
One call costs about 12 us (compiled march over ~400 elements), so even an hour at 1 s is
well under a second, and the recorded noise-free value *is* the model at that bit depth: a test
or a calibrator can compare with the model exactly. A broomstick over a depth grid with
interpolation would only pay off beyond ~10^5 samples and would put an interpolation error
into the truth.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from tdmon.errors import ModelError
from tdmon.model.torque_drag import Operation, WellModel
from tdmon.model.well import Well

__all__ = [
    "CHANNELS",
    "FAULT_KINDS",
    "PHASE_KINDS",
    "STATES",
    "ChannelSeries",
    "ExpectedAlarm",
    "FrictionAnomaly",
    "InjectedFault",
    "NoiseSettings",
    "Phase",
    "Position",
    "RigSettings",
    "Scenario",
    "SensorFault",
    "Session",
    "TightSpot",
    "Timeline",
    "build_timeline",
    "friction_with_anomalies",
    "simulate_session",
]

Array = NDArray[np.float64]

#: Rig states of docs/architecture.md (``unknown`` is the daemon's, never a truth).
STATES: tuple[str, ...] = ("in_slips", "pick_up", "slack_off", "rotating_off_bottom", "reaming",
                           "back_reaming", "drilling", "circulating", "static")
#: Channels the simulator can send, in the order their random streams are seeded.
CHANNELS: tuple[str, ...] = ("hookload", "torque", "bit_depth", "hole_depth", "block_position",
                             "rpm", "flow_in", "spp", "wob", "mud_temp_in", "mud_temp_out")
PHASE_KINDS: tuple[str, ...] = ("static", "circulate", "rotate", "slips", "trip_out", "trip_in",
                                "ream", "back_ream", "drill")
FAULT_KINDS: tuple[str, ...] = ("stuck", "dropout")

# Blocks closer than this [m] to the end of their travel need a connection before moving on.
_MIN_TRAVEL = 0.5
_EPS = 1e-9


@dataclass(frozen=True)
class Phase:
    """One step of the rig programme.

    Attributes
    ----------
    kind : one of :data:`PHASE_KINDS`
    duration : length of a ``static``/``circulate``/``rotate``/``slips`` phase [s]
    to : target bit depth of a trip or ream, target hole depth of ``drill`` [m]
    speed : trip or ream speed, rate of penetration for ``drill`` [m/s]
    rpm : surface rotation speed [rad/s]
    flow : pump rate [m^3/s]
    wob : weight on bit while drilling [N]
    slips_time : duration of each connection in slips [s]
    """

    kind: str
    duration: float = 0.0
    to: float | None = None
    speed: float = 0.0
    rpm: float = 0.0
    flow: float = 0.0
    wob: float = 0.0
    slips_time: float = 60.0


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
    """

    relative: float = 0.0
    absolute: float = 0.0
    spike_rate: float = 0.0
    spike_size: float = 0.2
    missing_rate: float = 0.0
    clock_jitter: float = 0.0


@dataclass(frozen=True)
class SensorFault:
    """A scheduled sensor fault: ``stuck`` (the last good value repeats) or ``dropout`` (nothing
    is sent) on ``channels`` from ``start`` for ``duration`` [s after the session start]."""

    kind: str
    channels: tuple[str, ...]
    start: float
    duration: float


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
    [m]; rotation [rad/s], flow [m^3/s] and weight on bit [N] are constant in a segment."""

    t0: Array
    t1: Array
    state: tuple[str, ...]
    bit0: Array
    bit1: Array
    hole0: Array
    hole1: Array
    block0: Array
    block1: Array
    rpm: Array
    flow: Array
    wob: Array

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


@dataclass(frozen=True)
class ChannelSeries:
    """One channel as sent.

    Attributes
    ----------
    t : payload time stamps [Unix s] (with clock jitter)
    receive_time : arrival at tdmon [Unix s] (true sampling time plus latency)
    value : values sent [SI]
    true_value : noise-free values at the true sampling time [SI]
    """

    t: Array
    receive_time: Array
    value: Array
    true_value: Array


@dataclass(frozen=True)
class ExpectedAlarm:
    """An alarm the daemon should raise: ``kind`` at about ``t`` [Unix s], with context.

    ``kind`` names the event (``overpull``, ``set_down``, ``friction_anomaly``,
    ``stuck_sensor``, ``data_gap``); ``accept`` lists the daemon's alarm kinds
    (:mod:`tdmon.calib.alarms`) that count as raising it.
    """

    t: float
    kind: str
    severity: str
    message: str
    channel: str | None = None
    md: float | None = None
    accept: tuple[str, ...] = ()


@dataclass(frozen=True)
class InjectedFault:
    """A sensor fault put into the data: ``spike`` (one sample), ``stuck`` or ``dropout``
    (a window ``t`` .. ``until`` [Unix s])."""

    t: float
    kind: str
    channel: str
    until: float | None = None


@dataclass(frozen=True)
class Session:
    """A generated session.

    Attributes
    ----------
    scenario : what it was generated from
    timeline : the rig motion
    channels : per channel name, what was sent
    truth_t : times of the truth samples [Unix s] (the true hook-load sampling times)
    truth : per truth sample: ``state`` (str array), ``bit_depth``, ``hole_depth``,
        ``block_position`` [m], ``hookload`` [N], ``torque`` [N m] (noise-free), ``mu_pick_up``,
        ``mu_slack_off``, ``mu_rotating`` (the uniform friction factor reproducing the true
        pick-up/slack-off hook load and rotating torque at that bit depth; NaN in slips),
        ``mu_mean`` (length-weighted mean of the profile over the string in the hole) [-]
    state_changes : (Unix time [s], state) at the start and every change
    profile_md : mid-MD of the hole-grid elements [m]
    profile_mu : true friction factor per element (base plus anomalies) [-]
    profile_temperature : annulus temperature per element [degC] or None
    alarms : expected alarms
    faults : injected sensor faults
    """

    scenario: Scenario
    timeline: Timeline
    channels: dict[str, ChannelSeries]
    truth_t: Array
    truth: dict[str, NDArray[np.generic]]
    state_changes: list[tuple[float, str]]
    profile_md: Array
    profile_mu: Array
    profile_temperature: Array | None
    alarms: list[ExpectedAlarm]
    faults: list[InjectedFault]


# -- timeline --------------------------------------------------------------------------------

class _Builder:
    """Appends segments while tracking where bit, hole and block are."""

    def __init__(self, scenario: Scenario) -> None:
        self.rig = scenario.rig
        self.t = 0.0
        self.bit = scenario.bit_depth
        self.hole = scenario.hole_depth
        self.block = scenario.block_position
        self.rows: list[tuple[float, float, str, float, float, float, float, float, float,
                              float, float, float]] = []

    @property
    def block_high(self) -> float:
        return self.rig.block_low + self.rig.stand_length

    def add(self, duration: float, state: str, *, bit: float | None = None,
            hole: float | None = None, block: float | None = None, rpm: float = 0.0,
            flow: float = 0.0, wob: float = 0.0) -> None:
        bit1 = self.bit if bit is None else bit
        hole1 = self.hole if hole is None else hole
        block1 = self.block if block is None else block
        if duration <= 0.0:
            return
        self.rows.append((self.t, self.t + duration, state, self.bit, bit1, self.hole, hole1,
                          self.block, block1, rpm, flow, wob))
        self.t += duration
        self.bit, self.hole, self.block = bit1, hole1, block1

    def connection(self, slips_time: float, going_deeper: bool) -> None:
        # In slips the empty block travels back to where the next stand starts: up when the
        # string goes deeper, down when it comes out.
        target = self.block_high if going_deeper else self.rig.block_low
        self.add(slips_time, "in_slips", block=target)

    def move(self, phase: Phase, target: float, state: str, drilling: bool = False) -> None:
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
                     wob=phase.wob if drilling else 0.0)


def build_timeline(scenario: Scenario) -> Timeline:
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
        if kind in ("static", "circulate", "rotate", "slips"):
            state = {"static": "static", "circulate": "circulating",
                     "rotate": "rotating_off_bottom", "slips": "in_slips"}[kind]
            rpm = phase.rpm if kind == "rotate" else 0.0
            flow = phase.flow if kind != "slips" else 0.0
            builder.add(phase.duration, state, rpm=rpm, flow=flow)
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
            builder.move(phase, phase.to, "drilling", drilling=True)
            continue
        down = kind in ("trip_in", "ream")
        if (down and phase.to <= builder.bit) or (not down and phase.to >= builder.bit):
            raise ModelError(f"{where}: 'to' ({phase.to:g} m) must be "
                             f"{'below' if down else 'above'} the bit ({builder.bit:g} m)")
        if phase.to > builder.hole + 1e-6:
            raise ModelError(f"{where}: 'to' ({phase.to:g} m) is below the hole depth "
                             f"({builder.hole:g} m); drill it")
        moving_state = {"trip_out": "pick_up", "trip_in": "slack_off", "ream": "reaming",
                        "back_ream": "back_reaming"}.get(kind)
        if moving_state is None:
            raise ModelError(f"{where}: unknown phase kind (one of {', '.join(PHASE_KINDS)})")
        builder.move(phase, phase.to, moving_state)
    if not builder.rows:
        raise ModelError("the scenario has no phase with a duration")
    columns = list(zip(*builder.rows, strict=True))

    def floats(k: int) -> Array:
        return np.asarray(columns[k], dtype=np.float64)

    return Timeline(t0=floats(0), t1=floats(1), state=tuple(str(s) for s in columns[2]),
                    bit0=floats(3), bit1=floats(4), hole0=floats(5), hole1=floats(6),
                    block0=floats(7), block1=floats(8), rpm=floats(9), flow=floats(10),
                    wob=floats(11))


# -- loads -----------------------------------------------------------------------------------

def friction_with_anomalies(element_mid_md: Array, base: Array,
                            anomalies: tuple[FrictionAnomaly, ...]) -> Array:
    """Per-element friction factor [-]: ``base`` plus each anomaly on the elements it covers."""
    mu = np.array(base, dtype=np.float64, copy=True)
    for anomaly in anomalies:
        mu[(element_mid_md >= anomaly.top) & (element_mid_md <= anomaly.bottom)] += \
            anomaly.delta_mu
    return mu


_MOVING_UP = ("pick_up", "back_reaming")
# A tight spot or a local friction change shows as a window's friction jumping above the recent
# ones, or as the load trending out of the modelled band.
_FRICTION_ALARMS = ("friction_jump", "band")
_MOVING_DOWN = ("slack_off", "reaming")


class _Loads:
    """Surface hook load [N] and torque [N m] of any timeline state, from the model."""

    def __init__(self, scenario: Scenario, mu: Array, model: WellModel) -> None:
        self.scenario = scenario
        self.model = model
        self.mu = mu
        # psi needs the pipe's surface speed: the radius of the top component, which is most
        # of the string in the hole
        self.pipe_radius = float(self.model.component_radius[-1])
        self.block_weight = scenario.well.block_weight

    def at(self, timeline: Timeline, t: Array) -> tuple[Array, Array]:
        where = timeline.at(t)
        index = where.segment
        speed = timeline.speed(index)
        hookload = np.empty(t.size)
        torque = np.empty(t.size)
        for k in range(t.size):
            i = int(index[k])
            hookload[k], torque[k] = self.one(
                timeline.state[i], float(where.bit_depth[k]), float(speed[k]),
                float(timeline.rpm[i]), float(timeline.wob[i]))
        return hookload + self.break_over(timeline, index, t), torque

    def break_over(self, timeline: Timeline, index: NDArray[np.int64], t: Array) -> Array:
        """Break-over peak [N] of pulls that start from rest (not from another pull)."""
        rig = self.scenario.rig
        extra = np.zeros(t.size)
        if rig.break_over <= 0.0:
            return extra
        for k, i in enumerate(index):
            if (timeline.state[i] in _MOVING_UP and i > 0
                    and timeline.state[i - 1] not in _MOVING_UP):
                extra[k] = rig.break_over * math.exp(-(t[k] - timeline.t0[i])
                                                     / rig.break_over_time)
        return extra

    def one(self, state: str, bit: float, speed: float, rpm: float, wob: float) -> tuple[
            float, float]:
        if state == "in_slips":
            return self.block_weight, 0.0
        method = self.scenario.method
        psi = None
        if state in ("reaming", "back_reaming") and rpm > 0.0:
            psi = math.atan2(abs(speed), rpm * self.pipe_radius)
        operation = {
            "pick_up": Operation.PICK_UP, "back_reaming": Operation.PICK_UP,
            "slack_off": Operation.SLACK_OFF, "reaming": Operation.SLACK_OFF,
            "rotating_off_bottom": Operation.ROTATING, "drilling": Operation.ON_BOTTOM,
        }.get(state, Operation.STATIC)
        hookload, torque = self.model.evaluate(
            operation, bit, self.mu, method=method, wob=wob,
            bit_torque=wob * self.scenario.rig.bit_torque_factor, psi=psi)
        for spot in self.scenario.tight_spots:
            if spot.md <= bit <= spot.md + spot.length:
                if state in _MOVING_UP:
                    hookload += spot.force
                elif state in _MOVING_DOWN:
                    hookload -= spot.force
        return hookload, torque

    def effective_mu(self, operation: Operation, bit: float) -> float:
        """Uniform mu giving the true profile's pick-up/slack-off hook load or rotating torque."""
        method = self.scenario.method
        if operation is Operation.ROTATING:
            _, true_torque = self.model.evaluate(operation, bit, self.mu, method=method)
            _, unit_torque = self.model.evaluate(operation, bit, 1.0, method=method)
            # off-bottom torque is linear in a uniform mu: no axial friction changes the tension
            return true_torque / unit_torque if unit_torque > 0 else math.nan
        target, _ = self.model.evaluate(operation, bit, self.mu, method=method)

        def mismatch(mu: float) -> float:
            return self.model.evaluate(operation, bit, mu, method=method)[0] - target

        low, high = mismatch(0.0), mismatch(2.0)
        if low == 0.0:
            return 0.0
        if low * high > 0:
            return math.nan
        return float(brentq(mismatch, 0.0, 2.0, xtol=1e-7))


# -- channels --------------------------------------------------------------------------------

def _channel_truth(name: str, scenario: Scenario, timeline: Timeline, loads: _Loads,
                   t: Array) -> Array:
    where = timeline.at(t)
    index = where.segment
    if name in ("hookload", "torque"):
        hookload, torque = loads.at(timeline, t)
        return hookload if name == "hookload" else torque
    if name in ("bit_depth", "hole_depth", "block_position"):
        return np.asarray(getattr(where, name), dtype=np.float64)
    if name == "rpm":
        return timeline.rpm[index]
    if name == "flow_in":
        return timeline.flow[index]
    if name == "spp":
        rig = scenario.rig
        return np.asarray(rig.spp_reference * (timeline.flow[index] / rig.flow_reference) ** 2)
    if name == "wob":
        return timeline.wob[index]
    if name == "mud_temp_in":
        return np.full(t.size, np.nan if scenario.mud_temp_in is None else scenario.mud_temp_in)
    if name == "mud_temp_out":
        return np.full(t.size, np.nan if scenario.mud_temp_out is None else scenario.mud_temp_out)
    raise ModelError(f"unknown channel '{name}' (one of {', '.join(CHANNELS)})")


def _sensor(name: str, scenario: Scenario, tau: Array, truth: Array, interval: float,
            rng: np.random.Generator) -> tuple[ChannelSeries, list[InjectedFault]]:
    """Noise, spikes, faults, missing samples and jitter applied to one channel's truth."""
    noise = scenario.noise.get(name, NoiseSettings())
    start = scenario.start
    n = tau.size
    # Draw every random stream whatever the settings, so that switching one feature on does
    # not reshuffle the others.
    gauss_rel, gauss_abs, jitter = rng.standard_normal(n), rng.standard_normal(n), \
        rng.standard_normal(n)
    spike_draw, spike_sign, missing_draw = rng.random(n), rng.random(n), rng.random(n)
    value = truth * (1.0 + noise.relative * gauss_rel) + noise.absolute * gauss_abs
    faults: list[InjectedFault] = []
    scale = float(np.max(np.abs(truth))) if n else 0.0
    spikes = spike_draw < noise.spike_rate
    if scale > 0.0 and spikes.any():
        value[spikes] += np.where(spike_sign[spikes] < 0.5, -1.0, 1.0) * noise.spike_size * scale
        faults += [InjectedFault(start + float(x), "spike", name) for x in tau[spikes]]
    keep = missing_draw >= noise.missing_rate
    for fault in scenario.faults:
        if name not in fault.channels:
            continue
        inside = (tau >= fault.start) & (tau < fault.start + fault.duration)
        faults.append(InjectedFault(start + fault.start, fault.kind, name,
                                    start + fault.start + fault.duration))
        if fault.kind == "dropout":
            keep &= ~inside
        elif fault.kind == "stuck" and inside.any():
            first = int(np.argmax(inside))
            value[inside] = value[first - 1] if first > 0 else value[first]
    limit = 0.45 * interval
    stamp = tau + np.clip(noise.clock_jitter * jitter, -limit, limit)
    series = ChannelSeries(t=start + stamp[keep], receive_time=start + tau[keep] +
                           scenario.rig.latency, value=value[keep], true_value=truth[keep])
    return series, faults


# -- truth -----------------------------------------------------------------------------------

def _state_changes(timeline: Timeline, start: float) -> list[tuple[float, str]]:
    changes: list[tuple[float, str]] = []
    for t0, state in zip(timeline.t0, timeline.state, strict=True):
        if not changes or changes[-1][1] != state:
            changes.append((start + float(t0), state))
    return changes


def _expected_alarms(scenario: Scenario, timeline: Timeline, truth_t: Array,
                     truth: dict[str, NDArray[np.generic]]) -> list[ExpectedAlarm]:
    alarms: list[ExpectedAlarm] = []
    state = truth["state"]
    bit = np.asarray(truth["bit_depth"], dtype=np.float64)
    for spot in scenario.tight_spots:
        inside = (bit >= spot.md) & (bit <= spot.md + spot.length)
        for kind, states, word in (("overpull", _MOVING_UP, "overpull"),
                                   ("set_down", _MOVING_DOWN, "set-down weight")):
            hits = np.flatnonzero(inside & np.isin(state, states))
            if hits.size:
                alarms.append(ExpectedAlarm(
                    float(truth_t[hits[0]]), kind, "warning",
                    f"{word} of {spot.force / 1e3:.0f} kN at a tight spot at {spot.md:.0f} m MD",
                    md=spot.md, accept=_FRICTION_ALARMS))
    moving = np.isin(state, ("pick_up", "slack_off"))
    for anomaly in scenario.anomalies:
        hits = np.flatnonzero(moving & (bit >= anomaly.top))
        if hits.size:
            alarms.append(ExpectedAlarm(
                float(truth_t[hits[0]]), "friction_anomaly", "warning",
                f"local friction {anomaly.delta_mu:+.2f} between {anomaly.top:.0f} and "
                f"{anomaly.bottom:.0f} m MD", md=0.5 * (anomaly.top + anomaly.bottom),
                accept=_FRICTION_ALARMS))
    for fault in scenario.faults:
        kind = "stuck_sensor" if fault.kind == "stuck" else "data_gap"
        channels = [c for c in fault.channels if c in scenario.sample_interval]
        if channels:
            # one alarm per fault: a dropout of every channel is one gap, not nine
            alarms.append(ExpectedAlarm(
                scenario.start + fault.start, kind, "warning",
                f"{', '.join(channels)} {'stuck' if fault.kind == 'stuck' else 'silent'} for "
                f"{fault.duration:.0f} s", channel=channels[0] if len(channels) == 1 else None,
                accept=tuple(f"sensor_{c}_frozen" for c in channels) if fault.kind == "stuck"
                else ("sensor_stale",)))
    return sorted(alarms, key=lambda alarm: alarm.t)


def _truth(scenario: Scenario, timeline: Timeline, loads: _Loads, tau: Array,
           element_md: Array, element_length: Array) -> dict[str, NDArray[np.generic]]:
    where = timeline.at(tau)
    index = where.segment
    hookload, torque = loads.at(timeline, tau)
    state = np.asarray([timeline.state[i] for i in index], dtype=np.str_)
    bit = where.bit_depth
    mus = {"mu_pick_up": np.full(tau.size, np.nan), "mu_slack_off": np.full(tau.size, np.nan),
           "mu_rotating": np.full(tau.size, np.nan), "mu_mean": np.full(tau.size, np.nan)}
    cache: dict[float, tuple[float, float, float, float]] = {}
    top_of_element = element_md - 0.5 * element_length
    for k in range(tau.size):
        if state[k] == "in_slips":
            continue
        depth = float(bit[k])
        if depth not in cache:
            # length of each element inside the string, for the mean friction it meets
            inside = np.clip(depth - top_of_element, 0.0, element_length)
            cache[depth] = (loads.effective_mu(Operation.PICK_UP, depth),
                            loads.effective_mu(Operation.SLACK_OFF, depth),
                            loads.effective_mu(Operation.ROTATING, depth),
                            float(np.sum(loads.mu * inside) / max(np.sum(inside), _EPS)))
        for key, value in zip(mus, cache[depth], strict=True):
            mus[key][k] = value
    return {"state": state, "bit_depth": bit, "hole_depth": where.hole_depth,
            "block_position": where.block_position, "hookload": hookload, "torque": torque,
            **mus}


def _sample_times(duration: float, interval: float) -> Array:
    return np.arange(0.0, duration - _EPS, interval, dtype=np.float64)


def simulate_session(scenario: Scenario) -> Session:
    """Generate a rig session with its truth.

    Parameters
    ----------
    scenario : the session's well, programme, sampling, noise and faults

    Returns
    -------
    Session
        Channels sampled every ``scenario.sample_interval[channel]`` seconds from the start
        (sample ``k`` at ``k * interval``, minus missing and dropped samples), truth sampled at
        the hook-load times.

    Raises
    ------
    ModelError
        A phase cannot be done, or a bit depth leaves the well (string too short, below the
        hole).

    Notes
    -----
    Deterministic: channel ``c`` draws from ``numpy.random.default_rng([seed, index of c in
    CHANNELS])``, so the same scenario gives the same session, and adding a channel does not
    change the others.
    """
    timeline = build_timeline(scenario)
    well = scenario.well
    model_check = WellModel(well)
    deepest = float(max(timeline.bit0.max(), timeline.bit1.max()))
    shallowest = float(min(timeline.bit0.min(), timeline.bit1.min()))
    model_check.check_bit_depth(deepest)
    model_check.check_bit_depth(shallowest)
    grid = model_check.grid
    element_md = grid.element_mid_md
    element_length = np.diff(grid.md)
    mu = friction_with_anomalies(element_md, np.asarray(scenario.friction, dtype=np.float64),
                                 scenario.anomalies)
    loads = _Loads(scenario, mu, model_check)

    channels: dict[str, ChannelSeries] = {}
    faults: list[InjectedFault] = []
    for number, name in enumerate(CHANNELS):
        interval = scenario.sample_interval.get(name)
        if interval is None:
            continue
        if name == "mud_temp_in" and scenario.mud_temp_in is None:
            continue
        if name == "mud_temp_out" and scenario.mud_temp_out is None:
            continue
        tau = _sample_times(timeline.duration, interval)
        truth_values = _channel_truth(name, scenario, timeline, loads, tau)
        rng = np.random.default_rng([scenario.seed, number])
        channels[name], injected = _sensor(name, scenario, tau, truth_values, interval, rng)
        faults += injected

    truth_interval = scenario.sample_interval.get("hookload", 5.0)
    tau = _sample_times(timeline.duration, truth_interval)
    truth = _truth(scenario, timeline, loads, tau, element_md, element_length)
    truth_t = scenario.start + tau
    return Session(
        scenario=scenario, timeline=timeline, channels=channels, truth_t=truth_t, truth=truth,
        state_changes=_state_changes(timeline, scenario.start), profile_md=element_md,
        profile_mu=mu, profile_temperature=scenario.temperature,
        alarms=_expected_alarms(scenario, timeline, truth_t, truth),
        faults=sorted(faults, key=lambda fault: (fault.t, fault.channel)),
    )
