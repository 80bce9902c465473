"""Sensors that lie, on the bundled replays (issue 28): the frozen channel is named within a
few windows, the windows of the frozen stretch reach no estimate as rotation, and a light
string hanging on the hook in a shallow well is not "in slips"."""

from __future__ import annotations

import asyncio
import bisect
from collections import Counter
from functools import cache
from pathlib import Path
from typing import Any

import pytest

from tdmon.config.daemon import load_daemon_config
from tdmon.config.expectations import load_expectations
from tdmon.replay.driver import replay

from .conftest import REPO, read_mcap

ROTATING = {"rotating", "reaming", "back_reaming", "drilling"}
#: the window operations each channel's windows rest on (tdmon.calib.rigstate.RESTING_ON)
RESTS_ON = {"spp": set(), "flow_in": set(), "wob": ROTATING,
            "bit_depth": {"pick_up", "slack_off", "static", *ROTATING},
            "block_position": {"pick_up", "slack_off", "reaming", "back_reaming"}}


@cache
def _recorded(name: str, out_dir: Path) -> tuple[list[Any], list[Any]]:
    """(the replay's messages, the recording's), replayed once per session."""
    path = REPO / "replays" / f"{name}.mcap"
    expectations = load_expectations(REPO / "replays" / "expectations" / f"{name}.toml")
    out = out_dir / f"{name}.out.mcap"
    asyncio.run(replay(path, load_daemon_config(expectations.config_path), out))
    return read_mcap(path), read_mcap(out)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Any:
    out_dir = tmp_path_factory.mktemp("sensor-replays")
    return lambda name: _recorded(name, out_dir)


def _of(reads: list[Any], topic: str) -> list[dict[str, Any]]:
    return [r.message for r in reads if r.topic == topic]


def test_frozen_rpm_is_named_and_its_stretch_feeds_no_rotation(recorded: Any) -> None:
    source, out = recorded("frozen-rpm")
    [fault] = _of(source, "/truth/alarm")
    assert fault["channel"] == "rpm"
    start, end = fault["t"], fault["t"] + 12 * 60.0
    frozen = [a for a in _of(out, "/tdmon/alarm") if a["kind"].endswith("_frozen")]
    # the RPM, once, within a minute (the detector needs 30 s of the torque's evidence after
    # the stop), not the torque at its zero offset
    assert [a["kind"] for a in frozen] == ["sensor_rpm_frozen"]
    assert start < frozen[0]["t"] < start + 60.0
    assert "100.0 rpm" in frozen[0]["message"] and "torque fell to" in frozen[0]["message"]
    windows = [e for e in _of(out, "/tdmon/estimate") if e["kind"] == "window"]
    during = [w for w in windows if start <= w["t_start"] < end]
    # hangs, pulls and runs went on during the stretch: their pick-up windows reach the
    # estimates, none as a rotating operation (main gave 34 back-reaming windows at 0.014)
    assert Counter(w["operation"] for w in during)["pick_up"] >= 10
    assert not [w for w in during if w["operation"] in ROTATING]
    # the second rotation (736-796 s) is read from the torque alone: the repaired channel
    # reads the 100 rpm it was stuck at, so it stays distrusted until it moves, and that
    # rotation's window is left out too
    states = [m for m in _of(out, "/tdmon/state") if start + 686.0 < m["t"] < start + 731.0]
    assert states and {m["state"] for m in states} == {"rotating_off_bottom"}
    assert not [w for w in windows if w["t_start"] > start and w["operation"] in ROTATING]


def test_light_string_hangs_and_moves_are_not_in_slips(recorded: Any) -> None:
    source, out = recorded("near-vertical-shallow")
    truth = [(m["t"], m["state"]) for m in _of(source, "/truth/state")]
    times = [t for t, _ in truth]
    hanging = Counter()
    for message in _of(out, "/tdmon/state"):
        k = bisect.bisect_right(times, message["t"]) - 1
        if k >= 0 and truth[k][1] in {"static", "pick_up", "slack_off"}:
            hanging[message["state"] == "in_slips"] += 1
    # a fixed 150 kN margin called 62 of these 900-odd messages in slips (the slack-offs of
    # a 180 kN string); half the string's modelled weight, 11 (the slips' edges)
    assert hanging[False] > 850
    assert hanging[True] < 20
    # the block weight learnt in slips stays the block's (300 kN) plus the load cell's drift
    block = [e["block_weight_N"] for e in _of(out, "/tdmon/estimate") if "block_weight_N" in e]
    assert block and all(295e3 < b < 312e3 for b in block)


def test_frozen_channels_each_raise_their_own_alarm(recorded: Any) -> None:
    source, out = recorded("frozen-channels")
    faults = _of(source, "/truth/alarm")
    raised = [a for a in _of(out, "/tdmon/alarm") if a["kind"].endswith("_frozen")]
    assert [a["kind"] for a in raised] == [f"sensor_{f['channel']}_frozen" for f in faults]
    for fault, alarm in zip(faults, raised, strict=True):
        assert fault["t"] < alarm["t"] < fault["t"] + 120.0, alarm["message"]
    windows = [e for e in _of(out, "/tdmon/estimate") if e["kind"] == "window"]
    # no window overlapping a frozen stretch once the channel is judged frozen reaches an
    # estimate (each fault's message: "<channel> stuck for <n> s")
    for fault, alarm in zip(faults, raised, strict=True):
        end = fault["t"] + float(fault["message"].split(" for ")[1].removesuffix(" s"))
        overlapping = [w for w in windows if w["t"] >= alarm["t"] and w["t_start"] < end
                       and w["operation"] in RESTS_ON[fault["channel"]]]
        assert not overlapping, fault["channel"]
    # the rotation on bottom read as off bottom while the weight on bit lied (0 kN, before it
    # was judged frozen) reached no estimate: no string "lighter than modelled" by the 100 kN
    # set on the bit
    assert not [a for a in _of(out, "/tdmon/alarm") if a["kind"] in {"weight_check",
                                                                      "weight_mismatch"}]
