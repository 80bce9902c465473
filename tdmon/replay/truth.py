"""The truth of a simulated session: what the daemon should find in it.

The rig state at its changes, the noise-free loads and the effective friction factors at every
true hook-load sample time, and the alarms a tight spot, a friction anomaly or a sensor fault
should raise.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Final

import numpy as np
from numpy.typing import NDArray

from tdmon.daemon.steps.coverage import SHORT_TOLERANCE
from tdmon.model.torque_drag import WellModel
from tdmon.model.well import Well
from tdmon.replay.loads import MOVING_DOWN, MOVING_UP, Loads
from tdmon.replay.sensors import block_motion, measured_hookload
from tdmon.replay.spec import Array, Scenario
from tdmon.replay.timeline import Timeline
from tdmon.vocabulary import AlarmKind, Operation, RigState, Severity

__all__ = ["ExpectedAlarm", "expected_alarms", "state_changes", "truth_samples",
           "weight_factors"]

# A tight spot or a local friction change shows as a window's friction jumping above the recent
# ones, or as the load trending out of the modelled band.
_FRICTION_ALARMS: Final = (AlarmKind.FRICTION_JUMP, AlarmKind.BAND)
_EPS = 1e-9


@dataclass(frozen=True)
class ExpectedAlarm:
    """An alarm the daemon should raise: ``kind`` at about ``t`` [Unix s], with context.

    ``kind`` names the event (``overpull``, ``set_down``, ``friction_anomaly``,
    ``stuck_sensor``, ``data_gap``, ``string_short``: the bit deeper than the daemon's well
    file's string is long); ``accept`` lists the daemon's alarm kinds
    (:mod:`tdmon.calib.alarms`) that count as raising it.
    """

    t: float
    kind: str
    severity: Severity
    message: str
    channel: str | None = None
    md: float | None = None
    accept: tuple[str, ...] = ()


def state_changes(timeline: Timeline, start: float) -> list[tuple[float, RigState]]:
    """(Unix time [s], state) at the start and at every change of rig state."""
    changes: list[tuple[float, RigState]] = []
    for t0, state in zip(timeline.t0, timeline.state, strict=True):
        if not changes or changes[-1][1] != state:
            changes.append((start + float(t0), state))
    return changes


def expected_alarms(scenario: Scenario, truth_t: Array,
                    truth: dict[str, NDArray[np.generic]]) -> list[ExpectedAlarm]:
    """The alarms the scenario's tight spots, friction anomalies and sensor faults should
    raise, in time order (``truth_t`` [Unix s] and ``truth`` from :func:`truth_samples`)."""
    alarms: list[ExpectedAlarm] = []
    state = truth["state"]
    bit = np.asarray(truth["bit_depth"], dtype=np.float64)
    for spot in scenario.tight_spots:
        inside = (bit >= spot.md) & (bit <= spot.md + spot.length)
        for kind, states, word in (("overpull", MOVING_UP, "overpull"),
                                   ("set_down", MOVING_DOWN, "set-down weight")):
            hits = np.flatnonzero(inside & np.isin(state, states))
            if hits.size:
                alarms.append(ExpectedAlarm(
                    float(truth_t[hits[0]]), kind, Severity.WARNING,
                    f"{word} of {spot.force / 1e3:.0f} kN at a tight spot at {spot.md:.0f} m MD",
                    md=spot.md, accept=_FRICTION_ALARMS))
    moving = np.isin(state, (RigState.PICK_UP, RigState.SLACK_OFF))
    for anomaly in scenario.anomalies:
        hits = np.flatnonzero(moving & (bit >= anomaly.top))
        if hits.size:
            alarms.append(ExpectedAlarm(
                float(truth_t[hits[0]]), "friction_anomaly", Severity.WARNING,
                f"local friction {anomaly.delta_mu:+.2f} between {anomaly.top:.0f} and "
                f"{anomaly.bottom:.0f} m MD", md=0.5 * (anomaly.top + anomaly.bottom),
                accept=_FRICTION_ALARMS))
    for fault in scenario.faults:
        kind = "stuck_sensor" if fault.kind == "stuck" else "data_gap"
        channels = [c for c in fault.channels if c in scenario.sample_interval]
        if channels:
            # one alarm per fault: a dropout of every channel is one gap, not nine
            alarms.append(ExpectedAlarm(
                scenario.start + fault.start, kind, Severity.WARNING,
                f"{', '.join(channels)} {'stuck' if fault.kind == 'stuck' else 'silent'} for "
                f"{fault.duration:.0f} s", channel=channels[0] if len(channels) == 1 else None,
                accept=tuple(f"sensor_{c}_frozen" for c in channels) if fault.kind == "stuck"
                else (AlarmKind.SENSOR_STALE,)))
    paper = scenario.model_well
    if paper is not None:
        # the daemon's well file has a shorter string than the bit depth: coverage alarm
        short = np.flatnonzero(bit > paper.string.length + SHORT_TOLERANCE)
        if short.size:
            k = int(short[0])
            alarms.append(ExpectedAlarm(
                float(truth_t[k]), "string_short", Severity.CRITICAL,
                f"string tally {float(bit[k]) - paper.string.length:.1f} m shorter than bit "
                f"depth {float(bit[k]):.1f} m", md=float(bit[k]),
                accept=(AlarmKind.MODEL_COVERAGE,)))
    return sorted(alarms, key=lambda alarm: alarm.t)


def truth_samples(timeline: Timeline, loads: Loads, tau: Array, element_md: Array,
                  element_length: Array) -> dict[str, NDArray[np.generic]]:
    """The truth at times ``tau`` [s from the start]: see :class:`tdmon.replay.session.Session`
    ``truth`` (element mid-MD and length [m] give the mean friction the string meets)."""
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
        if state[k] == RigState.IN_SLIPS:
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
    out = {"state": state, "bit_depth": bit, "hole_depth": where.hole_depth,
           "block_position": where.block_position, "hookload": hookload, "torque": torque,
           **mus}
    scenario = loads.scenario
    if scenario.measurement.any:
        out["hookload_reading"] = measured_hookload(scenario, timeline, hookload, tau)
        out["block_motion"] = block_motion(timeline, tau)
        out["hookload_offset"] = scenario.measurement.offset(tau, timeline.duration)
    return out



def weight_factors(loads: Loads, model_well: Well, truth: dict[str, NDArray[np.generic]]) -> Array:
    """The weight factor an injected model error implies at every truth sample [-]: true over
    modelled buoyed string weight at the hook (:meth:`Loads.weight_factor`), the model being
    ``model_well`` (the daemon's well file) with its top component reaching surface when its
    tally is shorter than the bit depth; NaN in slips."""
    bit = np.asarray(truth["bit_depth"], dtype=np.float64)
    state = truth["state"]
    paper = WellModel(model_well)
    factors = np.full(bit.size, np.nan)
    cache: dict[float, float] = {}
    for k in range(bit.size):
        if state[k] == RigState.IN_SLIPS:
            continue
        depth = float(bit[k])
        if depth not in cache:
            model = paper
            if depth > model_well.string.length:
                model = WellModel(replace(model_well, string=model_well.string.reaching(depth)))
            cache[depth] = loads.weight_factor(model, depth)
        factors[k] = cache[depth]
    return factors
