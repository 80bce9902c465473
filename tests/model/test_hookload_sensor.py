"""The hook-load measurement model against the block-efficiency table after API RP 9B and
against a line-by-line tension balance solved independently."""

from __future__ import annotations

import numpy as np
import pytest

from tdmon.errors import ModelError
from tdmon.model.hookload_sensor import (
    API_SHEAVE_FACTOR,
    HookloadSensor,
    SensorLocation,
    dead_line_factor,
    fast_line_factor,
)

# Shell Well Engineers' Notebook, table B-1 (after API RP 9B), sheave factor 1.04: dead-line
# and fast-line load per even line share W/N for 2, 4, ..., 12 lines, to the table's 3 digits.
LINES = (2, 4, 6, 8, 10, 12)
DEAD_LINE = (0.980, 0.942, 0.905, 0.868, 0.833, 0.799)
FAST_LINE = (1.060, 1.102, 1.145, 1.188, 1.233, 1.279)
EFFICIENCY = 1.0 / API_SHEAVE_FACTOR


@pytest.mark.parametrize(("lines", "dead", "fast"), list(zip(LINES, DEAD_LINE, FAST_LINE,
                                                              strict=True)))
def test_api_rp_9b_factors(lines: int, dead: float, fast: float) -> None:
    assert dead_line_factor(lines, EFFICIENCY, +1) == pytest.approx(dead, abs=5e-4)
    assert fast_line_factor(lines, EFFICIENCY) == pytest.approx(fast, abs=5e-4)


def _line_balance(lines: int, k: float, hoisting: bool) -> np.ndarray:
    """Line tensions from a linear system written line by line: each sheave the moving rope
    passes multiplies the tension by 1/k (hoisting: the rope runs from the fast line towards
    the dead line through the sheaves) or by k (lowering), and the lines carry a unit load."""
    n = lines + 1  # fast line, then lines 1..N (line N is the dead line's tension)
    a = np.zeros((n, n))
    b = np.zeros(n)
    ratio = 1.0 / k if hoisting else k
    for i in range(1, n):  # T_i - ratio T_(i-1) = 0
        a[i - 1, i] = 1.0
        a[i - 1, i - 1] = -ratio
    a[n - 1, 1:] = 1.0  # the N lines hold the load
    b[n - 1] = 1.0
    return np.linalg.solve(a, b)


@pytest.mark.parametrize("lines", [2, 6, 10, 14])
@pytest.mark.parametrize("k", [1.02, 1.04, 1.06])
def test_factors_equal_an_independent_line_balance(lines: int, k: float) -> None:
    up = _line_balance(lines, k, hoisting=True)
    down = _line_balance(lines, k, hoisting=False)
    assert dead_line_factor(lines, 1 / k, +1) == pytest.approx(lines * up[-1], rel=1e-12)
    assert dead_line_factor(lines, 1 / k, -1) == pytest.approx(lines * down[-1], rel=1e-12)
    assert fast_line_factor(lines, 1 / k) == pytest.approx(lines * up[0], rel=1e-12)


def test_ten_lines_read_17_percent_low_hoisting_and_19_high_lowering() -> None:
    assert dead_line_factor(10, EFFICIENCY, +1) == pytest.approx(0.833, abs=1e-3)
    assert dead_line_factor(10, EFFICIENCY, -1) == pytest.approx(1.186, abs=1e-3)
    assert dead_line_factor(10, EFFICIENCY, 0) == 1.0
    assert dead_line_factor(10, 1.0, +1) == 1.0


def test_sensor_reading_round_trips_and_scalars_match_arrays() -> None:
    sensor = HookloadSensor(SensorLocation.DEADLINE, lines=10, efficiency=0.98)
    loads = np.array([300e3, 800e3, 1500e3])
    for motion in (-1, 0, 1):
        read = sensor.reading(loads, motion, acceleration=0.3)
        assert np.allclose(sensor.hook_load(read, motion, acceleration=0.3), loads, rtol=1e-13)
        assert read[1] == pytest.approx(float(sensor.reading(800e3, motion, 0.3)), rel=1e-15)
    # inertia: (W / g) a on top of the load, before the sheave factor
    assert float(sensor.reading(1e6, 0, acceleration=9.80665)) == pytest.approx(2e6)
    pin = HookloadSensor(SensorLocation.TOP_DRIVE, above_sensor=150e3)
    assert float(pin.reading(1e6, +1)) == pytest.approx(850e3)
    assert not pin.reads_sheave_friction and sensor.reads_sheave_friction


def test_bad_rigging_is_refused() -> None:
    with pytest.raises(ModelError, match="lines"):
        HookloadSensor(SensorLocation.DEADLINE, lines=0)
    with pytest.raises(ModelError, match="efficiency"):
        HookloadSensor(SensorLocation.DEADLINE, efficiency=1.2)
    with pytest.raises(ModelError, match="deadline"):
        HookloadSensor(SensorLocation.DEADLINE, above_sensor=10e3)
    with pytest.raises(ValueError):
        HookloadSensor("crown")
