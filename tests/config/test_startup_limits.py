"""Start-up files a user (or an attacker) writes wrong on purpose (issue 32, fault 10): nesting
too deep for the parser, an empty survey, a well 1e300 m deep, a million survey stations, a
duration of 1e308 s, a queue of 10**30. Each is refused with one line naming the file, the key
and the bound (``tdmon.config.limits``), never a traceback, a hang or an overflow later."""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tdmon.config.daemon import load_daemon_config
from tdmon.config.limits import (
    MAX_MEASURED_DEPTH,
    MAX_QUEUE,
    MAX_SURVEY_STATIONS,
    MAX_TOML_BYTES,
)
from tdmon.config.well import load_well, load_well_model
from tdmon.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
EXAMPLE_STATIONS = """stations = [
    [0.0, 0.0, 0.0],
    [1500.0, 0.0, 0.0],
    [2023.5988, 60.0, 0.0],
    [4223.5988, 60.0, 0.0],
]"""


def _well(tmp_path: Path, old: str, new: str) -> Path:
    text = EXAMPLE.read_text()
    assert old in text, old
    path = tmp_path / "well.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def _refusal(load: object, path: Path) -> ConfigError:
    with pytest.raises(ConfigError) as caught:
        load(path)  # type: ignore[operator]
    assert "\n" not in str(caught.value)
    return caught.value


@pytest.mark.parametrize("text", [
    "a = " + "[" * 5000 + "]" * 5000 + "\n",
    "y = " + "{z = " * 3000 + "1" + "}" * 3000 + "\n",
])
def test_nesting_too_deep_is_a_syntax_error_not_a_recursion_error(tmp_path: Path,
                                                                  text: str) -> None:
    path = tmp_path / "well.toml"
    path.write_text(text)
    error = _refusal(load_well, path)
    assert error.key == ""
    assert error.reason.startswith("not valid TOML: arrays or tables nested too deeply")


def test_file_over_the_size_bound_is_refused_before_parsing(tmp_path: Path) -> None:
    # 60 000 stations of 20 characters: 1.2 MB, over the 1 MiB bound; tomllib would take
    # seconds to parse it on a loaded machine, a million stations over a minute
    rows = "".join(f"[{index * 0.1:.1f}, 0.0, 0.0],\n" for index in range(60_000))
    path = _well(tmp_path, EXAMPLE_STATIONS, "stations = [\n" + rows + "]")
    assert path.stat().st_size > MAX_TOML_BYTES
    error = _refusal(load_well, path)
    assert error.reason.startswith("larger than 1024 KiB")
    assert "[survey] file" in error.reason


@pytest.mark.parametrize(("stations", "count"), [("stations = []", 0),
                                                 ("stations = [[0.0, 0.0, 0.0]]", 1)])
def test_a_survey_needs_two_stations(tmp_path: Path, stations: str, count: int) -> None:
    error = _refusal(load_well, _well(tmp_path, EXAMPLE_STATIONS, stations))
    assert error.key == "survey.stations"
    assert error.reason.startswith(f"{count} station")
    assert "at least two" in error.reason


def test_survey_csv_over_the_station_bound(tmp_path: Path) -> None:
    rows = "".join(f"{index * 0.1:.1f},0,0\n" for index in range(MAX_SURVEY_STATIONS + 1))
    (tmp_path / "survey.csv").write_text("md_m,incl_deg,azi_deg\n" + rows)
    path = _well(tmp_path, EXAMPLE_STATIONS, 'file = "survey.csv"')
    error = _refusal(load_well_model, path)
    assert error.key == "survey.file"
    assert f"{MAX_SURVEY_STATIONS + 1} stations, more than the {MAX_SURVEY_STATIONS}" in (
        error.reason)


@pytest.mark.parametrize(("old", "new", "key"), [
    ('[4223.5988, 60.0, 0.0],', '[1e300, 60.0, 0.0],', "survey.stations"),
    ('bottom = "4223.5988 m"', 'bottom = "1e300 m"', "hole[0].bottom"),
    ('length = "4023.5988 m"', 'length = "1e300 m"', "string[1].length"),
])
def test_a_well_deeper_than_the_bound(tmp_path: Path, old: str, new: str, key: str) -> None:
    error = _refusal(load_well_model, _well(tmp_path, old, new))
    assert error.key == key
    assert error.reason == (f"1e+300 m is deeper than {MAX_MEASURED_DEPTH:g} m, the deepest "
                            "measured depth accepted (the longest wells reach about 15 km)")


def test_an_element_length_making_too_many_elements(tmp_path: Path) -> None:
    error = _refusal(load_well, _well(tmp_path, 'element_length = "10 m"',
                                      'element_length = "1 mm"'))
    assert error.key == "well.element_length"
    assert error.reason.startswith("0.001 m makes 4.22e+06 elements down to 4223.6 m")


def test_the_deepest_accepted_well_still_loads(tmp_path: Path) -> None:
    well = load_well_model(_well(tmp_path, '[4223.5988, 60.0, 0.0],',
                                 f'[{MAX_MEASURED_DEPTH}, 60.0, 0.0],'))
    assert well.survey.md[-1] == MAX_MEASURED_DEPTH


def _daemon(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "daemon.toml"
    path.write_text('prefix = "rig/T1"\n[sources.mcap]\npath = "x.mcap"\n' + body)
    return path


@pytest.mark.parametrize(("body", "key", "reason"), [
    ('[recorder]\nflush_interval = "1e308 s"\n', "recorder.flush_interval",
     "1e+308 s is longer than a week (604800 s)"),
    ('[align]\nstale_timeout = "8 d"\n', "align.stale_timeout",
     "691200 s is longer than a week"),
    ("[queues]\ningest = 1e30\n", "queues.ingest",
     f"1e+30 is more than {MAX_QUEUE} messages"),
    ("[queues]\npublish = 1000000000000000000\n", "queues.publish",
     f"1e+18 is more than {MAX_QUEUE} messages"),
    ("[queues]\nmax_payload_bytes = 1e12\n", "queues.max_payload_bytes",
     "1e+12 is more than 16777216 bytes"),
])
def test_daemon_durations_and_queues_are_bounded(tmp_path: Path, body: str, key: str,
                                                 reason: str) -> None:
    error = _refusal(load_daemon_config, _daemon(tmp_path, body))
    assert error.key == key
    assert error.reason.startswith(reason)


def test_the_bounds_themselves_are_accepted(tmp_path: Path) -> None:
    config = load_daemon_config(_daemon(
        tmp_path, f'[recorder]\nflush_interval = "7 d"\n[queues]\ningest = {MAX_QUEUE}\n'))
    assert config.recorder.flush_interval == 7 * 86400.0
    assert config.queues.ingest == MAX_QUEUE


def test_tdmon_run_refuses_a_huge_well_file_in_one_line(tmp_path: Path) -> None:
    """The issue's case end to end: a well file of a million stations (20 MB) made ``tdmon
    run`` parse for over a minute; now one line and exit 2, the file never parsed."""
    rows = "[0.0, 0.0, 0.0],\n" * 1_000_000
    well = _well(tmp_path, EXAMPLE_STATIONS, "stations = [\n" + rows + "]")
    config = tmp_path / "daemon.toml"
    config.write_text(f'prefix = "rig/T1"\nwell = "{well}"\n[sources.mcap]\n'
                      f'path = "{ROOT / "replays" / "faults-limits.mcap"}"\n')
    result = subprocess.run([sys.executable, "-m", "tdmon", "run", "--config", str(config)],
                            capture_output=True, text=True, timeout=120, cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    errors = [line for line in result.stderr.splitlines() if "error" in line]
    assert errors == [f"tdmon: error: {well}: larger than 1024 KiB, the most a TOML file of "
                      "tdmon may hold (a long survey belongs in a CSV file: [survey] file)"]


# -- MQTT credentials without TLS (issue 32, fault 11) ----------------------------------------

@pytest.mark.parametrize(("host", "tls", "warned"), [
    ("10.20.0.5", False, True), ("broker.rig.example", False, True),
    ("10.20.0.5", True, False), ("127.0.0.1", False, False), ("localhost", False, False),
    ("::1", False, False),
])
def test_credentials_without_tls_off_this_machine_warn(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch,
        host: str, tls: bool, warned: bool) -> None:
    (tmp_path / "ca.crt").write_text("x")
    path = tmp_path / "daemon.toml"
    path.write_text(f'prefix = "rig/T1"\n[sources.mqtt]\nhost = "{host}"\nusername = "rig"\n'
                    'password_env = "TDMON_TEST_PASSWORD"\n'
                    + ('[sources.mqtt.tls]\nca_file = "ca.crt"\n' if tls else ""))
    caplog.set_level(logging.WARNING, logger="tdmon.config.daemon")
    monkeypatch.setenv("TDMON_TEST_PASSWORD", "secret")
    load_daemon_config(path)
    lines = [record.getMessage() for record in caplog.records]
    expected = [f"sources.mqtt: the user name and password go to {host}:1883 in clear text "
                "(no [sources.mqtt.tls]); anyone on the network path can read them"]
    assert lines == (expected if warned else [])
