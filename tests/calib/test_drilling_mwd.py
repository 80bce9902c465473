"""The MWD's weight on bit and torque at the bit in the drilling windows (issue 29): a window
takes the MWD's means when every kept sample has them, says whose values it carries, and the
joint estimate's hook-load balance then sees a drifted hook-load offset that the surface weight
on bit (itself read off the hook load) hides, and the estimator keeps the MWD's bit torque."""

from __future__ import annotations

import math

import jsonschema
import numpy as np
import pytest

from tdmon.calib.estimator import FrictionEstimator, Output, _mwd_sources
from tdmon.calib.joint import JointSettings, _linearise, drilling_measurements
from tdmon.calib.rigstate import Detection, RigSample
from tdmon.calib.windows import Window, WindowSettings, summarise
from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.rig_state import rig_sample
from tdmon.model.torque_drag import Operation, WellModel
from tdmon.record.schemas import ESTIMATE
from tdmon.vocabulary import RigState

DEPTH = 3000.0
TRUE_WOB = 80e3  # what the bit carries [N]
OFFSET = 20e3  # the hook-load sensor's offset, drifted since the driller zeroed the WOB [N]


def _samples(hookload: float, *, mwd: bool = True, missing_at: int | None = None
             ) -> tuple[RigSample, ...]:
    # ten drilling samples 5 s apart: the MWD reads the bit's weight and 2.4-2.6 kN m, the
    # rig's surface WOB is the driller's (off-bottom load less load now, zeroed before the
    # offset drifted): the true weight less the offset
    rng = np.random.default_rng(29)
    out = []
    for k in range(10):
        mwd_here = mwd and k != missing_at
        out.append(RigSample(
            5.0 * k, hookload + 1e3 * rng.standard_normal(), DEPTH + 0.01 * k, rpm=12.0,
            torque=18e3 + 50.0 * k, wob=TRUE_WOB - OFFSET,
            downhole_wob=TRUE_WOB + 500.0 * (k - 4.5) if mwd_here else None,
            downhole_torque=2.5e3 + 20.0 * (k - 4.5) if mwd_here else None))
    return tuple(out)


def _window(samples: tuple[RigSample, ...]) -> Window | None:
    return summarise(RigState.DRILLING, samples, (0.0,) * len(samples), WindowSettings())


def test_a_frame_s_mwd_channels_reach_the_rig_sample() -> None:
    frame = Frame(10.0, 10_000_000_000, {"hookload": 1.0e6, "bit_depth": DEPTH, "wob": 60e3,
                         "downhole_wob": 78e3, "downhole_torque": math.nan}, {})
    sample = rig_sample(frame)
    assert (sample.wob, sample.downhole_wob, sample.downhole_torque) == (60e3, 78e3, None)
    assert rig_sample(Frame(10.0, 10_000_000_000, {"hookload": 1.0e6}, {})).downhole_wob is None


def test_a_drilling_window_takes_the_mwd_means_when_every_sample_has_them() -> None:
    window = _window(_samples(1.0e6))
    assert window is not None
    assert (window.wob, window.wob_source) == (pytest.approx(TRUE_WOB), "downhole")
    assert (window.bit_torque, window.bit_torque_source) == (pytest.approx(2.5e3), "downhole")
    assert _mwd_sources(window) == {"wob_source": "downhole", "bit_torque_source": "downhole"}
    # one sample without the MWD: the surface weight on bit, and no bit torque yet (the
    # estimator's tag step fills it)
    gap = _window(_samples(1.0e6, missing_at=3))
    assert gap is not None
    assert (gap.wob, gap.wob_source) == (pytest.approx(TRUE_WOB - OFFSET), "surface")
    assert (gap.bit_torque, gap.bit_torque_source) == (None, None)
    assert _mwd_sources(gap) == {}
    # another state carries neither
    rotating = summarise(RigState.ROTATING_OFF_BOTTOM, _samples(1.0e6), (0.0,) * 10,
                         WindowSettings())
    assert rotating is not None
    assert (rotating.wob, rotating.wob_source, rotating.bit_torque) == (None, None, None)


def test_the_mwd_weight_shows_the_hook_load_offset_the_surface_weight_hides(
        model_open: WellModel) -> None:
    # the sensor reads block + F_0 - W + offset (weight factor 1, no sheave term at the
    # deadline); the joint balance at offset 0 predicts block + F_0 - W_window
    block = model_open.well.block_weight
    f0 = model_open.evaluate(Operation.ROTATING, DEPTH, 0.25)[0] - block
    reading = block + f0 - TRUE_WOB + OFFSET
    residuals = {}
    for name, mwd in (("downhole", True), ("surface", False)):
        window = _window(_samples(reading, mwd=mwd))
        assert window is not None and window.wob_source == name
        hookload = drilling_measurements(window)[0]
        assert hookload.wob == window.wob
        linear = _linearise(model_open, hookload, window.bit_depth, block, 0.0,
                            JointSettings(), "soft-string")
        residuals[name] = hookload.value - float(linear(np.array([0.25, 1.0])).predicted)
    # with the MWD's weight the residual is the offset (the joint estimate learns it); the
    # surface weight carries the same offset and cancels it
    assert residuals["downhole"] == pytest.approx(OFFSET, abs=1.5e3)
    assert residuals["surface"] == pytest.approx(0.0, abs=1.5e3)


def test_the_estimator_keeps_the_mwd_torque_and_names_the_sources(
        model_open: WellModel) -> None:
    # a minute drilling at 3000 m, friction 0.25, 80 kN and 2.5 kN m at the bit, no tag seen:
    # the MWD's torque at the bit gives the window its friction; without it nothing does
    mu, bit_torque = 0.25, 2.5e3
    load, torque = model_open.evaluate(Operation.ON_BOTTOM, DEPTH, mu, wob=TRUE_WOB,
                                       bit_torque=bit_torque)
    drilling = Detection(RigState.DRILLING, True, 0.005)
    messages = {}
    for name, mwd in (("downhole", True), ("none", False)):
        estimator = FrictionEstimator(model_open)
        state = estimator.initial_state()
        outputs: list[Output] = []
        for k in range(12):
            wiggle = 1.0 if k % 2 else -1.0
            sample = RigSample(5.0 * k, load + 300.0 * wiggle, DEPTH + 0.005 * k, rpm=12.0,
                               torque=torque + 30.0 * wiggle, wob=TRUE_WOB - OFFSET,
                               downhole_wob=TRUE_WOB if mwd else None,
                               downhole_torque=bit_torque if mwd else None)
            state, more = estimator.add_sample(state, sample, drilling)
            outputs += more
        state, more = estimator.close(state)
        outputs += more
        messages[name] = [m for topic, m in outputs
                          if topic == "estimate" and m["operation"] == "drilling"]
    [window] = messages["downhole"]
    assert (window["wob_N"], window["bit_torque_Nm"]) == (TRUE_WOB, bit_torque)
    assert (window["wob_source"], window["bit_torque_source"]) == ("downhole", "downhole")
    assert window["mu"] == pytest.approx(mu, abs=0.005)
    jsonschema.validate(window, ESTIMATE)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**window, "wob_source": "mwd"}, ESTIMATE)
    assert messages["none"] == []  # no bit torque: no friction from the drilling torque
