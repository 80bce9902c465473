"""Live mu(T) calibration in the daemon: a simulated trip from TD with the Glydril law
(mu = 0.23 + 0.0013 T, Kaarstad et al. 2009) on Example 7.1 with a geothermal profile, replayed
through ``tdmon run`` (MCAP source, flat out), gives ``mu_T`` estimates whose slope is within
25 % of the truth, from a prior that knows nothing about temperature (b = 0).

The daemon runs as its own process with one BLAS thread: the friction-profile filter's small
matrix products are 5-10 x slower with OpenBLAS's threads competing for two busy cores (a
replay measured 70 s against 8 s), and a test process cannot change that once numpy is loaded.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

from tdmon.config.well import load_well
from tdmon.model.well import hole_grid
from tdmon.record.reader import read_messages
from tdmon.record.schemas import TOPIC_SCHEMAS
from tdmon.replay.scenario import load_scenario_model
from tdmon.replay.simulate import simulate_to_mcap

TRUTH_SLOPE = 0.0013  # Glydril, 1/K
TDMON = [sys.executable, "-m", "tdmon"]

# Example 7.1 (Aadnoy) with a 300 kN block, open hole to TD, Glydril friction at the geothermal
# temperature (15.3 degC at surface, 85.5 degC at 3033 m TVD; docs/reference-values.md §2). 40 m
# elements keep the replay short; the truth and the daemon share the grid.
WELL = """
[well]
name = "Example 7.1, Glydril mu(T), geothermal"
element_length = "40 m"
block_weight = "300 kN"

[survey]
stations = [[0.0, 0.0, 0.0], [1500.0, 0.0, 0.0], [2023.5988, 60.0, 0.0],
            [4223.5988, 60.0, 0.0]]

[[hole]]
name = "open hole"
kind = "open"
top = "0 m"
bottom = "4223.5988 m"
diameter = "8.5 in"
friction = FRICTION

[[string]]
name = "BHA"
length = "200 m"
od = "0.16 m"
id = "2.8125 in"
buoyed_weight = "3 kN/m"
tool_joint_od = "0.16 m"

[[string]]
name = "drill pipe"
length = "4023.5988 m"
od = "5 in"
id = "4.276 in"
buoyed_weight = "0.3 kN/m"
tool_joint_od = "0.16 m"

[fluid]
density = "13 ppg"
"""

TEMPERATURE = """
[temperature]
model = "geothermal"
surface_temperature = "59.5 degF"
geothermal_gradient = "0.0127 degF/ft"
"""

SCENARIO = """
[scenario]
name = "mu-t-trip-from-td"
well = "truth-well.toml"
seed = 5
start = "2024-03-01T06:00:00Z"
prefix = "sim/mut"
bit_depth = "4200 m"
hole_depth = "4223.5 m"
block_position = "2 m"

[friction]
temperature_model = "well"

[sampling]
interval = "5 s"
[sampling.intervals]
hookload = "1 s"
bit_depth = "1 s"
block_position = "1 s"

[noise]
relative = 0.003

[[phase]]
kind = "static"
duration = "1 min"

[[phase]]
kind = "trip_out"
to = "1700 m"
speed = "0.5 m/s"
slips_time = "40 s"

[[phase]]
kind = "static"
duration = "1 min"
"""


def write_well(path: Path, friction: str, temperature: bool = True) -> Path:
    path.write_text(WELL.replace("FRICTION", friction) + (TEMPERATURE if temperature else ""))
    return path


def daemon_config(folder: Path, well: Path, replay: Path, extra: str = "") -> Path:
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "sim/mut"
well = "{well}"
[sources.mcap]
path = "{replay}"
speed = "max"
[recorder]
enabled = true
output = "{folder / 'rec'}"
flush_interval = "1 s"
[align]
stale_timeout = "20 s"
[monitor]
method = "soft-string"
[calibration]
enabled = true
{extra}
""")
    return path


def run_daemon(config: Path, log: Path) -> str:
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    with log.open("w") as err:
        done = subprocess.run([*TDMON, "run", "--config", str(config)], stderr=err,
                              stdout=subprocess.DEVNULL, env=env, timeout=240)
    text = log.read_text()
    assert done.returncode == 0, text
    assert "Traceback" not in text
    return text


def recorded(folder: Path) -> list[tuple[str, dict[str, Any]]]:
    [path] = sorted((folder / "rec").glob("*.mcap"))
    return [(m.topic, m.message) for m in read_messages(path)]


@pytest.fixture(scope="module")
def trip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The simulated trip out from 4200 m to 1700 m (about 40,000 input messages)."""
    folder = tmp_path_factory.mktemp("mu-t-trip")
    write_well(folder / "truth-well.toml", '"kaarstad-glydril"')
    (folder / "scenario.toml").write_text(SCENARIO)
    replay = folder / "trip.mcap"
    simulate_to_mcap(load_scenario_model(folder / "scenario.toml"), replay)
    return replay


def test_slope_within_25_percent_of_the_truth(tmp_path: Path, trip: Path) -> None:
    # the daemon's well file knows the geometry and the temperatures, not the law
    well = write_well(tmp_path / "prior-well.toml", "{ family = \"linear\", a = 0.25, b = 0.0 }")
    config = daemon_config(tmp_path, well, trip, "mu_t_prior_std = [0.1, 0.005]")
    log = run_daemon(config, tmp_path / "daemon.log")
    assert "mu(T) calibration on: mu = 0.25 + 0 T (family mode)" in log
    messages = recorded(tmp_path)
    mu_t = [m for topic, m in messages if topic == "/tdmon/estimate" and m["kind"] == "mu_T"]
    assert len(mu_t) >= 100
    for message in mu_t:
        jsonschema.validate(message, TOPIC_SCHEMAS["/tdmon/estimate"])
        assert set(message["params"]) == {"a", "b"}  # keyed like the family's coefficients
        assert set(message["params_std"]) == {"a", "b"}
    last = mu_t[-1]
    assert last["params"]["b"] == pytest.approx(TRUTH_SLOPE, rel=0.25)
    assert last["params"]["a"] == pytest.approx(0.23, abs=0.03)
    assert last["identifiable"] is True, last["identifiability"]
    low, high = last["slope_interval_per_K"]
    assert 0.0 < low < last["slope_per_K"] < high
    assert last["temperature_C"][1] - last["temperature_C"][0] > 10.0
    # early on, one depth: the statement says the slope is not identified yet
    assert mu_t[0]["identifiable"] is False
    # no "calibration off" note when it runs
    [well_message] = [m for topic, m in messages if topic == "/tdmon/well"]
    assert well_message["notes"] == []
    # the profile carries the annulus temperatures the calibration used
    well_config = load_well(well)
    grid = hole_grid(well_config.to_model(well))
    [first_profile, *_] = [m for topic, m in messages if topic == "/tdmon/profile"]
    expected = well_config.annulus_temperature(well_config.to_model(well),
                                               np.asarray(first_profile["md_m"]), well).annulus
    np.testing.assert_allclose(first_profile["temperature_C"], expected, rtol=1e-9)
    assert len(first_profile["md_m"]) == grid.n_elements


def test_no_temperature_model_means_no_mu_t_said_once(tmp_path: Path, trip: Path) -> None:
    well = write_well(tmp_path / "no-temperature.toml", "0.25", temperature=False)
    config = daemon_config(tmp_path, well, trip)
    log = run_daemon(config, tmp_path / "daemon.log")
    assert log.count("mu(T) calibration is off") == 1
    assert "has no [temperature] table" in log
    messages = recorded(tmp_path)
    [well_message] = [m for topic, m in messages if topic == "/tdmon/well"]
    [note] = well_message["notes"]
    assert note.startswith("mu(T) calibration is off") and "[temperature]" in note
    jsonschema.validate(well_message, TOPIC_SCHEMAS["/tdmon/well"])
    estimates = [m for topic, m in messages if topic == "/tdmon/estimate"]
    assert estimates and not [m for m in estimates if m["kind"] == "mu_T"]
    assert {m["kind"] for m in estimates} == {"window", "profile", "joint"}
    # the profile then carries the friction alone
    profiles = [m for topic, m in messages if topic == "/tdmon/profile"]
    assert profiles and all("temperature_C" not in m and "mu" in m for m in profiles)
    json.dumps(profiles[-1], allow_nan=False)


def _parsed(folder: Path, calibration: dict[str, Any]) -> Any:
    from tdmon.config.daemon import parse_daemon_config

    well = write_well(folder / "well.toml", '"kaarstad-glydril"')
    data = {"prefix": "sim/mut", "well": str(well), "sources": {"mcap": {"path": "x.mcap"}},
            "calibration": {"enabled": True, **calibration}}
    return parse_daemon_config(data, folder / "daemon.toml")


def test_scale_mode_and_section_choice(tmp_path: Path) -> None:
    from tdmon.daemon.steps.calibrate import CalibrationStep
    from tdmon.daemon.steps.compose import calibration_steps_for
    from tdmon.errors import ConfigError

    config = _parsed(tmp_path, {"mu_t": "scale", "lab_fit": {"family": "linear", "a": 0.2,
                                                             "b": 0.001}})
    _, steps = calibration_steps_for(config)
    [calibration] = [s for s in steps if isinstance(s, CalibrationStep)]
    assert calibration.mu_t is not None
    assert calibration.mu_t.parametrisation.names == ("scale",)
    assert calibration.mu_t.params == {"a": 0.2, "b": 0.001}  # scale 1 to start with
    # the section by name or index; the deepest by default
    for section in ("open hole", 0, -1, None):
        _, steps = calibration_steps_for(_parsed(tmp_path, {"mu_t_section": section}))
        [calibration] = [s for s in steps if isinstance(s, CalibrationStep)]
        assert calibration.mu_t is not None and calibration.mu_t.params == {"a": 0.23,
                                                                            "b": 0.0013}
    with pytest.raises(ConfigError, match="no hole section named 'cased'"):
        calibration_steps_for(_parsed(tmp_path, {"mu_t_section": "cased"}))
    with pytest.raises(ConfigError, match="give 2 values"):
        calibration_steps_for(_parsed(tmp_path, {"mu_t_prior_std": [0.1]}))
    with pytest.raises(ConfigError, match="calibration: mu_t = 'scale' needs lab_fit"):
        _parsed(tmp_path, {"mu_t": "scale"})
    off = _parsed(tmp_path, {"mu_t": "off"})
    _, steps = calibration_steps_for(off)
    assert all(s.mu_t is None for s in steps if isinstance(s, CalibrationStep))
