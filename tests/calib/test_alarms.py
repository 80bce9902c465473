"""Alarms (band trend, limits, friction jump, sensors) and the daemon steps around the
estimators on synthetic trips: every message matches its JSON Schema and no NaN or inf is ever
emitted, also for garbage frames (hypothesis). The steps over the simulator's scenarios are in
tests/replay/test_scenario_steps.py."""

from __future__ import annotations

import functools
import json
import math
from dataclasses import replace
from typing import Any

import jsonschema
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tdmon.calib.alarms import (
    BandSettings,
    BandTrendState,
    JumpSettings,
    SensorSettings,
    SensorState,
    friction_jump,
    frozen_alarm,
    limit_alarms,
    profile_anomaly,
    sensor_alarms,
    update_band_trend,
)
from tdmon.calib.estimator import CalibrationSettings
from tdmon.calib.frozen import FrozenChannel
from tdmon.calib.rigstate import RigStateThresholds
from tdmon.calib.windows import Window, WindowSettings
from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.alarms import AlarmStep
from tdmon.daemon.steps.calibrate import CalibrationStep
from tdmon.daemon.steps.rig_state import RigStateStep
from tdmon.model.friction import KAARSTAD_2009
from tdmon.model.string import DrillString
from tdmon.model.torque_drag import WellModel
from tdmon.record.schemas import schema_for
from tdmon.vocabulary import AlarmKind


def test_band_spike_is_not_a_trend_but_an_offset_is() -> None:
    band = BandSettings(smoothing=0.1, threshold=3.0, min_samples=10)
    state = BandTrendState()
    alarms = []
    for k in range(50):  # one 20-sigma spike among in-band samples
        measured = 1.62e6 if k == 25 else 1.50e6
        state, alarm = update_band_trend(state, float(k), measured, 1.4e6, 1.55e6, 5e3, band)
        alarms.append(alarm)
    assert not any(alarms)
    for k in range(50, 120):  # then a sustained overpull 8 sigma above the band
        state, alarm = update_band_trend(state, float(k), 1.59e6, 1.4e6, 1.55e6, 5e3, band)
        alarms.append(alarm)
    fired = [a for a in alarms if a is not None]
    assert len(fired) == 1  # once per excursion
    assert fired[0].kind == "band" and fired[0].limit == 1.55e6
    assert fired[0].t >= 59.0  # needs min_samples beyond the band first
    state, alarm = update_band_trend(state, 200.0, math.nan, 1.4e6, 1.55e6, 5e3, band)
    assert alarm is None


def test_friction_jump() -> None:
    history = (0.20, 0.21, 0.19, 0.20, 0.205)
    jump = JumpSettings()
    assert friction_jump(history, 0.215, 0.005, 1.0, jump, operation="pick_up",
                         bit_depth=3000.0) is None
    alarm = friction_jump(history, 0.30, 0.005, 1.0, jump, operation="pick_up",
                          bit_depth=3000.0)
    assert alarm is not None and alarm.kind == "friction_jump"
    assert alarm.value == 0.30 and alarm.limit == pytest.approx(0.25)
    # an uncertain estimate does not raise it
    assert friction_jump(history, 0.30, 0.05, 1.0, jump, operation="pick_up",
                         bit_depth=3000.0) is None
    assert friction_jump(history[:2], 0.5, 0.005, 1.0, jump, operation="pick_up",
                         bit_depth=3000.0) is None


def test_limit_alarms_warn_then_critical(well_open: Any) -> None:
    # give the drill pipe a yield strength that puts pick-up tension near its limit
    pipe = well_open.string.components[1]
    area = pipe.area
    model = WellModel(well_open)
    loads = model.loads(4200.0, 0.25)
    top_tension = float(loads.axial_force["pick_up"][0])
    for fraction, severity in ((0.85, "warning"), (1.1, "critical")):
        weak = replace(pipe, yield_strength=top_tension / (fraction * area))
        well = replace(well_open, string=DrillString((well_open.string.components[0], weak)))
        alarms = limit_alarms(well, WellModel(well).loads(4200.0, 0.25), "pick_up", 5.0)
        tensile = [a for a in alarms if a.kind == "limit_tensile"]
        assert len(tensile) == 1
        assert tensile[0].severity == severity
        assert tensile[0].value == pytest.approx(top_tension)
        # the top of the string is named as an engineer would: at surface, not "at 0 m"
        assert tensile[0].message == (
            f"pick-up tension at surface is {100 * fraction:.0f} % of the tensile limit")
    assert limit_alarms(well_open, loads, "pick_up", 5.0) == []  # no yield strength given


def test_sensor_alarms() -> None:
    s = SensorSettings(persist_time=60.0)
    state = SensorState()
    state, alarms = sensor_alarms(state, 0.0, {"hookload": 1e6}, ("torque",), (), s)
    assert [a.kind for a in alarms] == ["sensor_stale"]
    state, alarms = sensor_alarms(state, 1.0, {"hookload": 1e6}, ("torque",), (), s)
    assert alarms == []  # reported once
    state, alarms = sensor_alarms(state, 2.0, {"hookload": -5e3}, (), (), s)
    assert [(a.kind, a.severity) for a in alarms] == [("sensor_hookload_implausible",
                                                       "critical")]
    kinds = []
    for k in range(12):  # a depth inconsistency must persist (hole depth is coarse)
        state, alarms = sensor_alarms(state, 20.0 + 10 * k, {"bit_depth": 3010.0,
                                                             "hole_depth": 3000.0}, (), (), s)
        kinds += [(k, a.kind) for a in alarms]
    assert kinds == [(6, "sensor_bit_below_hole")]


def test_a_frozen_channel_raises_its_own_alarm_once_with_why() -> None:
    # the rig-state detector names the frozen channels on every frame they stay frozen; the
    # alarm is raised when one first appears and again only after it moved
    rpm = FrozenChannel("rpm", 100 * math.pi / 30, 60.0,
                        "while the torque fell to 0.81 kN m: the string is not turning")
    torque = FrozenChannel("torque", 5.2e3, 70.0, "while the rpm reads 120.0 rpm")
    s, state, raised = SensorSettings(), SensorState(), []
    for t, frozen in ((90.0, (rpm,)), (91.0, (rpm,)), (100.0, (rpm, torque)), (101.0, ()),
                      (102.0, (rpm,))):
        state, alarms = sensor_alarms(state, t, {"hookload": 1e6}, (), frozen, s)
        raised += [(t, a.kind, a.severity, a.value) for a in alarms]
    assert raised == [(90.0, "sensor_rpm_frozen", "warning", pytest.approx(10.472, abs=1e-3)),
                      (100.0, "sensor_torque_frozen", "warning", 5.2e3),
                      (102.0, "sensor_rpm_frozen", "warning", pytest.approx(10.472, abs=1e-3))]
    alarm = frozen_alarm(90.0, rpm)
    assert alarm.message == (
        "rpm reads 100.0 rpm unchanged for 30 s while the torque fell to 0.81 kN m: the string "
        "is not turning; rotation is read from the torque alone and rotating windows are left "
        "out of the estimates")
    assert frozen_alarm(100.0, torque).message.startswith(
        "torque reads 5.20 kN m unchanged for 30 s while the rpm reads 120.0 rpm; ")


def test_sensor_state_carried_between_frames() -> None:
    s = SensorSettings(persist_time=1.0)
    hook = FrozenChannel("hookload", 1e6, 0.0, "while the string moves at 0.50 m/s")
    frames = [
        ({"hookload": 1e6, "torque": 0.0, "rpm": 10.0}, ("spp",), ()),
        ({"hookload": 1e6, "torque": 0.0, "bit_depth": 3010.0, "hole_depth": 3000.0}, (), ()),
        ({"hookload": 1e6, "bit_depth": 3010.0, "hole_depth": 3000.0}, ("spp", "rpm"), (hook,)),
        ({"hookload": 1.1e6, "bit_depth": 3010.0}, ("rpm",), ()),
    ]
    state, kinds = SensorState(), []
    states = []
    for k, (values, stale, frozen) in enumerate(frames):
        state, alarms = sensor_alarms(state, float(k), values, stale, frozen, s)
        kinds.append([a.kind for a in alarms])
        states.append(state)
    assert kinds == [["sensor_stale"], [], ["sensor_stale", "sensor_stale",
                                            "sensor_bit_below_hole", "sensor_hookload_frozen"],
                     []]
    assert states[2].active == frozenset({"sensor_hookload_frozen", "sensor_bit_below_hole"})
    assert states[1].below_since == 1.0 and states[2].below_since == 1.0
    assert states[3].stale == frozenset({"rpm"}) and states[3].active == frozenset()
    assert states[3].below_since is None


def _frames(session: Any) -> list[Frame]:
    frames = []
    for i in range(session.t.size):
        values = {"hookload": session.hookload[i], "bit_depth": session.bit_depth[i],
                  "block_position": session.block_position[i], "rpm": session.rpm[i],
                  "torque": session.torque[i], "hole_depth": session.hole_depth[i],
                  "flow_in": session.flow[i]}
        frames.append(Frame(t=float(session.t[i]), log_time_ns=int(session.t[i] * 1e9),
                            values={k: float(v) for k, v in values.items()}, ages={}))
    return frames


def _steps(model: WellModel, temperature: np.ndarray | None = None
           ) -> tuple[RigStateStep, CalibrationStep, AlarmStep]:
    rig = RigStateStep(RigStateThresholds(block_weight=model.well.block_weight))
    calibrate = CalibrationStep(model, rig, CalibrationSettings(
        windows=WindowSettings(min_samples=5), prior_mu=0.25),
        temperature=temperature, friction_law=KAARSTAD_2009["glydril"]
        if temperature is not None else None)
    return rig, calibrate, AlarmStep(rig_state=rig)


@functools.cache
def _validator(name: str) -> Any:
    """The validator of ``/tdmon/<name>``'s JSON Schema, the schema checked once: building one
    per message, as ``jsonschema.validate`` does, costs 25 times the validation itself."""
    schema = schema_for(f"/tdmon/{name}")
    validator = jsonschema.validators.validator_for(schema)
    validator.check_schema(schema)
    return validator(schema)


def _check(messages: list[tuple[str, dict[str, Any]]]) -> None:
    for name, message in messages:
        json.dumps(message, allow_nan=False)  # raises on NaN or inf
        _validator(name).validate(message)


def test_daemon_steps_emit_valid_estimates(model_cased: WellModel, trip: Any,
                                           temperatures: Any) -> None:
    kind = model_cased.grid.element_kind
    session = trip(model_cased, np.where(kind == "cased", 0.2, 0.3), start=4200.0, end=2500.0,
                   seed=41, rotate_every=5)
    steps = _steps(model_cased, temperatures(model_cased))
    messages: list[tuple[str, dict[str, Any]]] = []

    def emit(name: str, message: dict[str, Any]) -> None:
        messages.append((name, message))

    for frame in _frames(session):
        for step in steps:
            step.on_frame(frame, emit)
    for step in steps:
        step.close(emit)
    _check(messages)
    estimates = [m for n, m in messages if n == "estimate"]
    kinds = {m["kind"] for m in estimates}
    assert kinds == {"window", "profile", "mu_T", "joint"}
    windows = [m for m in estimates if m["kind"] == "window"]
    joint = [m for m in estimates if m["kind"] == "joint"]
    # the model's weight is right and the bit ends inside casing (mu 0.2): the joint estimate
    # finds both, from hangs, rotation and pick-up
    # (a load pin: the block weight and the sensor's zero show only as their sum, the 400 kN
    # an empty block reads)
    assert joint[-1]["identifiable"]
    verdict = joint[-1]["identifiability"]
    assert verdict.startswith("identifiable; block weight and hook-load offset: only their "
                              "sum is known, an empty block reads ")
    assert 395 <= int(verdict.rsplit(" ", 2)[1]) <= 405
    assert abs(joint[-1]["mu"] - 0.2) < 0.02 and abs(joint[-1]["weight_factor"] - 1.0) < 0.01
    # tripping out from below the shoe: open hole is solved again once cased friction is known
    opened = [m for m in windows if m["section"] == "open" and m["operation"] == "pick_up"]
    cased = [m for m in windows if m["section"] == "cased" and m["operation"] == "pick_up"]
    assert opened and all(m.get("revised") for m in opened)
    assert np.median([m["mu"] for m in opened]) == pytest.approx(0.3, abs=0.01)
    assert np.median([m["mu"] for m in cased]) == pytest.approx(0.2, abs=0.01)
    calibrate = steps[1]
    assert calibrate.block_weight.estimate is not None
    assert calibrate.block_weight.estimate.value == pytest.approx(400e3, rel=0.01)
    # the learnt block weight is the rig-state detector's, the median of the last in-slips
    # hook loads (the tracker's window)
    assert steps[0].thresholds.block_weight == calibrate.block_weight.estimate.value
    assert calibrate.block_weight.estimate.value == np.median(calibrate.block_weight.recent)


def test_friction_rise_raises_a_jump_alarm(model_open: WellModel, trip: Any) -> None:
    first = trip(model_open, np.full(model_open.n_elements, 0.2), start=4200.0, end=3800.0,
                 seed=51)
    second = trip(model_open, np.full(model_open.n_elements, 0.3), start=3800.0, end=3500.0,
                  seed=52, t0=float(first.t[-1]) + 1.0)
    steps = _steps(model_open)
    messages: list[tuple[str, dict[str, Any]]] = []
    for session in (first, second):
        for frame in _frames(session):
            for step in steps:
                step.on_frame(frame, lambda n, m: messages.append((n, m)))
    _check(messages)
    jumps = [m for n, m in messages if n == "alarm" and m["kind"] == "friction_jump"]
    assert jumps and jumps[0]["t"] > first.t[-1]


channel_value = st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True, width=64))


@settings(max_examples=150, deadline=None)
@given(rows=st.lists(st.fixed_dictionaries({
    "hookload": channel_value, "bit_depth": channel_value, "block_position": channel_value,
    "rpm": channel_value, "torque": channel_value, "hole_depth": channel_value,
    "dt": st.floats(min_value=-5.0, max_value=100.0)}), min_size=1, max_size=60))
def test_garbage_frames_never_emit_nan(model_open: WellModel,
                                       rows: list[dict[str, float | None]]) -> None:
    steps = _steps(model_open)
    messages: list[tuple[str, dict[str, Any]]] = []
    t = 1.6e9
    for row in rows:
        t += float(row.pop("dt") or 0.0)
        values = {k: float(v) for k, v in row.items() if v is not None}
        frame = Frame(t=t, log_time_ns=int(t * 1e9), values=values, ages={},
                      stale=("torque",) if "torque" not in values else ())
        for step in steps:
            step.on_frame(frame, lambda n, m: messages.append((n, m)))
    for step in steps:
        step.close(lambda n, m: messages.append((n, m)))
    for name, message in messages:
        json.dumps(message, allow_nan=False)
        if name != "state":  # bit_depth_m may be absent in a garbage frame, never NaN
            _validator(name).validate(message)


def test_profile_anomaly_on_the_contrast() -> None:
    edges = np.arange(0.0, 30.0 * 21, 30.0)
    mu = np.full(20, 0.25)
    mu[10:13] = 0.35
    covariance = np.eye(20) * 0.01**2
    jump = JumpSettings()
    alarm, known = profile_anomaly(1.0, edges, mu, covariance, 0.1, jump)
    assert alarm is not None and alarm.kind == "friction_jump"
    assert "between 300 and 390 m" in alarm.message
    assert alarm.value == pytest.approx(0.35)
    again, _ = profile_anomaly(2.0, edges, mu, covariance, 0.1, jump, known=known)
    assert again is None  # reported once
    # the same bump with bins that trade friction (uncertain contrast) is no alarm
    loose = np.eye(20) * 0.07**2
    assert profile_anomaly(1.0, edges, mu, loose, 0.1, jump)[0] is None
    # untouched bins (prior uncertainty) never count
    assert profile_anomaly(1.0, edges, mu, np.eye(20) * 0.1**2, 0.1, jump)[0] is None


def _anomaly_by_masks(mu: np.ndarray, covariance: np.ndarray, prior_std: float,
                      settings: JumpSettings, width: int, known: frozenset[int]
                      ) -> tuple[float, int, float, float, float] | None:
    """profile_anomaly's search written plainly, one boolean mask per candidate stretch."""
    n = mu.size
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    touched = np.isfinite(mu) & (std < 0.8 * prior_std)
    starts = [k for k in range(n - width + 1) if touched[k:k + width].all()]
    if len(starts) < 3:
        return None
    best = None
    for first in starts:
        rest = touched.copy()
        rest[max(0, first - 1):first + width + 1] = False
        if rest.sum() < width:
            continue
        contrast = np.zeros(n)
        contrast[first:first + width] = 1.0 / width
        contrast[rest] = -1.0 / rest.sum()
        excess = float(contrast @ mu)
        spread = math.sqrt(max(float(contrast @ covariance @ contrast), 0.0))
        limit = max(settings.min_step, settings.sigmas * spread)
        if excess > limit and not (set(range(first, first + width)) & known) and (
                best is None or excess - limit > best[0]):
            best = (excess - limit, first, excess, limit, float(np.mean(mu[rest])))
    return best


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 40), width=st.integers(1, 4),
       untouched=st.floats(0.0, 0.6), known=st.sets(st.integers(0, 39), max_size=6))
def test_profile_anomaly_equals_the_masked_search(seed: int, n: int, width: int,
                                                  untouched: float, known: set[int]) -> None:
    rng = np.random.default_rng(seed)
    mu = 0.25 + 0.05 * rng.standard_normal(n)
    mu[rng.integers(0, n)] += rng.choice([0.0, 0.2])  # sometimes a bump
    factor = rng.standard_normal((n, n)) * 0.01
    covariance = factor @ factor.T / n + np.diag(rng.uniform(1e-5, 2e-3, n))
    wide = rng.random(n) < untouched  # bins the data have not touched: prior uncertainty
    covariance[wide, wide] = 0.1**2
    if rng.random() < 0.2:
        mu[rng.integers(0, n)] = math.nan
    jump = JumpSettings(min_step=float(rng.choice([0.0, 0.05])), sigmas=3.0)
    edges = np.arange(n + 1) * 30.0
    alarm, reported = profile_anomaly(1.0, edges, mu, covariance, 0.1, jump, width=width,
                                      known=frozenset(known))
    best = _anomaly_by_masks(mu, covariance, 0.1, jump, width, frozenset(known))
    if best is None:
        assert alarm is None and reported == frozenset(known)
        return
    _, first, excess, limit, reference = best
    assert alarm is not None
    assert (alarm.value, alarm.limit) == (reference + excess, reference + limit)  # exactly
    assert f"between {edges[first]:.0f} and {edges[first + width]:.0f} m MD" in alarm.message
    assert reported == frozenset(known) | frozenset(range(first, first + width))


def test_weight_check_needs_three_odd_hangs(model_open: WellModel) -> None:
    calibrate = _steps(model_open)[1]
    messages: list[tuple[str, dict[str, Any]]] = []
    static = model_open.evaluate("static", 3500.0, 0.0)[0]
    for k, factor in enumerate((1.0, 0.85, 0.85, 1.0, 0.85, 0.85, 0.85, 0.85)):
        window = Window("static", 10.0 * k, 10.0 * k + 5, 5, 3500.0, 3500.0, 3500.0,
                        400e3 + factor * (static - 400e3), 3e3)
        calibrate.on_window(window, lambda n, m: messages.append((n, m)))
    checks = [m for n, m in messages if n == "alarm" and m["kind"] == "weight_check"]
    assert len(checks) == 1 and checks[0]["t"] == 65.0
    lighter = 0.15 * (static - 400e3) / 1e3
    assert f"{lighter:.0f} kN (15.0 %) lighter" in checks[0]["message"]
    assert "density" not in checks[0]["message"]  # kN and %, never a density
    assert calibrate.weight_checks[0].ratio == pytest.approx(1.0)


def test_a_gap_is_one_stale_alarm_and_its_channels_are_not_named_again() -> None:
    s = SensorSettings()
    state = SensorState()
    # the whole stream silent from 19 s (stale from 24 s) to 65 s; torque does not come back
    gap = (("hookload", 24.0), ("bit_depth", 24.0), ("torque", 23.5))
    state, alarms = sensor_alarms(state, 65.0, {"hookload": 1e6, "bit_depth": 3000.0},
                                  ("torque",), (), s, gap)
    [alarm] = alarms
    assert (alarm.t, alarm.value) == (23.5, 41.5)
    assert alarm.message == ("3 channels went stale together, for 42 s until data resumed: "
                             "hookload, bit_depth, torque")
    state, alarms = sensor_alarms(state, 66.0, {"hookload": 1e6}, ("torque",), (), s)
    assert alarms == []
    # torque heard from again, then stale again later: a new event, a new alarm
    state, alarms = sensor_alarms(state, 67.0, {"hookload": 1e6, "torque": 5e3}, (), (), s)
    state, alarms = sensor_alarms(state, 80.0, {"hookload": 1e6}, ("torque",), (), s)
    assert [a.message for a in alarms] == ["channel torque is stale"]
    # the hook load alone
    _, [alone] = sensor_alarms(SensorState(), 40.0, {"hookload": 1e6}, (), (), s,
                               (("hookload", 30.0),))
    assert alone.message == "channel hookload went stale, for 10 s until it resumed"


def test_sensor_state_init_is_the_dataclass_one() -> None:
    # the hand-written __init__ (its signature: tests/test_hand_written_inits.py): frozen,
    # compared, copied and pickled like the dataclass
    import dataclasses
    import pickle

    state = SensorState(frozenset({"torque"}), active=frozenset({AlarmKind.SENSOR_RPM_FROZEN}),
                        below_since=3.0)
    assert (state.stale, state.announced, state.active, state.below_since) == (
        frozenset({"torque"}), frozenset(), frozenset({"sensor_rpm_frozen"}), 3.0)
    assert state == replace(state) and hash(state) == hash(replace(state))
    assert pickle.loads(pickle.dumps(state)) == state
    with pytest.raises(dataclasses.FrozenInstanceError):
        state.below_since = 1.0  # type: ignore[misc]
