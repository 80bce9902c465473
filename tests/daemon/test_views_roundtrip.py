"""Round trip: what a daemon run logged is read back, from the MCAP flight recording (every
topic, counts and values) and from the Rerun .rrd (entities, timelines, row counts).

The daemon is ``tdmon run`` on the bundled simulated trip out (replays/trip-out-tight-spot.mcap,
MCAP source flat out) with calibration on, the folder recorder and Rerun in file mode, as a
user would run it. One BLAS thread: see tests/daemon/test_mu_calibration_live.py.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from daemon_support import schema_validators
from rerun.chunk import RrdReader

from tdmon.config.well import load_well
from tdmon.model.well import hole_grid
from tdmon.record.reader import RecordedMessage, read_messages, schemas_of, topic_counts

ROOT = Path(__file__).resolve().parents[2]
REPLAY = ROOT / "replays" / "trip-out-tight-spot.mcap"
WELL = ROOT / "replays" / "scenarios" / "wells" / "example-7-1-glydril.toml"
TDMON = [sys.executable, "-m", "tdmon"]


class Run:
    def __init__(self, folder: Path) -> None:
        [self.mcap] = sorted((folder / "rec").glob("*.mcap"))
        self.rrd = folder / "views.rrd"
        self.messages: list[RecordedMessage] = list(read_messages(self.mcap))
        self.by_topic: dict[str, list[dict[str, Any]]] = defaultdict(list)
        for item in self.messages:
            self.by_topic[item.topic].append(item.message)

    def estimates(self, kind: str) -> list[dict[str, Any]]:
        return [m for m in self.by_topic["/tdmon/estimate"] if m["kind"] == kind]


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    folder = tmp_path_factory.mktemp("views-roundtrip")
    config = folder / "daemon.toml"
    config.write_text(f"""
prefix = "sim/trip-out"
well = "{WELL}"
[sources.mcap]
path = "{REPLAY}"
speed = "max"
[recorder]
enabled = true
output = "{folder / 'rec'}"
[rerun]
mode = "file"
path = "{folder / 'views.rrd'}"
[align]
stale_timeout = "20 s"
[monitor]
method = "soft-string"
band_mu = [0.1, 0.2, 0.3, 0.4]
[calibration]
enabled = true
profile_interval = "60 s"
""")
    log = folder / "daemon.log"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    with log.open("w") as err:
        done = subprocess.run([*TDMON, "run", "--config", str(config)], stderr=err,
                              stdout=subprocess.DEVNULL, env=env, timeout=240)
    assert done.returncode == 0, log.read_text()
    return Run(folder)


def test_every_topic_validates_against_the_schema_in_its_channel(run: Run) -> None:
    stored = schema_validators(schemas_of(run.mcap))
    counts: Counter[str] = Counter()
    for item in run.messages:
        stored[item.topic].validate(item.message)
        counts[item.topic] += 1
    assert dict(counts) == {t: n for t, n in topic_counts(run.mcap).items() if n}
    expected_topics = {"/tdmon/raw", "/tdmon/sample", "/tdmon/state", "/tdmon/model",
                       "/tdmon/estimate", "/tdmon/alarm", "/tdmon/status", "/tdmon/well",
                       "/tdmon/profile"}
    assert expected_topics <= set(counts)


def test_input_comes_back_one_for_one(run: Run) -> None:
    replay = [m.message for m in read_messages(REPLAY, "/tdmon/raw")]
    raw, samples = run.by_topic["/tdmon/raw"], run.by_topic["/tdmon/sample"]
    assert len(raw) == len(replay) == len(samples)  # simulated input: nothing rejected
    assert [r["payload"] for r in raw] == [r["payload"] for r in replay]
    for payload, sample in zip(raw, samples, strict=True):
        body = json.loads(payload["payload"])
        assert sample["t"] == body["t"]
        assert sample["value"] == pytest.approx(body["value"], rel=1e-12)


def test_well_and_profile_values(run: Run) -> None:
    config = load_well(WELL)
    well = config.to_model(WELL)
    grid = hole_grid(well)
    [message] = run.by_topic["/tdmon/well"]
    # once, at start-up, stamped with the first frame's time
    assert message["t"] == run.by_topic["/tdmon/state"][0]["t"]
    np.testing.assert_allclose(message["md_m"], grid.md)
    np.testing.assert_allclose(message["tvd_m"], grid.tvd)
    np.testing.assert_allclose(message["north_m"], grid.north)
    np.testing.assert_allclose(message["east_m"], grid.east)
    profiles = run.by_topic["/tdmon/profile"]
    assert len(profiles) >= 3  # start-up, updates while tripping, the end
    times = [p["t"] for p in profiles]
    assert times == sorted(times) and min(np.diff(times)) >= 60.0 - 1e-9  # rate-limited
    md = np.asarray(profiles[0]["md_m"])
    np.testing.assert_allclose(md, grid.element_mid_md)
    temperature = config.annulus_temperature(well, md, WELL).annulus
    for profile in profiles:
        np.testing.assert_allclose(profile["temperature_C"], temperature, rtol=1e-12)
        assert len(profile["mu"]) == len(profile["mu_std"]) == md.size
    # the last profile is the calibration's final friction profile, bins mapped to elements
    last_estimate = run.estimates("profile")[-1]
    edges_mid = np.asarray(last_estimate["md_m"])
    nearest = np.abs(md[:, None] - edges_mid[None, :]).argmin(axis=1)
    np.testing.assert_allclose(profiles[-1]["mu"],
                               np.asarray(last_estimate["mu_profile"])[nearest], atol=1e-12)
    # the Glydril open hole is calibrated from its own law
    mu_t = run.estimates("mu_T")
    assert mu_t and all(set(m["params"]) == {"a", "b"} for m in mu_t)


def _rrd(path: Path) -> tuple[dict[str, int], dict[str, set[str]]]:
    reader = RrdReader(path)
    [recording] = reader.recordings()
    assert recording.application_id == "tdmon"
    rows: dict[str, int] = defaultdict(int)
    timelines: dict[str, set[str]] = defaultdict(set)
    for chunk in reader.stream().to_chunks():
        if chunk.is_static:
            timelines[chunk.entity_path].add("static")
            continue
        rows[chunk.entity_path] += chunk.num_rows
        timelines[chunk.entity_path].update(chunk.timeline_names)
    return dict(rows), dict(timelines)


def test_rrd_holds_what_the_daemon_logged(run: Run) -> None:
    rows, timelines = _rrd(run.rrd)
    models = run.by_topic["/tdmon/model"]
    measured = sum(1 for m in models if m["measured"]["hookload_N"] is not None)
    assert rows["/hookload_kN/measured"] == measured
    assert rows["/hookload_kN/model/pick_up"] == len(models)
    assert rows["/vs_depth/hookload_kN/model/pick_up"] == len(models)
    assert timelines["/hookload_kN/model/pick_up"] == {"time", "static"}
    assert timelines["/vs_depth/hookload_kN/model/pick_up"] == {"bit_depth_cm", "static"}
    samples = Counter(s["channel"] for s in run.by_topic["/tdmon/sample"])
    for channel, count in samples.items():
        assert rows[f"/samples/{channel}"] == count, channel
    windows = run.estimates("window")
    for operation, count in Counter(w["operation"] for w in windows).items():
        assert rows[f"/friction/{operation}"] == count, operation
    joint = run.estimates("joint")
    assert rows["/friction/joint"] == rows["/weight_factor"] == len(joint) > 0
    joint = run.estimates("joint")
    assert rows["/friction/joint"] == rows["/weight_factor"] == len(joint) > 0
    mu_t = run.estimates("mu_T")
    assert rows["/friction_mu_T/a"] == rows["/friction_mu_T/b"] == len(mu_t)
    assert rows["/alarms"] == len(run.by_topic["/tdmon/alarm"])
    # profiles: the temperature from every profile message, the friction from those and from
    # every profile estimate; the well once, static
    profiles = run.by_topic["/tdmon/profile"]
    assert rows["/profile/temperature_C"] == len(profiles)
    assert rows["/profile/friction"] == len(profiles) + len(run.estimates("profile"))
    assert timelines["/profile/temperature_C"] == {"time"}
    assert "/well/trajectory" not in rows and timelines["/well/trajectory"] == {"static"}
    assert rows["/well/friction"] == rows["/profile/friction"]
    assert rows["/well/string"] >= 9 and rows["/well/bit"] == rows["/well/string"]
    states = [s["state"] for s in run.by_topic["/tdmon/state"]]
    changes = 1 + sum(1 for a, b in itertools.pairwise(states) if a != b)
    assert rows["/rig_state"] == changes
    assert rows["/status/samples_in"] == len(run.by_topic["/tdmon/status"])
