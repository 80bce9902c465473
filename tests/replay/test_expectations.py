"""Expectations files and their checks, on small hand-made recordings (no daemon)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from mcap.writer import Writer

from tdmon.config.expectations import Expectations, load_expectations
from tdmon.errors import ConfigError
from tdmon.replay.expectations import check_replay, failed, find_expectations

T0 = 1_700_000_000.0


def _write(path: Path, messages: list[tuple[str, dict[str, Any]]]) -> None:
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("any", "jsonschema", b"{}")
        channels: dict[str, int] = {}
        for topic, message in messages:
            if topic not in channels:
                channels[topic] = writer.register_channel(topic, "json", schema)
            ns = int(message["t"] * 1e9)
            writer.add_message(channels[topic], ns, json.dumps(message).encode(), ns)
        writer.finish()


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    """A replay with truth (states: pick_up 0-100 s, in_slips 100-200 s; an overpull at
    50 s) and a daemon recording that is right except for 20 s of static."""
    replay: list[tuple[str, dict[str, Any]]] = [
        ("/tdmon/raw", {"t": T0, "topic": "sim/x/hookload", "receive_time": T0,
                        "payload": "{}", "source": "mcap"}),
        ("/truth/state", {"t": T0, "state": "pick_up"}),
        ("/truth/alarm", {"t": T0 + 50, "kind": "overpull", "accept": ["friction_jump", "band"]}),
        ("/truth/alarm", {"t": T0 + 60, "kind": "overpull", "accept": ["friction_jump", "band"]}),
        ("/truth/state", {"t": T0 + 100, "state": "in_slips"}),
    ]
    replay += [("/truth/friction", {"t": T0 + t, "mu_pick_up": 0.25, "mu_slack_off": 0.3,
                                    "mu_rotating": 0.2}) for t in range(0, 200, 10)]
    recording: list[tuple[str, dict[str, Any]]] = []
    for t in range(0, 200):
        state = "pick_up" if t < 100 else "static" if t < 120 else "in_slips"
        recording.append(("/tdmon/state", {"t": T0 + t, "state": state}))
        recording.append(("/tdmon/sample", {"t": T0 + t, "channel": "hookload"}))
    for t, mu in ((20, 0.26), (40, 0.27), (60, 0.24)):
        recording.append(("/tdmon/estimate", {"t": T0 + t, "kind": "window",
                                              "operation": "pick_up", "mu": mu,
                                              "bit_depth_m": 1000.0 + t, "section": "all"}))
    recording.append(("/tdmon/alarm", {"t": T0 + 55, "kind": "friction_jump"}))
    recording.append(("/tdmon/alarm", {"t": T0 + 150, "kind": "sensor_stale"}))
    recording.sort(key=lambda item: item[1]["t"])
    _write(tmp_path / "x.mcap", replay)
    _write(tmp_path / "y.mcap", recording)
    return tmp_path / "x.mcap", tmp_path / "y.mcap"


def _expect(**data: Any) -> Expectations:
    return Expectations.model_validate({"replay": "x.mcap", "config": "d.toml", **data})


def _by_name(checks: list[Any]) -> dict[str, Any]:
    return {c.name: c for c in checks}


def test_states_agreement_and_required(files: tuple[Path, Path]) -> None:
    replay, recording = files
    checks = _by_name(check_replay(_expect(states={
        "agreement": 0.95, "settle": 5, "required": ["pick_up", "drilling"]}),
        recording, replay=replay))
    agreement = checks["states vs truth"]
    # 200 messages, 5 s after each of the two changes left out: 190; 15 of them static
    assert not agreement.passed and "175" not in agreement.measured
    assert agreement.measured.startswith("92.1 % of 190")
    assert "in_slips reported as static x15" in agreement.detail
    assert checks["state pick_up reported"].passed
    assert not checks["state drilling reported"].passed


def test_input_friction_and_finite(files: tuple[Path, Path]) -> None:
    replay, recording = files
    checks = _by_name(check_replay(_expect(
        input={"messages": 201},
        friction=[{"operation": "pick_up", "min": 0.2, "max": 0.25, "truth_abs": 0.015}]),
        recording, replay=replay, non_finite_published=2))
    assert checks["decoded samples"].detail == "-1"
    friction = checks["friction pick_up"]
    assert not friction.passed
    assert "median 0.260 of 3 windows" in friction.measured
    assert friction.detail == "median off by 0.010"  # the truth part passes
    assert "median |error| 0.010" in friction.measured
    assert not checks["finite results"].passed


def test_one_alarm_answers_one_expectation(files: tuple[Path, Path]) -> None:
    replay, recording = files
    checks = check_replay(_expect(alarm=[
        {"event": "overpull", "window": [-5, 30]},
        {"event": "overpull", "nth": 2, "window": [-10, 30],
         "known_issue": "only one alarm for two pulls"},
        {"kinds": ["sensor_stale"], "at": 100, "window": [0, 40]},
    ], forbidden={"kinds": ["sensor_stale", "band"]}), recording, replay=replay)
    by_name = _by_name(checks)
    assert by_name["alarm overpull"].passed
    assert by_name["alarm overpull"].measured == "friction_jump at 55 s"
    second = by_name["alarm overpull #2"]
    assert not second.passed and second.detail == "already answers an earlier expectation"
    assert not second.fails and "KNOWN" in second.line()
    late = by_name["alarm sensor_stale"]
    assert not late.passed and late.detail == "10 s outside the window"
    assert not by_name["no sensor_stale alarm"].passed and by_name["no band alarm"].passed
    assert [c.name for c in failed(checks)] == ["alarm sensor_stale", "no sensor_stale alarm"]


def test_volve_codes_are_compared_within_their_rows(tmp_path: Path) -> None:
    activity = [("/reference/rig_activity", {"t": T0 + t, "activity": a, "code": 0,
                                             "circulating": False, "rotating": False})
                for t, a in ((0, "tripping out"), (15, "tripping out"), (30, "in slips"),
                             (45, "none"), (300, "off bottom"))]
    states = [("/tdmon/state", {"t": T0 + t, "state": s})
              for t, s in ((5, "pick_up"), (20, "back_reaming"), (35, "in_slips"),
                           (50, "static"), (200, "static"), (305, "circulating"))]
    _write(tmp_path / "x.mcap", activity)
    _write(tmp_path / "y.mcap", states)
    [check] = check_replay(_expect(input={"rejected": 0}, finite=False,
                                   states={"reference": "volve", "settle": 0}),
                           tmp_path / "y.mcap", replay=tmp_path / "x.mcap")[1:]
    # "none" (50 s) says nothing; 200 s is beyond two rows of the last code: 4 compared
    assert check.passed and check.measured.startswith("100.0 % of 4")


def test_load_find_and_mistakes(tmp_path: Path) -> None:
    folder = tmp_path / "expectations"
    folder.mkdir()
    good = folder / "x.toml"
    good.write_text('replay = "../x.mcap"\nconfig = "d.toml"\n[states]\nagreement = 0.8\n')
    assert find_expectations(tmp_path / "x.mcap") == good
    assert find_expectations(tmp_path / "other.mcap") is None
    loaded = load_expectations(good)
    assert loaded.replay_path == folder / "../x.mcap" and loaded.states is not None
    bad = tmp_path / "bad.toml"
    bad.write_text('replay = "x"\nconfig = "y"\n[states]\nagrement = 0.8\n')
    with pytest.raises(ConfigError, match=r"bad.toml: states.agrement: unknown key"):
        load_expectations(bad)
    bad.write_text('replay = "x"\nconfig = "y"\n[[friction]]\noperation = "pick_up"\n')
    with pytest.raises(ConfigError, match="give min, max, truth_abs, within_2_std or resolvable"):
        load_expectations(bad)
    with pytest.raises(ConfigError, match="no such file"):
        load_expectations(tmp_path / "none.toml")
