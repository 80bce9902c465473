"""The simulated hook-load channel as a rig's sensor reads it: sheave friction of a deadline
sensor with the block's motion, a drifting zero offset, and a torque zero offset."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tdmon.errors import ConfigError
from tdmon.model.hookload_sensor import dead_line_factor
from tdmon.replay.scenario import load_scenario_model
from tdmon.replay.session import simulate_session

DEADLINE = """
[sensor]
location = "deadline"
lines = 10
efficiency = 0.98
offset_start = "5 kN"
offset_end = "25 kN"
"""


def test_deadline_sensor_reads_low_hoisting_high_lowering_with_offset(
        write_scenario: Callable[..., Path]) -> None:
    session = simulate_session(load_scenario_model(write_scenario(extra=DEADLINE)))
    truth = session.truth
    duration = session.timeline.duration
    offset = 5e3 + (session.truth_t - session.scenario.start) / duration * 20e3
    up, down = dead_line_factor(10, 0.98, 1), dead_line_factor(10, 0.98, -1)
    state = truth["state"]
    motion = truth["block_motion"]
    load = np.asarray(truth["hookload"])
    reading = np.asarray(truth["hookload_reading"])
    np.testing.assert_allclose(truth["hookload_offset"], offset, rtol=1e-12)
    # pulling the string hoists the block, running it lowers it, a hang keeps it still
    assert set(motion[state == "pick_up"]) == {1}
    assert set(motion[state == "slack_off"]) == {-1}
    assert set(motion[np.isin(state, ["static", "rotating_off_bottom"])]) == {0}
    for direction, factor in ((1, up), (-1, down), (0, 1.0)):
        where = motion == direction
        np.testing.assert_allclose(reading[where], factor * load[where] + offset[where],
                                   rtol=1e-12)
    # the empty block moves in slips too: read with its own motion's factor
    slips = state == "in_slips"
    assert set(motion[slips]) >= {1, -1}
    # what the rig sends (no noise in this scenario) is the reading at the sensor's times
    series = session.channels["hookload"]
    np.testing.assert_array_equal(series.value, series.true_value)
    sent = np.interp(session.truth_t, series.t, series.value)
    assert np.max(np.abs(sent - reading)) < 1e-6 * np.max(reading)


def test_no_sensor_table_reads_the_load_on_the_hook(write_scenario: Callable[..., Path]) -> None:
    session = simulate_session(load_scenario_model(write_scenario()))
    assert "hookload_reading" not in session.truth
    series = session.channels["hookload"]
    sent = np.interp(session.truth_t, series.t, series.value)
    np.testing.assert_allclose(sent, session.truth["hookload"], rtol=1e-12)


def test_torque_zero_offset(write_scenario: Callable[..., Path]) -> None:
    extra = '[noise.channels.torque]\noffset = "0.8 kN m"\n'
    session = simulate_session(load_scenario_model(write_scenario(extra=extra)))
    series = session.channels["torque"]
    np.testing.assert_allclose(series.value - series.true_value, 800.0, atol=1e-9)


@pytest.mark.parametrize(("table", "key"), [
    ('[sensor]\nlocation = "deadline"\nabove_sensor = "10 kN"\n', "sensor"),
    ('[sensor]\nlocation = "crown"\n', "sensor.location"),
    ('[sensor]\nefficiency = 1.2\n', "sensor.efficiency"),
    ('[noise]\noffset = 3\n', "noise.offset"),
])
def test_bad_sensor_tables_name_their_key(write_scenario: Callable[..., Path], table: str,
                                          key: str) -> None:
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        load_scenario_model(write_scenario(extra=table))
