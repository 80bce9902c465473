"""The committed replay files in replays/: present, small, current with their sources."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from tdmon.cli import main
from tdmon.replay.session import STATES

from .conftest import REPO, VOLVE_DATA, read_mcap

REPLAYS = REPO / "replays"
SCENARIOS = sorted((REPLAYS / "scenarios").glob("*.toml"))
VOLVE_REPLAYS = {"volve-f4-trip-out.mcap": "trip-out-2016-10-04.csv",
                 "volve-f4-trip-in.mcap": "trip-in-2016-10-05.csv"}
MAX_BYTES = 2 * 1024 * 1024


def test_every_scenario_has_a_small_replay() -> None:
    assert len(SCENARIOS) >= 2
    for scenario in SCENARIOS:
        replay = REPLAYS / f"{scenario.stem}.mcap"
        assert replay.exists(), f"{replay.name}: run tdmon simulate --scenario {scenario}"
        assert replay.stat().st_size < MAX_BYTES


def test_scenarios_cover_every_state_and_the_alarms() -> None:
    states: set[str] = set()
    alarms: Counter[str] = Counter()
    for scenario in SCENARIOS:
        for read in read_mcap(REPLAYS / f"{scenario.stem}.mcap"):
            if read.topic == "/truth/state":
                states.add(read.message["state"])
            elif read.topic == "/truth/alarm":
                alarms[read.message["kind"]] += 1
    assert states == set(STATES)
    assert {"overpull", "friction_anomaly", "stuck_sensor"} <= set(alarms)


def _values(path: Path) -> tuple[Counter[str], dict[str, np.ndarray]]:
    topics: Counter[str] = Counter()
    values: dict[str, list[float]] = {}
    for read in read_mcap(path):
        topics[read.topic] += 1
        if read.topic == "/tdmon/raw":
            payload = json.loads(read.message["payload"])
            values.setdefault(read.message["topic"], []).append(payload["value"])
    return topics, {topic: np.asarray(v) for topic, v in values.items()}


@pytest.mark.parametrize("scenario", SCENARIOS, ids=lambda p: p.stem)
def test_committed_simulation_is_current(scenario: Path, tmp_path: Path) -> None:
    """Regenerating gives the committed file (values to 1e-6: the model may move in its last
    digits without changing the replay)."""
    out = tmp_path / "again.mcap"
    assert main(["simulate", "--scenario", str(scenario), "--out", str(out)]) == 0
    committed_topics, committed = _values(REPLAYS / f"{scenario.stem}.mcap")
    topics, fresh = _values(out)
    assert topics == committed_topics
    for topic, values in committed.items():
        np.testing.assert_allclose(fresh[topic], values, rtol=1e-6, atol=1e-9, err_msg=topic)


@pytest.mark.parametrize(("replay", "csv_name"), VOLVE_REPLAYS.items())
def test_volve_replays_are_the_import(replay: str, csv_name: str, tmp_path: Path) -> None:
    out = tmp_path / "again.mcap"
    assert main(["import", "volve", str(VOLVE_DATA / csv_name), "--out", str(out)]) == 0
    assert [(r.topic, r.data) for r in read_mcap(out)] == \
        [(r.topic, r.data) for r in read_mcap(REPLAYS / replay)]
    assert (REPLAYS / replay).stat().st_size < MAX_BYTES


def test_volve_licence_note_beside_the_files() -> None:
    readme = (REPLAYS / "README.md").read_text()
    assert "Equinor Open Data Licence (CC BY-NC-SA 4.0 terms)" in readme
    assert '"Equinor and the former Volve licence partners"' in readme
    for replay in VOLVE_REPLAYS:
        assert replay in readme
