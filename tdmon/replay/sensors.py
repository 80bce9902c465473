"""The sensors of a simulated session: each channel's true value, and what a rig sends of it.

A channel's true value at its sample times comes from the timeline (depths, rotation, flow,
weight on bit), from the loads (hook load, torque) or from the scenario (mud temperatures);
:func:`sensor_series` then applies the channel's noise, spikes, scheduled faults, missing
samples and clock jitter, from the channel's own random stream.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tdmon.channels import check_channel
from tdmon.config.scenario import CHANNELS
from tdmon.errors import ModelError
from tdmon.replay.loads import Loads
from tdmon.replay.spec import Array, NoiseSettings, Scenario
from tdmon.replay.timeline import Timeline

__all__ = ["ChannelSeries", "InjectedFault", "block_motion", "channel_truth", "measured_hookload",
           "sensor_series"]


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
class InjectedFault:
    """A sensor fault put into the data: ``spike`` (one sample), ``stuck`` or ``dropout``
    (a window ``t`` .. ``until`` [Unix s])."""

    t: float
    kind: str
    channel: str
    until: float | None = None


def block_motion(timeline: Timeline, t: Array) -> NDArray[np.int64]:
    """The travelling block's motion at times ``t`` [s from the start]: +1 hoisting, -1
    lowering, 0 still (the segment's block travel; the empty block moves in slips too)."""
    index = timeline.segment_at(t)
    return np.sign(timeline.block1[index] - timeline.block0[index]).astype(np.int64)


def measured_hookload(scenario: Scenario, timeline: Timeline, hook_load: Array,
                      t: Array) -> Array:
    """What the rig's hook-load sensor reads [N] of the load on the hook ``hook_load`` [N] at
    times ``t`` [s from the start]: the sheave factor of the block's motion, the travelling
    equipment above a load pin, and the drifting zero offset (``scenario.measurement``). The
    block's speed changes step-wise between segments, so no inertia is added."""
    measurement = scenario.measurement
    if not measurement.any:
        return hook_load
    sensor = measurement.sensor
    motion = block_motion(timeline, t)
    reading = np.empty_like(hook_load)
    for direction in (-1, 0, 1):
        where = motion == direction
        reading[where] = sensor.reading(hook_load[where], direction)
    return reading + measurement.offset(t, timeline.duration)


def channel_truth(name: str, scenario: Scenario, timeline: Timeline, loads: Loads,
                  t: Array) -> Array:
    """Noise-free values [SI] of channel ``name`` at times ``t`` [s from the start] (the hook
    load as the rig's sensor reads it, :func:`measured_hookload`)."""
    where = timeline.at(t)
    index = where.segment
    if name in ("hookload", "torque"):
        hookload, torque = loads.at(timeline, t)
        if name == "torque":
            return torque
        return measured_hookload(scenario, timeline, hookload, t)
    if name in ("bit_depth", "hole_depth", "block_position"):
        return np.asarray(getattr(where, name), dtype=np.float64)
    # constant over each segment of the timeline
    per_segment = {"rpm": timeline.rpm, "flow_in": timeline.flow, "wob": timeline.wob}
    if name in per_segment:
        return per_segment[name][index]
    if name == "spp" and loads.fluid is not None:
        return loads.fluid.standpipe_pressure(t)
    if name == "mud_density":  # the mud pumped in: a phase's pill, else the well's mud
        density = timeline.density[index]
        return np.where(np.isnan(density), scenario.well.fluid.density, density)
    if name == "spp":
        rig = scenario.rig
        return np.asarray(rig.spp_reference * (timeline.flow[index] / rig.flow_reference) ** 2)
    constant = {"mud_temp_in": scenario.mud_temp_in, "mud_temp_out": scenario.mud_temp_out}
    if name in constant:
        value = constant[name]
        return np.full(t.size, np.nan if value is None else value)
    try:
        check_channel(name, CHANNELS)
    except ValueError as exc:
        raise ModelError(str(exc)) from None
    raise ModelError(f"no simulated series for channel '{name}'")


def sensor_series(name: str, scenario: Scenario, tau: Array, truth: Array, interval: float,
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
    value = truth * (1.0 + noise.relative * gauss_rel) + noise.absolute * gauss_abs + noise.offset
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
