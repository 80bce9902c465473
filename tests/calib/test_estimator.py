"""The pure friction estimator on synthetic windows whose truth is known (made by the model)."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from tdmon.calib.blockweight import BlockWeightWindow, add_block_weight, block_weight_from_samples
from tdmon.calib.cased import CasedFriction, add_cased
from tdmon.calib.estimator import CalibrationSettings, FrictionEstimator, Output
from tdmon.calib.rigstate import Detection, RigSample
from tdmon.calib.windows import Window, WindowSettings
from tdmon.model.torque_drag import WellModel

SE = 1e3  # standard error of a window's mean hook load [N]


def _window(model: WellModel, state: str, depth: float, mu: Any, t: float,
            factor: float = 1.0) -> Window:
    """A window whose hook load is the model's at ``mu``; ``factor`` scales the string weight
    (hook load less block weight)."""
    operation = "static" if state == "static" else state
    hookload = model.evaluate(operation, depth, mu)[0]
    block = model.well.block_weight
    return Window(state, t, t + 10.0, 10, depth, depth, depth,
                  block + factor * (hookload - block), SE)


def _of(outputs: tuple[Output, ...], topic: str, kind: str) -> list[dict[str, Any]]:
    return [m for t, m in outputs if t == topic and m["kind"] == kind]


def test_a_window_made_at_mu_gives_mu(model_open: WellModel) -> None:
    estimator = FrictionEstimator(model_open)
    state = estimator.initial_state()
    state, outputs = estimator.update(state, _window(model_open, "pick_up", 3500.0, 0.25, 0.0))
    [window] = _of(outputs, "estimate", "window")
    assert window["mu"] == pytest.approx(0.25, abs=1e-6)
    assert window["operation"] == "pick_up" and window["section"] == "all"
    assert window["measured"] == pytest.approx(model_open.evaluate("pick_up", 3500.0, 0.25)[0])
    # the window also fed the profile: one update, one profile estimate at the bit
    [profile] = _of(outputs, "estimate", "profile")
    assert state.windows.profile_updates == 1 and profile["bit_depth_m"] == 3500.0
    assert all(json.dumps(m, allow_nan=False) for _, m in outputs)


def test_update_leaves_the_old_state_as_it_was(model_open: WellModel) -> None:
    estimator = FrictionEstimator(model_open)
    state = estimator.initial_state()
    before = state.windows.profile.state
    window = _window(model_open, "slack_off", 3400.0, 0.3, 0.0)
    first, out_first = estimator.update(state, window)
    again, out_again = estimator.update(state, window)
    assert state.windows.profile.state is before  # the filter in the old state is untouched
    assert state.windows.profile_updates == 0
    assert first.windows.profile.state is not before
    assert json.dumps(out_first) == json.dumps(out_again)
    np.testing.assert_array_equal(first.windows.profile.state.mu,
                                  again.windows.profile.state.mu)


def test_pending_windows_are_revised_once_the_cased_friction_is_known(
        model_cased: WellModel) -> None:
    kind = model_cased.grid.element_kind
    truth = np.where(kind == "cased", 0.2, 0.3)
    estimator = FrictionEstimator(model_cased)
    state = estimator.initial_state()
    # tripping out from below the shoe (3000 m): no cased friction yet, solved over all
    for k, depth in enumerate((3600.0, 3500.0)):
        state, outputs = estimator.update(state, _window(model_cased, "pick_up", depth, truth,
                                                         10.0 * k))
        [window] = _of(outputs, "estimate", "window")
        assert window["section"] == "all" and "revised" not in window
        assert 0.2 < window["mu"] < 0.3
    assert len(state.windows.pending["pick_up"]) == 2
    # inside casing: the first two cased windows do not yet release the waiting ones
    for k, depth in enumerate((2900.0, 2800.0, 2700.0)):
        state, outputs = estimator.update(state, _window(model_cased, "pick_up", depth, truth,
                                                         100.0 + 10.0 * k))
        [cased] = [m for m in _of(outputs, "estimate", "window") if "revised" not in m]
        assert cased["section"] == "cased" and cased["mu"] == pytest.approx(0.2, abs=1e-6)
        revised = [m for m in _of(outputs, "estimate", "window") if m.get("revised")]
        assert (revised == []) == (k < 2)
    assert [m["bit_depth_m"] for m in revised] == [3600.0, 3500.0]
    for message in revised:
        assert message["section"] == "open" and message["mu"] == pytest.approx(0.3, abs=1e-5)
        assert message["mu_cased"] == pytest.approx(0.2, abs=1e-6)
    assert state.windows.pending["pick_up"] == ()
    assert state.windows.mu_cased("pick_up") == pytest.approx(0.2, abs=1e-6)
    # a deep window now is solved for open hole at once
    state, outputs = estimator.update(state, _window(model_cased, "pick_up", 3550.0, truth, 200))
    [window] = _of(outputs, "estimate", "window")
    assert window["section"] == "open" and window["mu"] == pytest.approx(0.3, abs=1e-5)


def test_cased_mean_is_inverse_variance_weighted() -> None:
    cased = add_cased(add_cased(CasedFriction(), 0.2, 0.01), 0.3, 0.02)
    # weights 1/0.01^2 = 10000 and 1/0.02^2 = 2500
    assert cased.mu == pytest.approx((10000 * 0.2 + 2500 * 0.3) / 12500)
    assert cased.count == 2 and not cased.known
    assert add_cased(cased, 0.25, 0.0).weight == pytest.approx(12500 + 1e8)  # std floor 1e-4
    assert CasedFriction().mu is None


def test_weight_check_fires_on_the_third_odd_hang(model_open: WellModel) -> None:
    estimator = FrictionEstimator(model_open)
    state = estimator.initial_state()
    factors = (1.0, 0.85, 0.85, 0.85, 0.85, 1.0, 0.85, 0.85, 0.85)
    alarms: list[dict[str, Any]] = []
    for k, factor in enumerate(factors):
        state, outputs = estimator.update(state, _window(model_open, "static", 3500.0, 0.0,
                                                         100.0 * k, factor))
        alarms += _of(outputs, "alarm", "weight_check")
    # third odd hang in a row (k = 3), not the fourth; again after the weights agreed (k = 8)
    assert [a["t"] for a in alarms] == [310.0, 810.0]
    assert "(15.0 %) lighter" in alarms[0]["message"]
    ratios = [c.ratio for c in state.windows.weight_checks]
    assert ratios == pytest.approx(list(factors))
    assert alarms[0]["value"] == pytest.approx(state.windows.weight_checks[3].measured_weight)


def test_block_weight_is_learnt_in_slips_and_alarmed_once(model_open: WellModel) -> None:
    estimator = FrictionEstimator(model_open, CalibrationSettings(block_weight_tolerance=0.05))
    state = estimator.initial_state()
    in_slips = Detection("in_slips", True, None)
    alarms: list[tuple[int, dict[str, Any]]] = []
    for k in range(30):
        hookload = 460e3 + (100.0 if k % 2 else -100.0)  # configured: 400 kN
        state, outputs = estimator.add_sample(state, RigSample(float(k), hookload, 3500.0),
                                              in_slips)
        alarms += [(k, m) for _, m in outputs if m["kind"] == "block_weight"]
        learnt = estimator.learnt_block_weight(state)
        assert (learnt is None) == (k < 19)  # 20 samples before the detector gets it
    assert alarms == []  # the connection is not over yet
    # the connection ends (here: the input): its readings go to the joint estimate, which
    # alarms once; a still block cannot tell its weight from the sensor's zero, so both are
    # named with what the empty block reads
    state, outputs = estimator.close(state)
    [alarm] = [m for _, m in outputs if m["kind"] == "block_weight"]
    assert alarm["value"] == pytest.approx(460e3, abs=1e3) and alarm["limit"] == 400e3
    assert alarm["message"].startswith("an empty block reads 460 kN, the configured block "
                                       "weight is 400 kN: the block weight or the hook-load "
                                       "sensor's zero is off by +60 kN")
    assert estimator.learnt_block_weight(state) == pytest.approx(460e3)
    off = FrictionEstimator(model_open, CalibrationSettings(learn_block_weight=False))
    quiet = off.initial_state()
    for k in range(30):
        quiet, outputs = off.add_sample(quiet, RigSample(float(k), 460e3, 3500.0), in_slips)
        assert outputs == ()
    assert off.learnt_block_weight(quiet) is None
    assert quiet.samples.block_weight.estimate is not None  # still used by the weight check


def test_samples_build_windows_and_close_gives_the_last(model_open: WellModel) -> None:
    estimator = FrictionEstimator(model_open, CalibrationSettings(
        windows=WindowSettings(min_samples=3)))
    state = estimator.initial_state()
    depth0 = 3500.0
    outputs: tuple[Output, ...] = ()
    for k in range(6):
        depth = depth0 - 0.5 * k
        hookload = model_open.evaluate("pick_up", depth, 0.25)[0]
        state, out = estimator.add_sample(state, RigSample(float(k), hookload, depth),
                                          Detection("pick_up", True, -0.5))
        outputs += out
    assert outputs == () and len(state.samples.accumulator.samples) == 6
    state, outputs = estimator.close(state)
    [window] = _of(outputs, "estimate", "window")
    # the mean hook load of a straight section's pull, at the mean depth: close to 0.25
    assert window["samples"] == 6 and window["bit_depth_m"] == pytest.approx(depth0 - 1.25)
    assert window["mu"] == pytest.approx(0.25, abs=2e-3)
    assert state.samples.accumulator.samples == ()


def test_friction_jump_and_rejected_windows(model_open: WellModel) -> None:
    estimator = FrictionEstimator(model_open)
    state = estimator.initial_state()
    jumps: list[dict[str, Any]] = []
    for k, mu in enumerate((0.2, 0.2, 0.2, 0.2, 0.32)):
        state, outputs = estimator.update(state, _window(model_open, "pick_up",
                                                         3500.0 - 40 * k, mu, 10.0 * k))
        jumps += _of(outputs, "alarm", "friction_jump")
    [jump] = jumps
    assert jump["t"] == 50.0 and jump["value"] == pytest.approx(0.32, abs=1e-6)
    assert state.windows.history["pick_up"] == pytest.approx((0.2, 0.2, 0.2, 0.2, 0.32))
    rejected = Window("pick_up", 0.0, 1.0, 2, 3000.0, 3000.0, 3000.0, 1e6, SE,
                      rejected="hookload_stuck")
    state, outputs = estimator.update(state, rejected)
    [alarm] = [m for _, m in outputs]
    assert alarm["kind"] == "window_rejected" and "hookload_stuck" in alarm["message"]
    few = Window("pick_up", 0.0, 1.0, 0, 3000.0, 3000.0, 3000.0, 1e6, SE,
                 rejected="too_few_samples:0")
    state, outputs = estimator.update(state, few)
    assert outputs == ()  # counted, not alarmed
    assert dict(state.windows.rejected) == {"hookload_stuck": 1, "too_few_samples": 1}


def test_block_weight_window_equals_the_batch_median() -> None:
    rng = np.random.default_rng(5)
    values = np.round(655e3 + 2e3 * rng.standard_normal(60), 0)
    window = BlockWeightWindow()
    for value in values:
        window = add_block_weight(window, float(value), keep=25)
    batch = block_weight_from_samples(values[-25:])
    assert window.estimate is not None
    assert (window.estimate.value, window.estimate.std, window.estimate.n) == (
        batch.value, batch.std, 25)
    assert tuple(window.ordered) == tuple(sorted(values[-25:]))
    assert add_block_weight(window, float("nan")) is window
