"""The torque evidence of rotation (tdmon.calib.rotation): bounded work per frame, and no
exception or NaN from torques near the float limit."""

import math

from tdmon.calib.rotation import RECENT_SAMPLES, TorqueZero, torque_turning

ARGS = dict(average=5.0, floor=500.0, sigmas=4.0, fraction=0.2)


def test_level_averages_the_window_and_a_still_string_learns_its_offset():
    zero = TorqueZero()
    for i in range(10):  # 10 s still at 100 N m, 1 Hz
        zero = torque_turning(zero, 100.0 + (i % 2), float(i), True, **ARGS)
    assert zero.offset == 100.5 and not zero.turning
    for i in range(10, 16):  # turning at 5 kN m
        zero = torque_turning(zero, 5000.0, float(i), False, **ARGS)
    assert zero.turning
    assert len(zero.recent) == 5  # the samples of the last 5 s
    assert math.isclose(sum(v for _, v in zero.recent) / 5, 5000.0)


def test_a_backlog_microseconds_apart_keeps_the_window_bounded():
    zero = TorqueZero()
    for i in range(3 * RECENT_SAMPLES):
        zero = torque_turning(zero, 2000.0 + i, i * 1e-5, False, **ARGS)
    assert len(zero.recent) == RECENT_SAMPLES
    assert zero.recent[-1] == ((3 * RECENT_SAMPLES - 1) * 1e-5, 2000.0 + 3 * RECENT_SAMPLES - 1)
    assert zero.recent[0][1] == 2000.0 + 2 * RECENT_SAMPLES  # the latest ones kept


def test_torques_near_the_float_limit_give_an_infinite_level_not_an_error():
    zero = TorqueZero()
    for i, torque in enumerate([9e307, 9e307, -9e307, 9e307]):
        zero = torque_turning(zero, torque, float(i), False, **ARGS)
        assert not math.isnan(zero.peak)
    assert zero.peak == math.inf  # and nothing raised: the frame goes on
