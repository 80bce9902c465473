"""The pure session generator: timeline, loads against the model, truth, noise and faults."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tdmon.config.well import load_well
from tdmon.errors import ModelError
from tdmon.model.friction import KAARSTAD_2009
from tdmon.model.torque_drag import WellModel
from tdmon.replay.scenario import load_scenario_model
from tdmon.replay.session import (
    STATES,
    NoiseSettings,
    Phase,
    Scenario,
    SensorFault,
    Session,
    TightSpot,
    build_timeline,
    simulate_session,
)

from .conftest import SCENARIO_WELL


@pytest.fixture
def scenario(write_scenario: Callable[..., Path]) -> Scenario:
    return load_scenario_model(write_scenario())


@pytest.fixture
def session(scenario: Scenario) -> Session:
    return simulate_session(scenario)


def _with_noise(scenario: Scenario, channel: str = "hookload", **settings: float) -> Scenario:
    noise = dict(scenario.noise)
    noise[channel] = NoiseSettings(**settings)
    return dataclasses.replace(scenario, noise=noise)


def test_every_state_and_the_block_travel(session: Session) -> None:
    timeline = session.timeline
    assert set(timeline.state) == set(STATES)
    # the block never leaves its travel; in slips the bit does not move
    low, high = 2.0, 30.0
    assert timeline.block0.min() >= low - 1e-9 and timeline.block1.max() <= high + 1e-9
    slips = np.array([s == "in_slips" for s in timeline.state])
    assert np.allclose(timeline.bit0[slips], timeline.bit1[slips])
    # latched, the block moves opposite to the bit, by the same distance
    latched = ~slips
    assert np.allclose((timeline.block1 - timeline.block0)[latched],
                       -(timeline.bit1 - timeline.bit0)[latched])
    # the hole deepens only while drilling, with the bit on bottom
    for i, state in enumerate(timeline.state):
        if state == "drilling":
            assert timeline.hole0[i] == timeline.bit0[i] and timeline.hole1[i] == timeline.bit1[i]
        else:
            assert timeline.hole0[i] == timeline.hole1[i]
    assert [s for _, s in session.state_changes][:4] == [
        "static", "circulating", "rotating_off_bottom", "reaming"]


def test_zero_noise_loads_are_the_model(session: Session, scenario: Scenario) -> None:
    """Hand check of every state against WellModel.evaluate with the true profile."""
    model = WellModel(scenario.well)
    mu = session.profile_mu
    truth = session.truth
    seen = set()
    for k in range(0, session.truth_t.size, 7):
        state = str(truth["state"][k])
        bit = float(truth["bit_depth"][k])
        hookload, torque = float(truth["hookload"][k]), float(truth["torque"][k])
        if state == "in_slips":
            expected = (scenario.well.block_weight, 0.0)
        elif state == "pick_up":
            expected = model.evaluate("pick_up", bit, mu)
        elif state == "slack_off":
            expected = model.evaluate("slack_off", bit, mu)
        elif state == "rotating_off_bottom":
            expected = model.evaluate("rotating", bit, mu)
        elif state in ("static", "circulating"):
            expected = model.evaluate("static", bit, mu)
        elif state == "drilling":
            expected = model.evaluate("on_bottom", bit, mu, wob=80e3, bit_torque=80e3 * 0.02)
        else:
            continue  # reaming: combined motion, checked below
        seen.add(state)
        assert hookload == pytest.approx(expected[0], rel=1e-12)
        assert torque == pytest.approx(expected[1], rel=1e-12, abs=1e-9)
    assert seen == set(STATES) - {"reaming", "back_reaming"}
    # sent values equal the truth when there is no noise
    for series in session.channels.values():
        np.testing.assert_array_equal(series.value, series.true_value)


def test_reaming_uses_the_combined_motion_angle(session: Session, scenario: Scenario) -> None:
    model = WellModel(scenario.well)
    truth = session.truth
    k = int(np.flatnonzero(truth["state"] == "back_reaming")[3])
    bit = float(truth["bit_depth"][k])
    # back-reaming at 0.2 m/s and 60 rpm, pipe radius 0.08 m: psi = atan(v / (omega r))
    psi = math.atan2(0.2, 60 * 2 * math.pi / 60 * 0.08)
    expected = model.evaluate("pick_up", bit, session.profile_mu, psi=psi)
    assert truth["hookload"][k] == pytest.approx(expected[0], rel=1e-12)
    assert truth["torque"][k] == pytest.approx(expected[1], rel=1e-12)
    # pulling while rotating needs less than a pure pull, more than hanging
    assert model.evaluate("static", bit, session.profile_mu)[0] < truth["hookload"][k] \
        < model.evaluate("pick_up", bit, session.profile_mu)[0]


def test_friction_follows_temperature(scenario: Scenario) -> None:
    """Open-hole elements carry Kaarstad's Glydril law at the Apak annulus temperature."""
    config = load_well(SCENARIO_WELL)
    well = config.to_model(SCENARIO_WELL)
    model = WellModel(well)
    open_hole = model.grid.element_section == 1
    assert scenario.temperature is not None
    expected = KAARSTAD_2009["glydril"](scenario.temperature[open_hole])
    np.testing.assert_allclose(scenario.friction[open_hole], expected, rtol=1e-12)
    # the well file's own adapter gives the same profile (circulating mud)
    np.testing.assert_allclose(scenario.friction, config.element_friction(well), rtol=1e-9)
    # circulating mud is warmest some way above TD (Kabir et al.): friction peaks there too
    peak = int(np.argmax(scenario.temperature))
    assert int(np.argmax(scenario.friction)) == peak < scenario.temperature.size - 1


def test_geothermal_mud_is_hotter_at_depth(write_scenario: Callable[..., Path]) -> None:
    circulating = load_scenario_model(write_scenario())
    resting = load_scenario_model(write_scenario(
        friction='[friction]\ntemperature_model = "geothermal"'))
    assert circulating.temperature is not None and resting.temperature is not None
    # Table 10: geotherm 85.5 C at 3033 m TVD, circulating annulus ~57.7 C
    assert resting.temperature[-1] == pytest.approx(85.5, abs=0.5)
    assert circulating.temperature[-1] == pytest.approx(57.7, abs=1.0)
    assert resting.friction[-1] > circulating.friction[-1]
    assert resting.mud_temp_in == pytest.approx(resting.mud_temp_out)


def test_anomaly_and_effective_friction(write_scenario: Callable[..., Path]) -> None:
    scenario = load_scenario_model(write_scenario(
        friction='[[friction.anomaly]]\ntop = "3500 m"\nbottom = "3600 m"\ndelta_mu = 0.1'))
    session = simulate_session(scenario)
    md = session.profile_md
    inside = (md >= 3500) & (md <= 3600)
    assert inside.sum() == 10
    np.testing.assert_allclose(session.profile_mu[inside] - scenario.friction[inside], 0.1)
    np.testing.assert_array_equal(session.profile_mu[~inside], scenario.friction[~inside])
    # the uniform mu reported as truth reproduces the true pick-up load and rotating torque
    model = WellModel(scenario.well)
    truth = session.truth
    k = int(np.flatnonzero(truth["state"] == "pick_up")[2])
    bit = float(truth["bit_depth"][k])
    true_pick_up = model.evaluate("pick_up", bit, session.profile_mu)[0]
    assert model.evaluate("pick_up", bit, float(truth["mu_pick_up"][k]))[0] == \
        pytest.approx(true_pick_up, rel=1e-9)
    true_torque = model.evaluate("rotating", bit, session.profile_mu)[1]
    assert model.evaluate("rotating", bit, float(truth["mu_rotating"][k]))[1] == \
        pytest.approx(true_torque, rel=1e-9)
    assert truth["mu_slack_off"][k] < truth["mu_mean"][k] + 0.05
    assert math.isnan(float(truth["mu_pick_up"][np.flatnonzero(truth["state"] == "in_slips")[0]]))
    assert [a.kind for a in session.alarms] == ["friction_anomaly"]


def test_tight_spot_overpull_and_set_down(scenario: Scenario) -> None:
    spots = (TightSpot(md=4110.0, length=5.0, force=150e3),)
    session = simulate_session(dataclasses.replace(scenario, tight_spots=spots))
    plain = simulate_session(scenario)
    extra = np.asarray(session.truth["hookload"], dtype=float) - np.asarray(
        plain.truth["hookload"], dtype=float)
    bit = np.asarray(session.truth["bit_depth"], dtype=float)
    state = session.truth["state"]
    inside = (bit >= 4110.0) & (bit <= 4115.0)
    assert np.allclose(extra[inside & (state == "pick_up")], 150e3)
    assert np.allclose(extra[inside & (state == "slack_off")], -150e3)
    assert np.all(extra[~inside] == 0.0)
    kinds = {alarm.kind: alarm for alarm in session.alarms}
    assert set(kinds) == {"overpull", "set_down"}
    assert kinds["overpull"].md == 4110.0
    assert kinds["overpull"].accept == ("friction_jump", "band")
    first = session.truth_t[np.flatnonzero(inside & np.isin(state, ["pick_up", "back_reaming"]))[0]]
    assert kinds["overpull"].t == first


def test_counts_follow_the_sampling(session: Session, scenario: Scenario) -> None:
    duration = session.timeline.duration
    for name, series in session.channels.items():
        interval = scenario.sample_interval[name]
        assert series.t.size == math.ceil(duration / interval - 1e-9)
        # no jitter: stamps on the grid, arrival after the rig's latency
        np.testing.assert_allclose(series.t - scenario.start,
                                   np.arange(series.t.size) * interval, atol=1e-9)
        np.testing.assert_allclose(series.receive_time - series.t, scenario.rig.latency, atol=1e-6)
    assert set(session.channels) == {"hookload", "torque", "bit_depth", "hole_depth",
                                     "block_position", "rpm", "flow_in", "spp", "wob",
                                     "mud_temp_in", "mud_temp_out"}


def test_same_seed_same_session_other_seed_other_noise(scenario: Scenario) -> None:
    noisy = _with_noise(scenario, relative=0.01, clock_jitter=0.3, spike_rate=0.02,
                        missing_rate=0.05)
    first, again = simulate_session(noisy), simulate_session(noisy)
    other = simulate_session(dataclasses.replace(noisy, seed=noisy.seed + 1))
    for name in first.channels:
        np.testing.assert_array_equal(first.channels[name].value, again.channels[name].value)
        np.testing.assert_array_equal(first.channels[name].t, again.channels[name].t)
    assert not np.array_equal(first.channels["hookload"].value, other.channels["hookload"].value)
    # noise on one channel leaves the others untouched (a random stream per channel)
    np.testing.assert_array_equal(first.channels["torque"].value,
                                  simulate_session(scenario).channels["torque"].value)


def test_relative_noise_has_its_size(scenario: Scenario) -> None:
    session = simulate_session(_with_noise(scenario, relative=0.01))
    series = session.channels["hookload"]
    ratio = series.value / series.true_value - 1.0
    # 390 samples: the sample standard deviation is within ~10 % of 0.01 (5 sigma ~ 18 %)
    assert np.std(ratio) == pytest.approx(0.01, rel=0.18)
    assert abs(np.mean(ratio)) < 0.01 * 5 / math.sqrt(ratio.size)


def test_spikes_are_counted_and_sized(scenario: Scenario) -> None:
    session = simulate_session(_with_noise(scenario, spike_rate=0.05, spike_size=0.3))
    series = session.channels["hookload"]
    spiked = np.flatnonzero(series.value != series.true_value)
    spikes = [f for f in session.faults if f.kind == "spike"]
    assert len(spikes) == spiked.size > 5
    scale = 0.3 * np.max(np.abs(series.true_value))
    np.testing.assert_allclose(np.abs(series.value[spiked] - series.true_value[spiked]), scale)
    np.testing.assert_allclose([f.t for f in spikes], series.t[spiked])


def test_missing_samples_are_never_sent(scenario: Scenario) -> None:
    full = simulate_session(scenario).channels["hookload"]
    series = simulate_session(_with_noise(scenario, missing_rate=0.1)).channels["hookload"]
    lost = full.t.size - series.t.size
    # binomial(390, 0.1): mean 39, sd 5.9
    assert 15 < lost < 65
    assert set(series.t).issubset(set(full.t))


def test_dropout_leaves_a_gap(scenario: Scenario) -> None:
    fault = SensorFault("dropout", ("hookload", "torque"), start=200.0, duration=60.0)
    session = simulate_session(dataclasses.replace(scenario, faults=(fault,)))
    for name in ("hookload", "torque"):
        t = session.channels[name].t - scenario.start
        assert not np.any((t >= 200.0) & (t < 260.0))
        assert np.max(np.diff(t)) >= 60.0
    assert session.channels["bit_depth"].t.size == simulate_session(
        scenario).channels["bit_depth"].t.size
    assert [(a.kind, a.accept) for a in session.alarms] == [("data_gap", ("sensor_stale",))]
    assert {(f.kind, f.channel) for f in session.faults} == {("dropout", "hookload"),
                                                            ("dropout", "torque")}


def test_stuck_sensor_repeats_its_last_value(scenario: Scenario) -> None:
    noisy = _with_noise(scenario, "torque", relative=0.01)
    fault = SensorFault("stuck", ("torque",), start=470.0, duration=120.0)
    session = simulate_session(dataclasses.replace(noisy, faults=(fault,)))
    series = session.channels["torque"]
    t = series.t - scenario.start
    inside = (t >= 470.0) & (t < 590.0)
    assert inside.sum() == 60
    before = series.value[np.flatnonzero(inside)[0] - 1]
    assert np.all(series.value[inside] == before)
    # the true torque changes during the window (drilling, then back-reaming)
    assert np.ptp(series.true_value[inside]) > 1e3
    assert len(set(series.value[~inside])) > 100
    alarm = session.alarms[0]
    assert (alarm.kind, alarm.channel, alarm.t) == ("stuck_sensor", "torque",
                                                   scenario.start + 470.0)
    assert alarm.accept == ("sensor_torque_frozen",)


def test_clock_jitter_moves_stamps_not_order(scenario: Scenario) -> None:
    session = simulate_session(_with_noise(scenario, clock_jitter=0.5))
    series = session.channels["hookload"]
    error = series.t - (series.receive_time - scenario.rig.latency)
    assert 0.3 < np.std(error) < 0.6
    assert np.max(np.abs(error)) <= 0.45 * 2.0 + 1e-6
    assert np.all(np.diff(series.t) > 0)


def test_impossible_phases_are_errors(scenario: Scenario) -> None:
    with pytest.raises(ModelError, match="must be below the bit"):
        build_timeline(dataclasses.replace(scenario, phases=(
            Phase("trip_in", to=4000.0, speed=0.5),)))
    with pytest.raises(ModelError, match="on bottom"):
        build_timeline(dataclasses.replace(scenario, phases=(
            Phase("drill", to=4160.0, speed=0.01, wob=1e5, rpm=10.0),)))
    with pytest.raises(ModelError, match="below the hole depth"):
        build_timeline(dataclasses.replace(scenario, phases=(
            Phase("trip_in", to=4200.0, speed=0.5),)))
    with pytest.raises(ModelError, match="outside its travel"):
        build_timeline(dataclasses.replace(scenario, block_position=40.0))
    with pytest.raises(ModelError, match="below the hole depth 4150"):
        build_timeline(dataclasses.replace(scenario, bit_depth=4160.0))
    with pytest.raises(ModelError, match="no travel"):
        build_timeline(dataclasses.replace(
            scenario, block_position=0.5, rig=dataclasses.replace(
                scenario.rig, stand_length=0.5, block_low=0.0)))
    deep = dataclasses.replace(scenario, hole_depth=4300.0, phases=(
        Phase("trip_in", to=4300.0, speed=0.5),))
    with pytest.raises(ModelError, match="deeper than the drill string"):
        simulate_session(deep)


def test_break_over_peak_at_the_start_of_a_pull_from_rest(scenario: Scenario) -> None:
    rig = dataclasses.replace(scenario.rig, break_over=50e3, break_over_time=3.0)
    session = simulate_session(dataclasses.replace(scenario, rig=rig))
    plain = simulate_session(scenario)
    extra = np.asarray(session.truth["hookload"], dtype=float) - np.asarray(
        plain.truth["hookload"], dtype=float)
    timeline = session.timeline
    expected = np.zeros_like(extra)
    tau = session.truth_t - scenario.start
    for i, state in enumerate(timeline.state):
        # back-reaming after drilling and the pull after a connection start from rest; the
        # pull that follows back-reaming does not
        if state in ("pick_up", "back_reaming") and timeline.state[i - 1] not in (
                "pick_up", "back_reaming"):
            inside = (tau >= timeline.t0[i]) & (tau < timeline.t1[i])
            expected[inside] = 50e3 * np.exp(-(tau[inside] - timeline.t0[i]) / 3.0)
    np.testing.assert_allclose(extra, expected, atol=1e-6)
    assert np.count_nonzero(expected > 49e3) == 2
    # the friction truth is the model's, without the peak
    np.testing.assert_array_equal(session.truth["mu_pick_up"], plain.truth["mu_pick_up"])
