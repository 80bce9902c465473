"""``tdmon simulate``: a real MCAP file read back (counts, truth topics, SI values, schemas)."""

from __future__ import annotations

import asyncio
import itertools
import json
import math
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import jsonschema
import numpy as np
import pytest

from tdmon.cli import main
from tdmon.config.well import load_well_model
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.mcap_source import McapSource
from tdmon.ingest.types import Rejected
from tdmon.model.torque_drag import WellModel

from .conftest import SCENARIO_WELL, Read, payloads, read_mcap

TRUTH_TOPICS = {"/truth/scenario", "/truth/state", "/truth/load", "/truth/friction",
                "/truth/profile", "/truth/alarm", "/truth/fault"}

NOISY = """
[noise]
relative = 0.01
spike_rate = 0.02
missing_rate = 0.02
clock_jitter = "0.3 s"

[[tight_spot]]
md = "4110 m"
length = "5 m"
force = "150 kN"

[[fault]]
kind = "stuck"
channels = ["torque"]
start = "470 s"
duration = "2 min"
"""


@pytest.fixture
def simulated(write_scenario: Callable[..., Path], tmp_path: Path) -> list[Read]:
    out = tmp_path / "zero-noise.mcap"
    assert main(["simulate", "--scenario", str(write_scenario(interval="1 s")),
                 "--out", str(out)]) == 0
    return read_mcap(out)


def test_counts_and_topics(simulated: list[Read]) -> None:
    topics = Counter(read.topic for read in simulated)
    assert TRUTH_TOPICS - {"/truth/alarm", "/truth/fault"} <= set(topics)
    scenario = next(r.message for r in simulated if r.topic == "/truth/scenario")
    duration = scenario["duration_s"]
    channels = payloads(simulated, "sim/test")
    for name, values in channels.items():
        interval = scenario["sample_interval_s"][name]
        assert len(values) == math.ceil(duration / interval), name
    assert len(channels) == 11
    assert topics["/tdmon/raw"] == sum(len(v) for v in channels.values())
    # one truth load per hook-load sample, one profile, state changes in time order
    assert topics["/truth/load"] == len(channels["hookload"])
    assert topics["/truth/profile"] == 1
    times = [r.log_time for r in simulated]
    assert times == sorted(times)


def test_schemas_are_json_schema_and_messages_conform(simulated: list[Read]) -> None:
    checked: set[str] = set()
    for read in simulated:
        assert read.schema_encoding == "jsonschema"
        if read.topic not in checked or read.topic == "/truth/state":
            jsonschema.validate(read.message, read.schema)
            checked.add(read.topic)
    raw = next(r.message for r in simulated if r.topic == "/tdmon/raw")
    assert raw["source"] == "mcap" and raw["payload_encoding"] == "utf-8"
    assert all(r.log_time == round(r.message["receive_time"] * 1e9) for r in simulated
               if r.topic == "/tdmon/raw")
    assert set(json.loads(raw["payload"])) == {"t", "value", "unit"}


def test_zero_noise_payloads_are_the_model_in_si(simulated: list[Read]) -> None:
    """Recorded pick-up / slack-off hook load and rotating torque equal WellModel.evaluate at
    the recorded bit depth, with the recorded true profile (values written to 7 digits)."""
    channels = payloads(simulated, "sim/test")
    units = {name: {p["unit"] for p in values} for name, values in channels.items()}
    assert units["hookload"] == {"N"} and units["torque"] == {"N*m"}
    assert units["rpm"] == {"rad/s"} and units["flow_in"] == {"m**3/s"}
    assert units["spp"] == {"Pa"} and units["mud_temp_in"] == {"degC"}
    by_time = {name: {round(p["t"], 3): p["value"] for p in values}
               for name, values in channels.items()}
    states = {round(r.message["t"], 3): r.message["state"]
              for r in simulated if r.topic == "/truth/load"}
    profile = next(r.message for r in simulated if r.topic == "/truth/profile")
    model = WellModel(load_well_model(SCENARIO_WELL))
    mu = np.asarray(profile["mu"])
    assert mu.size == model.n_elements
    checked = Counter[str]()
    for t, state in states.items():
        bit = by_time["bit_depth"][t]
        hookload, torque = by_time["hookload"][t], by_time["torque"][t]
        if state in ("pick_up", "slack_off"):
            assert hookload == pytest.approx(model.evaluate(state, bit, mu)[0], rel=2e-6)
            assert torque == 0.0
        elif state == "rotating_off_bottom":
            expected = model.evaluate("rotating", bit, mu)
            assert (hookload, torque) == pytest.approx(expected, rel=2e-6)
        elif state == "in_slips":
            assert hookload == pytest.approx(300e3)
        elif state in ("circulating", "drilling"):
            assert by_time["flow_in"].get(t, 2000 / 60000) == pytest.approx(2000 / 60000)
        checked[state] += 1
    assert min(checked[s] for s in ("pick_up", "slack_off", "rotating_off_bottom")) > 10
    # WOB in N, RPM in rad/s while drilling
    drilling = [t for t, s in states.items() if s == "drilling"]
    assert by_time["wob"][drilling[5]] == pytest.approx(80e3)
    assert by_time["rpm"][drilling[5]] == pytest.approx(100 * 2 * math.pi / 60, rel=1e-6)


def test_truth_topics_describe_the_session(simulated: list[Read]) -> None:
    states = [r.message["state"] for r in simulated if r.topic == "/truth/state"]
    assert set(states) == {"in_slips", "pick_up", "slack_off", "rotating_off_bottom", "reaming",
                           "back_reaming", "drilling", "circulating", "static"}
    assert all(a != b for a, b in itertools.pairwise(states))
    friction = [r.message for r in simulated if r.topic == "/truth/friction"]
    assert all(m["state"] != "in_slips" for m in friction)
    assert all(0.15 < m["mu_pick_up"] < 0.35 for m in friction)
    holes = [r.message["hole_depth_m"] for r in simulated if r.topic == "/truth/load"]
    assert holes[0] == 4150.0 and holes[-1] == pytest.approx(4152.0)


def test_same_seed_same_message_bytes(write_scenario: Callable[..., Path],
                                      tmp_path: Path) -> None:
    scenario = write_scenario(extra=NOISY)
    first, second, third = tmp_path / "a.mcap", tmp_path / "b.mcap", tmp_path / "c.mcap"
    assert main(["simulate", "--scenario", str(scenario), "--out", str(first)]) == 0
    assert main(["simulate", "--scenario", str(scenario), "--out", str(second)]) == 0
    assert main(["simulate", "--scenario", str(scenario), "--out", str(third),
                 "--seed", "6"]) == 0

    def content(path: Path) -> list[tuple[str, int, bytes]]:
        return [(r.topic, r.log_time, r.data) for r in read_mcap(path)]

    assert content(first) == content(second)
    assert content(first) != content(third)


def test_noise_and_faults_show_in_the_file(write_scenario: Callable[..., Path],
                                           tmp_path: Path) -> None:
    out = tmp_path / "noisy.mcap"
    assert main(["simulate", "--scenario", str(write_scenario(extra=NOISY)),
                 "--out", str(out)]) == 0
    messages = read_mcap(out)
    faults = Counter((r.message["kind"], r.message["channel"]) for r in messages
                     if r.topic == "/truth/fault")
    assert faults[("stuck", "torque")] == 1 and faults[("spike", "hookload")] > 0
    alarms = [r.message["kind"] for r in messages if r.topic == "/truth/alarm"]
    assert sorted(alarms) == ["overpull", "set_down", "stuck_sensor"]
    torque = payloads(messages, "sim/test")["torque"]
    start = next(r.message["t"] for r in messages if r.topic == "/truth/scenario")
    stuck = {p["value"] for p in torque if 470.5 <= p["t"] - start < 589.5}
    assert len(stuck) == 1


def test_replay_source_reads_simulated_files_like_recordings(simulated: list[Read],
                                                             tmp_path: Path,
                                                             write_scenario: Callable[..., Path],
                                                             ) -> None:
    out = tmp_path / "again.mcap"
    assert main(["simulate", "--scenario", str(write_scenario(interval="1 s")),
                 "--out", str(out)]) == 0
    decoder = Decoder("sim/test", [ChannelSpec(c, c) for c in (
        "hookload", "torque", "bit_depth", "hole_depth", "block_position", "rpm", "flow_in",
        "spp", "wob", "mud_temp_in", "mud_temp_out")])

    async def collect() -> tuple[Counter[str], int]:
        counts: Counter[str] = Counter()
        rejected = 0
        async with McapSource(out) as source:
            async for raw in source:
                sample = decoder.decode(raw)
                if isinstance(sample, Rejected):
                    rejected += 1
                else:
                    counts[sample.channel] += 1
        return counts, rejected

    counts, rejected = asyncio.run(collect())
    assert rejected == 0
    expected = Counter(r.message["topic"].rsplit("/", 1)[-1] for r in simulated
                       if r.topic == "/tdmon/raw")
    assert counts == expected


@pytest.mark.parametrize(("text", "message"), [
    ("[scenario]\nwell = 'x.toml'\nbit_depth = '100 m'\n[[phase]]\nkind = 'static'\n"
     "duration = '10 s'\n", "scenario.well: no such file"),
    ("[scenario]\nbit_depth = '100 m'\n[[phase]]\nkind = 'static'\nduration = '10 s'\n",
     "scenario.well: missing key"),
    ("[scenario]\nwell = 'x.toml'\nbit_depth = '100 m'\nspeed = 3\n[[phase]]\nkind = 'static'\n"
     "duration = '10 s'\n", "scenario.speed: unknown key"),
    ("[scenario]\nwell = 'x.toml'\nbit_depth = '100 m'\n[[phase]]\nkind = 'trip_in'\n",
     "phase[0]: Value error, a 'trip_in' phase needs 'to'"),
    ("[scenario]\nwell = 'x.toml'\nbit_depth = '100 m'\n[sampling]\ninterval = '5 parsecs'\n"
     "[[phase]]\nkind = 'static'\nduration = '10 s'\n", "sampling.interval"),
])
def test_bad_scenarios_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                            text: str, message: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    assert main(["simulate", "--scenario", str(path), "--out", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("tdmon: error: ")
    assert message.replace("Value error, ", "") in err
    assert not (tmp_path / "x.mcap").exists()


def test_impossible_programme_exits_2(write_scenario: Callable[..., Path], tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    phases = "[[phase]]\nkind = 'trip_in'\nto = '4300 m'\nspeed = '0.5 m/s'\n"
    path = write_scenario(phases=phases, hole_depth="4300 m")
    assert main(["simulate", "--scenario", str(path), "--out", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert "deeper than the drill string" in err and err.count("\n") == 1
