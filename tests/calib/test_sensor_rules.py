"""Sensors that lie (issue 28), hand cases of each rule: a frozen channel is named (the one that
froze, not its neighbour), rotation needs torque above its still-string zero offset, windows
resting on a frozen channel reach no estimate, and the in-slips margin scales with the string's
modelled weight at the bit depth."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tdmon.calib.estimator import FrictionEstimator
from tdmon.calib.rigstate import (
    Detection,
    DetectorState,
    RigSample,
    RigStateThresholds,
    detect,
    in_slips_limit,
)
from tdmon.calib.windows import Window, WindowAccumulator, WindowSettings, add_sample, close
from tdmon.model.torque_drag import WellModel

ROOT = Path(__file__).resolve().parents[2]
TH = RigStateThresholds(block_weight=400e3)
RPM_100 = 100 * math.pi / 30
KNM = 1e3


def _run(samples: list[RigSample], thresholds: RigStateThresholds = TH
         ) -> list[Detection]:
    prior, out = DetectorState(), []
    for sample in samples:
        prior, detection = detect(prior, sample, thresholds)
        out.append(detection)
    return out


def _noisy(rng: np.random.Generator, value: float, sd: float) -> float:
    return float(value + sd * rng.standard_normal())


def _pick_up_window(model: WellModel, depth: float, mu: float) -> Window:
    """A pick-up window whose hook load is the model's at ``mu``."""
    hookload = model.evaluate("pick_up", depth, mu)[0]
    return Window("pick_up", 0.0, 10.0, 10, depth, depth, depth, hookload, 1e3)


def _frozen(detection: Detection) -> list[str]:
    return [f.channel for f in detection.frozen]


def test_an_rpm_frozen_after_the_string_stops_is_named_not_the_torque() -> None:
    # 60 s rotating off bottom (15 kN m above a 0.8 kN m zero offset), then the string stops:
    # the torque falls to its offset while the RPM keeps reading 100 rpm
    rng = np.random.default_rng(1)
    samples = [RigSample(float(t), _noisy(rng, 1.2e6, 2e3), 3000.0,
                         _noisy(rng, 20.0, 0.005), RPM_100, None, None, 3010.0,
                         _noisy(rng, (0.8 + (15.0 if t < 60 else 0.0)) * KNM, 100.0))
               for t in range(180)]
    out = _run(samples)
    assert {d.state for d in out[10:60]} == {"rotating_off_bottom"}
    # no rotation once the torque is at its offset, whatever the RPM says
    assert {d.state for d in out[65:]} == {"static"}
    # contradicted (RPM turning, torque still; the torque level averages 5 s): not steady
    # until the RPM is judged frozen
    first = next(k for k, d in enumerate(out) if d.frozen)
    assert 85 <= first <= 100  # 30 s of the torque's evidence after the stop (~62 s)
    assert not any(d.steady for d in out[64:first])
    assert all(_frozen(d) == ["rpm"] for d in out[first:])
    [rpm] = out[first].frozen
    assert rpm.value == RPM_100 and rpm.since < 60.0
    assert rpm.reason.startswith("while the torque fell to 0.") and "not turning" in rpm.reason
    # then the hang is steady again, read from the torque alone, and rests on no frozen channel
    assert all(d.steady for d in out[first + 5:])
    assert all(d.suspect == frozenset() for d in out[first:])


def test_a_torque_frozen_while_the_rpm_turns_is_named_not_the_rpm() -> None:
    rng = np.random.default_rng(2)
    samples = [RigSample(float(t), _noisy(rng, 1.2e6, 2e3), 3000.0,
                         _noisy(rng, 20.0, 0.005), _noisy(rng, RPM_100, 0.05), None, None,
                         3010.0, 15.8 * KNM if t >= 40 else _noisy(rng, 15.8 * KNM, 100.0))
               for t in range(120)]
    out = _run(samples)
    first = next(k for k, d in enumerate(out) if d.frozen)
    assert 69 <= first <= 75  # 30 s of a turning string from the freeze
    assert all(_frozen(d) == ["torque"] for d in out[first:])
    assert "rpm reads 100" in out[first].frozen[0].reason
    # still rotating (by the RPM now), but its windows rest on the frozen torque
    assert {d.state for d in out[first:]} == {"rotating_off_bottom"}
    assert all(d.suspect == frozenset({"torque"}) for d in out[first:])


def test_a_still_string_with_constant_torque_and_rpm_offsets_is_not_frozen() -> None:
    # Volve F-4 tripping: 0.23 rpm and 5.2 N m sent unchanged for hours while the string moves
    rng = np.random.default_rng(3)
    samples = [RigSample(float(t), _noisy(rng, 1.4e6, 5e3), 3000.0 - 0.5 * t, 30.0 - 0.5 * t,
                         0.23 * math.pi / 30, None, None, 3500.0, 5.2) for t in range(50)]
    out = _run(samples)
    assert {d.state for d in out[3:]} == {"pick_up"}
    assert not any(d.frozen or d.suspect for d in out)


def test_rotation_needs_torque_above_the_offset_and_the_rpm_decides_alone_without_one() -> None:
    rng = np.random.default_rng(4)

    def samples(torque_above: float | None) -> list[RigSample]:
        out = []
        for t in range(80):
            slips = t < 20  # the zero offset is learnt in slips
            torque = None if torque_above is None else _noisy(
                rng, 0.8 * KNM + (0.0 if slips else torque_above), 100.0)
            out.append(RigSample(float(t), _noisy(rng, 300e3 if slips else 1.2e6, 2e3), 3000.0,
                                 20.0, RPM_100, None, None, 3010.0, torque))
        return out

    assert {d.state for d in _run(samples(0.0))[25:]} == {"static"}
    # above the offset by more than the 100 N m floor and 4 deviations of the level
    assert {d.state for d in _run(samples(1.0 * KNM))[25:]} == {"rotating_off_bottom"}
    assert {d.state for d in _run(samples(None))[25:]} == {"rotating_off_bottom"}


@pytest.mark.parametrize(("weight", "limit"), [
    (None, 450e3),      # no model: the configured margin
    (190e3, 395e3),     # a light string: half its weight
    (900e3, 450e3),     # a heavy one: the configured margin bounds it
    (10e3, 320e3),      # a few stands: at least the smallest margin
])
def test_in_slips_limit_scales_with_the_string_weight(weight: float | None, limit: float
                                                      ) -> None:
    th = RigStateThresholds(block_weight=300e3, in_slips_margin=150e3)
    assert in_slips_limit(weight, th) == pytest.approx(limit)


def test_a_light_string_on_the_hook_is_not_in_slips() -> None:
    # the near-vertical shallow well: a 190 kN string under a 300 kN block; a fixed 200 kN
    # margin calls its hang in slips, half its weight (95 kN) does not
    th = RigStateThresholds(block_weight=300e3, in_slips_margin=200e3)
    hanging = [RigSample(float(t), 490e3, 1150.0, 20.0, string_weight=190e3) for t in range(5)]
    assert {d.state for d in _run(hanging, th)} == {"static"}
    assert {d.state for d in _run([replace(s, string_weight=None) for s in hanging], th)} == {
        "in_slips"}
    in_slips = [replace(s, hookload=305e3) for s in hanging]
    assert {d.state for d in _run(in_slips, th)} == {"in_slips"}


def test_a_bit_depth_frozen_while_the_block_pulls_is_named_and_its_windows_suspect() -> None:
    rng = np.random.default_rng(5)
    samples = [RigSample(float(t), _noisy(rng, 1.4e6, 2e3),
                         3000.0 - 0.5 * min(t, 10),
                         _noisy(rng, 5.0 + 0.5 * t, 0.005)) for t in range(60)]
    out = _run(samples)
    first = next(k for k, d in enumerate(out) if d.frozen)
    assert 38 <= first <= 42
    assert _frozen(out[first]) == ["bit_depth"]
    assert "block moves the string at 0.50 m/s" in out[first].frozen[0].reason
    # the velocity now comes from the block: still a pull, resting on the frozen bit depth
    assert all(d.state == "pick_up" and d.suspect == frozenset({"bit_depth"})
               for d in out[first:])


def test_the_pumps_contradicting_a_frozen_flow_or_pressure_name_it() -> None:
    rng = np.random.default_rng(6)
    # the pumps stop at 20 s: the pressure falls, the flow reading stays at 2000 L/min
    flow_stuck = [RigSample(float(t), _noisy(rng, 1.2e6, 2e3), 3000.0, 20.0, 0.0, 2000 / 60e3,
                            _noisy(rng, 150e5, 1e5) if t < 20 else 0.0, 3010.0)
                  for t in range(70)]
    out = _run(flow_stuck)
    first = next(k for k, d in enumerate(out) if d.frozen)
    assert 49 <= first <= 52 and _frozen(out[first]) == ["flow_in"]
    assert "standpipe pressure (0.0 bar) says the pumps stopped" in out[first].frozen[0].reason
    # from the next frame on, circulation is read from the pressure
    assert {d.state for d in out[first + 1:]} == {"static"}
    # the pumps start at 20 s: the flow rises, the pressure reading stays at zero
    spp_stuck = [replace(s, flow=_noisy(rng, 2000 / 60e3, 1e-4) if s.t >= 20 else 0.0, spp=0.0)
                 for s in flow_stuck]
    out = _run(spp_stuck)
    first = next(k for k, d in enumerate(out) if d.frozen)
    assert 49 <= first <= 52 and _frozen(out[first]) == ["spp"]


def test_weight_set_on_the_bit_names_a_frozen_wob() -> None:
    rng = np.random.default_rng(7)
    # on bottom from the start; 100 kN set down from 20 s; the weight on bit reads zero
    samples = [RigSample(float(t), _noisy(rng, 1.3e6 - (100e3 if t >= 20 else 0.0), 2e3),
                         3000.0, 20.0, RPM_100, 2000 / 60e3, 150e5, 3000.2,
                         _noisy(rng, 20 * KNM, 100.0), 0.0) for t in range(70)]
    out = _run(samples)
    first = next(k for k, d in enumerate(out) if d.frozen)
    assert 49 <= first <= 52 and _frozen(out[first]) == ["wob"]
    # without the weight on bit the depths say on bottom: drilling
    assert {d.state for d in out[first + 1:]} == {"drilling"}


def test_suspect_windows_carry_their_channel_and_reach_no_estimate(model_open: WellModel
                                                                   ) -> None:
    settings = WindowSettings(min_samples=2)
    acc, suspect = WindowAccumulator(), frozenset({"bit_depth"})
    for t in range(4):
        sample = RigSample(float(t), 1.4e6 + t, 3000.0 - 0.5 * t, 20.0 + 0.5 * t)
        acc, _ = add_sample(acc, sample, Detection("pick_up", True, -0.5,
                                                   suspect if t == 2 else frozenset()),
                            settings)
    _, window = close(acc, settings)
    assert window is not None and window.suspect == ("bit_depth",)
    estimator = FrictionEstimator(model_open)
    state = estimator.initial_state()
    clean = _pick_up_window(model_open, 3500.0, 0.25)
    _, outputs = estimator.update(state, clean)
    [(_, estimate)] = [(topic, m) for topic, m in outputs
                       if topic == "estimate" and m["kind"] == "window"]
    assert estimate["mu"] == pytest.approx(0.25, abs=1e-4)
    flagged, outputs = estimator.update(state, replace(clean, suspect=("bit_depth",)))
    assert outputs == ()
    assert dict(flagged.windows.rejected) == {"suspect_channel": 1}
    np.testing.assert_array_equal(flagged.windows.profile.state.mu,
                                  state.windows.profile.state.mu)


def test_the_daemon_file_keys_reach_the_detector() -> None:
    from tdmon.config.daemon import CalibrationConfig, RigStateConfig, load_daemon_config
    from tdmon.daemon.steps.rig_state import calibration_thresholds, rig_state_thresholds

    rs = RigStateConfig(rotating_torque="0.2 kN*m", torque_average="10 s", frozen_time="1 min",
                        frozen_samples=6, frozen_resolution={"hookload": "1 kN",
                                                             "flow_in": "60 L/min"})
    th = rig_state_thresholds(rs)
    assert (th.rotating_torque, th.torque_average, th.frozen_time, th.frozen_samples) == (
        pytest.approx(200.0), 10.0, 60.0, 6)
    # the given resolutions over the defaults of the others
    assert th.frozen_resolution["hookload"] == pytest.approx(1e3)
    assert th.frozen_resolution["flow_in"] == pytest.approx(1e-3)
    assert th.frozen_resolution["torque"] == 10.0
    config = load_daemon_config(ROOT / "config" / "daemon" / "replay-sim-shallow.toml")
    calibration = CalibrationConfig(in_slips_fraction=0.4, in_slips_min_margin="30 kN")
    config = config.model_copy(update={"calibration": calibration,
                                       "rig_state": RigStateConfig(frozen_time="45 s")})
    cal = calibration_thresholds(config, 300e3)
    assert (cal.in_slips_fraction, cal.in_slips_min_margin, cal.frozen_time) == (
        0.4, pytest.approx(30e3), 45.0)
    assert in_slips_limit(100e3, cal) == pytest.approx(340e3)
    assert in_slips_limit(50e3, cal) == pytest.approx(330e3)  # at least the minimum
    for bad in ({"hookload": 1000.0}, {"hook_load": "1 kN"}, {"rpm": "-1 rpm"}):
        with pytest.raises(ValueError):
            RigStateConfig(frozen_resolution=bad)
