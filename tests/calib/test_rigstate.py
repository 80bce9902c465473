"""Rig-state detection and steady windows: hand cases, synthetic trips scored against the
generator's truth, and bad input (gaps, spikes, a stuck sensor, the depth-tracking artefact)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from tdmon.calib.rigstate import (
    STATES,
    Detection,
    DetectorState,
    RigSample,
    RigStateThresholds,
    classify,
    detect,
    detect_series,
)
from tdmon.calib.windows import WindowAccumulator, WindowSettings, add_sample, close, summarise
from tdmon.model.torque_drag import WellModel

TH = RigStateThresholds(block_weight=400e3)
RPM_100 = 100 * 2 * math.pi / 60


@pytest.mark.parametrize(
    ("hookload", "velocity", "rpm", "circulating", "on_bottom", "expected"),
    [
        (None, 0.0, 0.0, False, False, "unknown"),
        (450e3, -0.5, 0.0, False, False, "in_slips"),  # empty block moving: still in slips
        (1.4e6, -0.5, 0.0, False, False, "pick_up"),
        (1.0e6, 0.5, 0.0, False, False, "slack_off"),
        (1.2e6, 0.0, RPM_100, False, False, "rotating_off_bottom"),
        (1.0e6, 0.2, RPM_100, True, False, "reaming"),
        (1.4e6, -0.2, RPM_100, True, False, "back_reaming"),
        (1.0e6, 0.001, RPM_100, True, True, "drilling"),
        (1.2e6, 0.0, 0.0, True, False, "circulating"),
        (1.2e6, 0.0, 0.0, False, False, "static"),
        (1.2e6, 0.0, 0.02, False, False, "static"),  # Volve's 0.23 rev/min offset
    ],
)
def test_classify_hand_cases(hookload: float | None, velocity: float, rpm: float,
                             circulating: bool, on_bottom: bool, expected: str) -> None:
    assert classify(hookload, velocity, rpm, circulating, on_bottom, TH) == expected
    assert expected in STATES


def test_circulating_from_pressure_when_flow_is_missing() -> None:
    prior = DetectorState()
    for t in range(3):
        prior, result = detect(prior, RigSample(float(t), 1.2e6, 2000.0, spp=50e5), TH)
    assert result.state == "circulating"


def test_trip_out_states_match_truth(model_open: WellModel, trip: Any,
                                     windows_of: Any
                                     ) -> None:
    mu = np.full(model_open.n_elements, 0.25)
    session = trip(model_open, mu, start=4200.0, end=3000.0, rotate_every=3)
    states, _ = windows_of(session)
    agreement = float(np.mean(np.array(states) == session.truth))
    assert agreement >= 0.95


def test_trip_in_states_match_truth(model_open: WellModel, trip: Any,
                                    windows_of: Any
                                    ) -> None:
    mu = np.full(model_open.n_elements, 0.25)
    session = trip(model_open, mu, start=2500.0, end=3600.0, seed=4)
    states, _ = windows_of(session)
    agreement = float(np.mean(np.array(states) == session.truth))
    assert agreement >= 0.95


def test_steady_samples_leave_out_break_over_and_acceleration(
        model_open: WellModel, trip: Any) -> None:
    mu = np.full(model_open.n_elements, 0.25)
    s = trip(model_open, mu, start=4200.0, end=4000.0)
    states, steady = detect_series(s.t, s.hookload, s.bit_depth, TH,
                                   block_position=s.block_position)
    velocity = np.abs(np.diff(s.bit_depth, prepend=s.bit_depth[0]))
    pulls = (states == "pick_up") & steady
    assert pulls.sum() > 50
    # no steady sample while the string accelerates (speed below the 0.5 m/s plateau) or in
    # the first 5 s of a pull, where the generator puts the break-over peak
    assert np.all(velocity[pulls] > 0.35)
    starts = np.flatnonzero((states == "pick_up") & (np.roll(states, 1) != "pick_up"))
    for start in starts:
        assert not steady[start:start + 5].any()


def _feed(samples: list[RigSample], settings: WindowSettings,
          thresholds: RigStateThresholds = TH) -> list[Any]:
    prior, acc, windows = DetectorState(), WindowAccumulator(), []
    for sample in samples:
        prior, detection = detect(prior, sample, thresholds)
        acc, window = add_sample(acc, sample, detection, settings)
        if window is not None:
            windows.append(window)
    acc, window = close(acc, settings)
    if window is not None:
        windows.append(window)
    return windows


def _pull(t0: float, n: int, hook: float, depth0: float, speed: float = -0.5,
          noise: float = 3e3, seed: int = 0) -> list[RigSample]:
    rng = np.random.default_rng(seed)
    return [RigSample(t0 + k, hook + noise * rng.standard_normal(), depth0 + speed * k,
                      block_position=1.0 - speed * k) for k in range(n)]


def test_depth_tracking_artefact_never_makes_a_window() -> None:
    # Volve trip in, 01:35-02:20Z: the bit depth advances while the hook load stays at the
    # in-slips level (no block position sent here, the worst case)
    samples = [RigSample(float(k), 405e3 + 1e3 * math.sin(k), 2000.0 + 0.6 * k)
               for k in range(120)]
    prior = DetectorState()
    for sample in samples:
        prior, detection = detect(prior, sample, TH)
        assert detection.state == "in_slips"
    windows = _feed(samples, WindowSettings(min_samples=3))
    assert all(w.state == "in_slips" for w in windows)


def test_depth_jump_without_block_is_not_steady() -> None:
    samples = _pull(0.0, 40, 1.4e6, 3000.0)
    samples = [RigSample(s.t, s.hookload, s.bit_depth) for s in samples]  # no block channel
    jumped = [RigSample(s.t, s.hookload, (s.bit_depth or 0.0) - (30.0 if s.t >= 20 else 0.0))
              for s in samples]
    prior = DetectorState()
    flags = []
    for sample in jumped:
        prior, detection = detect(prior, sample, TH)
        flags.append(detection.steady)
    assert not flags[20]  # the 30 m jump is a 30 m/s^2 acceleration


def test_gap_splits_windows_and_restarts_settling() -> None:
    first = _pull(0.0, 30, 1.4e6, 3000.0)
    second = _pull(200.0, 30, 1.4e6, 2985.0, seed=1)  # 170 s of nothing in between
    windows = _feed(first + second, WindowSettings(min_samples=3, max_travel=100.0))
    pulls = [w for w in windows if w.state == "pick_up"]
    assert len(pulls) == 2
    assert all(w.t_start - 200.0 >= 5.0 or w.t_end < 100.0
               for w in pulls)


def test_spikes_are_dropped_from_a_window() -> None:
    samples = _pull(0.0, 40, 1.4e6, 3000.0)
    # a 40 kN spike stays inside the detector's step tolerance, so the window must drop it
    spiked = [RigSample(s.t, (s.hookload or 0.0) + (40e3 if s.t == 20.0 else 0.0),
                        s.bit_depth, s.block_position) for s in samples]
    windows = _feed(spiked, WindowSettings(min_samples=3, max_travel=100.0))
    pull = next(w for w in windows if w.state == "pick_up")
    assert "spikes_removed:1" in pull.flags
    assert abs(pull.hookload - 1.4e6) < 3e3


def test_stuck_hookload_rejects_the_window() -> None:
    samples = [RigSample(float(k), 1.4e6, 3000.0 - 0.5 * k, block_position=1.0 + 0.5 * k)
               for k in range(40)]
    windows = _feed(samples, WindowSettings(min_samples=3, max_travel=100.0))
    pull = next(w for w in windows if w.state == "pick_up")
    assert pull.rejected == "hookload_stuck"


def test_bit_depth_not_following_block_is_low_confidence() -> None:
    samples = [RigSample(float(k), 1.4e6 + 2e3 * math.sin(k), 3000.0,  # depth frozen
                         block_position=1.0 + 0.5 * k) for k in range(40)]
    windows = _feed(samples, WindowSettings(min_samples=3, max_travel=100.0))
    pull = next(w for w in windows if w.state == "pick_up")
    assert pull.low_confidence
    assert "depth_not_following_block" in pull.flags


def test_single_sample_window_has_the_noise_floor() -> None:
    sample = RigSample(0.0, 1.6e6, 2500.0, block_position=5.0)
    window = summarise("pick_up", (sample,), (-0.3,), WindowSettings())
    assert window is not None
    assert window.n == 1
    assert window.hookload_se == pytest.approx(0.005 * 1.6e6)


def test_detector_memory_of_each_channel() -> None:
    # (sample, then the state after it: bit depth, its time, block position, its time, whether
    # the block was loaded, velocity, state): the aligner repeats a channel's last sample on
    # frames between its samples, samples arrive out of order, the block travels empty in slips
    steps = [
        (RigSample(0.0, 1.4e6, 3000.0, block_position=20.0),
         (3000.0, 0.0, 20.0, 0.0, True, None, "static")),
        (RigSample(1.0, 1.4e6, 2999.5, block_position=20.5),
         (2999.5, 1.0, 20.5, 1.0, True, -0.5, "pick_up")),
        # both channels repeated from t = 1: memory kept, the last velocity carried
        (RigSample(2.0, 1.4e6, 2999.5, block_position=20.5, block_time=1.0, bit_time=1.0),
         (2999.5, 1.0, 20.5, 1.0, True, -0.5, "pick_up")),
        # a block sample older than the one held: no velocity from it, memory kept
        (RigSample(3.0, 1.4e6, 2999.0, block_position=20.3, block_time=0.5),
         (2999.0, 3.0, 20.5, 1.0, True, -0.25, "pick_up")),
        # in slips: the empty block's position is remembered as unloaded
        (RigSample(4.0, 450e3, 2999.0, block_position=21.0),
         (2999.0, 4.0, 21.0, 4.0, False, 0.0, "in_slips")),
        # out of the slips: no block velocity across them, the bit depth's counts
        (RigSample(5.0, 1.4e6, 2998.5, block_position=21.5),
         (2998.5, 5.0, 21.5, 5.0, True, -0.5, "pick_up")),
        # a gap longer than max_gap: the channels are remembered, no velocity
        (RigSample(100.0, 1.4e6, 2990.0, block_position=30.0),
         (2990.0, 100.0, 30.0, 100.0, True, None, "static")),
    ]
    prior = DetectorState()
    for sample, expected in steps:
        prior, detection = detect(prior, sample, TH)
        assert (prior.bit_depth, prior.bit_time, prior.block_position, prior.block_time,
                prior.block_loaded, prior.velocity, prior.state) == expected
        assert prior.t == sample.t and prior.hookload == sample.hookload
        assert (detection.state, detection.velocity) == (expected[6], expected[5])
    assert prior.state_since == 100.0
    bad_time, detection = detect(prior, RigSample(math.nan, 1.4e6, 2990.0), TH)
    assert detection.state == "unknown" and bad_time.state == "unknown"
    assert bad_time.bit_depth == prior.bit_depth and bad_time.t == prior.t


def test_nan_channels_give_unknown_and_no_window() -> None:
    samples = [RigSample(float(k), math.nan, math.nan) for k in range(20)]
    prior = DetectorState()
    for sample in samples:
        prior, detection = detect(prior, sample, TH)
        assert detection.state == "unknown" and not detection.steady
    assert _feed(samples, WindowSettings()) == []


def _setting_slips() -> list[RigSample]:
    # Volve F-4 at 5 s sampling: a static hang at 1410 kN (1 kN of noise), then the slips are
    # set and the hook load falls 1410 -> 1344 -> 1035 kN before the string rests in them
    loads = [1410e3 + 1e3 * math.sin(k) for k in range(12)] + [1344e3, 1035e3, 420e3, 418e3]
    return [RigSample(5.0 * k, load, 2390.0, block_position=12.0)
            for k, load in enumerate(loads)]


def test_a_hang_being_set_in_the_slips_is_not_steady() -> None:
    prior = DetectorState()
    detections = []
    for sample in _setting_slips():
        prior, detection = detect(prior, sample, TH)
        detections.append(detection)
    assert [d.state for d in detections[:14]] == ["static"] * 14
    assert all(d.steady for d in detections[2:12])  # the hang itself settles
    # 1344 kN is 66 kN below the hang: within the sample-to-sample step (5 % of the load) but
    # not a settled hang
    assert not detections[12].steady
    assert not detections[13].steady
    windows = _feed(_setting_slips(), WindowSettings(min_samples=3))
    statics = [w for w in windows if w.state == "static"]
    assert len(statics) == 1
    assert statics[0].t_end == 55.0  # the last sample of the hang, nothing of the transient
    assert statics[0].hookload == pytest.approx(1410e3, abs=1e3)


def test_a_hang_drifting_within_the_tolerance_stays_steady() -> None:
    # 0.5 kN/sample of drift (mud temperature, line stretch) stays inside 20 kN over 5 s
    samples = [RigSample(5.0 * k, 1410e3 + 500.0 * k, 2390.0) for k in range(20)]
    prior = DetectorState()
    flags = []
    for sample in samples:
        prior, detection = detect(prior, sample, TH)
        flags.append(detection.steady)
    assert all(flags[1:])


def test_stuck_torque_flags_only_windows_that_use_torque() -> None:
    # the torque sensor reads a constant 5.2 kN m: a pick-up without rotation does not use
    # torque and keeps full confidence; a rotating window does and is flagged
    pull = [RigSample(float(k), 1.4e6 + 2e3 * math.sin(k), 3000.0 - 0.5 * k,
                      block_position=1.0 + 0.5 * k, rpm=0.0, torque=5.2e3) for k in range(40)]
    [window] = [w for w in _feed(pull, WindowSettings(min_samples=3, max_travel=100.0))
                if w.state == "pick_up"]
    assert window.torque == pytest.approx(5.2e3)
    assert "torque_stuck" not in window.flags
    assert not window.low_confidence
    spin = [RigSample(float(k), 1.2e6 + 2e3 * math.sin(k), 3000.0, block_position=1.0,
                      rpm=RPM_100, torque=5.2e3) for k in range(40)]
    rotating = [w for w in _feed(spin, WindowSettings(min_samples=3))
                if w.state == "rotating_off_bottom"]
    assert rotating and all("torque_stuck" in w.flags and w.low_confidence for w in rotating)


def test_detector_values_are_built_frozen_compared_and_copied_like_dataclasses() -> None:
    import dataclasses
    import pickle

    sample = RigSample(3.0, 1.4e6, 2999.0, block_position=20.3, block_time=0.5)
    assert (sample.t, sample.hookload, sample.bit_depth, sample.block_position, sample.rpm,
            sample.block_time, sample.bit_time) == (3.0, 1.4e6, 2999.0, 20.3, None, 0.5, None)
    assert sample == RigSample(t=3.0, hookload=1.4e6, bit_depth=2999.0, block_position=20.3,
                               block_time=0.5)
    assert hash(sample) == hash(dataclasses.replace(sample))
    assert dataclasses.replace(sample, rpm=1.0).rpm == 1.0
    with pytest.raises(TypeError):
        RigSample(3.0, 1.4e6)  # type: ignore[call-arg]
    state = DetectorState()
    assert state.t == -math.inf and state.state == "unknown" and state.hang_run == 0
    prior, detection = detect(state, sample, TH)
    assert pickle.loads(pickle.dumps(prior)) == prior
    assert dataclasses.astuple(prior)[0] == 3.0 and prior.run == 1
    assert detection == Detection(prior.state, detection.steady, detection.velocity)
    assert repr(detection) == (f"Detection(state={prior.state!r}, steady=False, "
                               f"velocity={detection.velocity!r}, suspect=frozenset(), "
                               "frozen=())")
    for value, name in ((sample, "hookload"), (prior, "run"), (detection, "steady")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(value, name, None)
