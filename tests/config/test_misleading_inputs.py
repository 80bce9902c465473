"""Configuration that used to mislead silently (issue 13, item 8): plain numbers for dimensional
keys, three friction limits, surveys in radians; and the password keys of item 5."""

from __future__ import annotations

import logging
import math
import re
from pathlib import Path

import numpy as np
import pytest

from tdmon.cli import main
from tdmon.config.common import MAX_FRICTION
from tdmon.config.daemon import MqttConfig, load_daemon_config, parse_daemon_config
from tdmon.config.scenario import load_scenario
from tdmon.config.well import WellInfo, load_well, load_well_model, looks_like_radians
from tdmon.errors import ConfigError
from tdmon.model.torque_drag import torque_drag

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"


def _example_with(tmp_path: Path, old: str, new: str, name: str = "well.toml") -> Path:
    text = EXAMPLE.read_text()
    assert old in text, old
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


# -- dimensional keys need a unit -------------------------------------------------------------

def test_block_weight_without_unit_names_the_key_and_an_example(tmp_path: Path) -> None:
    path = _example_with(tmp_path, 'block_weight = "0 kN"', "block_weight = 655")
    with pytest.raises(ConfigError) as caught:
        load_well(path)
    assert caught.value.key == "well.block_weight"
    assert caught.value.reason == '655 has no unit; write the unit, e.g. block_weight = "655 kN"'
    # with the unit it is 655 kN, not 655 N (the 654 kN the plain number lost)
    path = _example_with(tmp_path, 'block_weight = "0 kN"', 'block_weight = "655 kN"')
    assert load_well_model(path).block_weight == pytest.approx(655e3)


@pytest.mark.parametrize(("old", "new", "key"), [
    ('block_weight = "0 kN"', "block_weight = 0", "well.block_weight"),        # zero too
    ('block_weight = "0 kN"', 'block_weight = "655"', "well.block_weight"),    # a text number
    ('element_length = "10 m"', "element_length = 10", "well.element_length"),
    ('diameter = "8.5 in"', "diameter = 0.2159", "hole[0].diameter"),
    ('buoyed_weight = "0.3 kN/m"', "buoyed_weight = 300", "string[1].buoyed_weight"),
    ('makeup_torque = "40 kN*m"', "makeup_torque = 40000", "string[1].makeup_torque"),
    ('density = "1.2 sg"', "density = 1200", "fluid.density"),
    ('geothermal_gradient = "0.0127 degF/ft"', "geothermal_gradient = 0.023",
     "temperature.geothermal_gradient"),
])
def test_every_dimensional_well_key_needs_its_unit(tmp_path: Path, old: str, new: str,
                                                   key: str) -> None:
    source = ROOT / "config" / "wells" / "thesis-case2-geothermal.toml"
    text = source.read_text()
    if old not in text:
        text = EXAMPLE.read_text()
    assert old in text, old
    path = tmp_path / "well.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(ConfigError, match=re.escape("has no unit; write the unit")) as caught:
        load_well(path)
    assert caught.value.key == key


def test_dimensionless_keys_stay_plain_numbers(tmp_path: Path) -> None:
    config = load_well(EXAMPLE)
    assert config.limits.safety_factor == 1.25  # plain in the file
    assert config.hole[0].friction is not None
    assert config.hole[0].friction.constant_value() == pytest.approx(0.15)


def test_python_callers_still_pass_si_floats() -> None:
    """The unit rule is for files; code building the models passes SI (the internal unit)."""
    assert WellInfo(block_weight=655e3).block_weight == 655e3


def _daemon(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "daemon.toml"
    path.write_text('prefix = "rig/T1"\n[sources.mcap]\npath = "x.mcap"\n' + body)
    return path


@pytest.mark.parametrize(("body", "key", "example"), [
    ("[publish]\nstatus_interval = 1\n", "publish.status_interval", 'status_interval = "1 s"'),
    ("[align]\nstale_timeout = 30\n", "align.stale_timeout", 'stale_timeout = "30 s"'),
    ("[rig_state]\nin_slips_hookload = 800\n", "rig_state.in_slips_hookload",
     'in_slips_hookload = "800 kN"'),
    ("[calibration]\nin_slips_margin = 200\n", "calibration.in_slips_margin",
     'in_slips_margin = "200 kN"'),
    ("[channels.hookload]\nmin = -100\n", "channels.hookload.min", 'min = "-100 kN"'),
    ("[channels.mud_temp_in]\nmax = '90'\n", "channels.mud_temp_in.max", 'max = "90 degC"'),
])
def test_daemon_file_dimensional_keys_need_units(tmp_path: Path, body: str, key: str,
                                                 example: str) -> None:
    with pytest.raises(ConfigError) as caught:
        load_daemon_config(_daemon(tmp_path, body))
    assert caught.value.key == key
    assert caught.value.reason.endswith(f"e.g. {example}")


def test_daemon_file_with_units_reads_si(tmp_path: Path) -> None:
    config = load_daemon_config(_daemon(
        tmp_path, '[rig_state]\nin_slips_hookload = "800 kN"\n[align]\nmax_wait = "250 ms"\n'
                  '[channels.hookload]\nmin = "-100 kN"\n'))
    assert config.rig_state.in_slips_hookload == pytest.approx(800e3)
    assert config.align.max_wait == pytest.approx(0.25)
    assert config.channel_specs()[0].minimum == pytest.approx(-100e3)
    # defaults need no unit (they are SI in the code)
    assert config.publish.status_interval == 1.0


def test_scenario_keys_need_units(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    path.write_text('[scenario]\nwell = "w.toml"\nbit_depth = "100 m"\n'
                    '[[phase]]\nkind = "static"\nduration = 10\n')
    with pytest.raises(ConfigError, match=r'phase\[0\]\.duration: 10 has no unit; write the '
                                          r'unit, e.g. duration = "10 s"'):
        load_scenario(path)


@pytest.mark.parametrize("pattern", ["config/wells/*.toml", "config/daemon/*.toml",
                                     "replays/scenarios/*.toml", "replays/scenarios/wells/*.toml"])
def test_bundled_files_carry_their_units(pattern: str) -> None:
    """Every bundled file reads under the rule (a plain number would raise)."""
    files = sorted(ROOT.glob(pattern))
    assert files
    for path in files:
        if "daemon" in pattern:
            load_daemon_config(path)
        elif pattern == "replays/scenarios/*.toml":
            load_scenario(path)
        else:
            load_well_model(path)


# -- one friction rule ------------------------------------------------------------------------

def test_one_friction_limit_in_well_file_daemon_file_and_command_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    reason = f"friction factor 1.5 is outside 0-{MAX_FRICTION:g}"
    well = _example_with(tmp_path, "friction = 0.15", "friction = 1.5")
    with pytest.raises(ConfigError, match=re.escape(reason)) as caught:
        load_well(well)
    assert caught.value.key == "hole[0].friction"
    with pytest.raises(ConfigError, match=re.escape(reason)) as caught:
        load_daemon_config(_daemon(tmp_path, "[monitor]\nmu = 1.5\n"))
    assert caught.value.key == "monitor.mu"
    with pytest.raises(ConfigError, match=re.escape(reason)) as caught:
        load_daemon_config(_daemon(tmp_path, "[monitor]\nband_mu = [0.2, 1.5]\n"))
    assert caught.value.key == "monitor.band_mu[1]"
    with pytest.raises(SystemExit) as exited:  # argparse's usage error: exit 2
        main(["model", "loads", "--well", str(EXAMPLE), "--mu", "1.5"])
    assert exited.value.code == 2
    assert f"argument --mu: {reason}" in capsys.readouterr().err
    # the bound itself is accepted everywhere
    load_well(_example_with(tmp_path, "friction = 0.15", "friction = 1.0"))
    assert load_daemon_config(_daemon(tmp_path, "[monitor]\nmu = 1.0\n")).monitor.mu == 1.0
    assert main(["model", "loads", "--well", str(EXAMPLE), "--mu", "1.0", "--json"]) == 0
    # and a table law's constant too
    law = _example_with(tmp_path, "friction = 0.15", "friction = { family = 'constant', mu = 5 }")
    with pytest.raises(ConfigError, match="friction factor 5 is outside 0-1"):
        load_well(law)


# -- surveys state their angle unit -----------------------------------------------------------

STATIONS_DEG = [[0.0, 0.0, 0.0], [1500.0, 0.0, 0.0], [2023.5988, 60.0, 0.0],
                [4223.5988, 60.0, 0.0]]


def _stations(rows: list[list[float]]) -> str:
    return "stations = [\n" + "".join(f"    {row},\n" for row in rows) + "]\n"


def _with_survey(tmp_path: Path, survey: str, name: str) -> Path:
    text = EXAMPLE.read_text()
    start = text.index("[survey]")
    end = text.index("[[hole]]")
    path = tmp_path / name
    path.write_text(text[:start] + "[survey]\n" + survey + "\n" + text[end:])
    return path


def test_survey_in_radians_without_a_unit_is_refused(tmp_path: Path) -> None:
    radians = [[md, math.radians(inc), math.radians(azi)] for md, inc, azi in STATIONS_DEG]
    path = _with_survey(tmp_path, _stations(radians), "rad.toml")
    with pytest.raises(ConfigError) as caught:
        load_well_model(path)
    assert caught.value.key == "survey.stations"
    assert "look like radians" in caught.value.reason
    assert 'angle_unit = "rad" or "deg"' in caught.value.reason


def test_survey_in_radians_with_its_unit_gives_the_degree_well(tmp_path: Path) -> None:
    """The issue's case: radians read as degrees gave a near-vertical well (865 kN instead
    of 770 kN); stated as radians the loads are those of the degree file."""
    radians = [[md, math.radians(inc), math.radians(azi)] for md, inc, azi in STATIONS_DEG]
    rad = load_well_model(_with_survey(tmp_path, 'angle_unit = "rad"\n' + _stations(radians),
                                       "rad.toml"))
    deg = load_well_model(EXAMPLE)
    np.testing.assert_allclose(rad.survey.tvd, deg.survey.tvd, rtol=1e-12, atol=1e-9)
    depth = 4000.0
    assert torque_drag(rad, depth, 0.25).hookload["pick_up"] == pytest.approx(
        torque_drag(deg, depth, 0.25).hookload["pick_up"], rel=1e-12)
    # read as degrees, the same numbers are a well within 1.05 deg of vertical
    misread = load_well_model(_with_survey(tmp_path, 'angle_unit = "deg"\n' + _stations(radians),
                                           "misread.toml"))
    assert misread.survey.tvd[-1] > deg.survey.tvd[-1] + 1000.0


def test_degree_surveys_without_a_unit_still_read(tmp_path: Path) -> None:
    # a deviated well in degrees, and a near-vertical one whose azimuths wander (as they do)
    load_well_model(_with_survey(tmp_path, _stations(STATIONS_DEG), "deg.toml"))
    vertical = [[0.0, 0.0, 0.0], [1000.0, 0.8, 145.0], [2000.0, 1.2, 210.0],
                [4300.0, 0.9, 33.0]]
    load_well_model(_with_survey(tmp_path, _stations(vertical), "vertical.toml"))


def test_radian_heuristic() -> None:
    assert looks_like_radians([0.0, 0.3, 1.05, 1.05], [0.0, 2.0, 2.1, 6.2])
    assert not looks_like_radians([0.0, 0.0], [0.0, 0.0])          # vertical: same either way
    assert not looks_like_radians([0.0, 1.0, 3.5], [0.0, 1.0, 2.0])  # 3.5 > pi: degrees
    assert not looks_like_radians([0.0, 1.0, 1.2], [0.0, 7.0, 2.0])  # 7 > 2 pi: degrees
    assert looks_like_radians([0.0, 0.5], [-3.0, 3.1])              # signed azimuths


def test_csv_survey_states_its_unit_in_the_header(tmp_path: Path) -> None:
    rows = [(md, math.radians(inc), math.radians(azi)) for md, inc, azi in STATIONS_DEG]

    def csv(name: str, header: str) -> str:
        (tmp_path / name).write_text(header + "\n" + "".join(
            f"{md},{inc!r},{azi!r}\n" for md, inc, azi in rows))
        return name

    unstated = _with_survey(tmp_path, f'file = "{csv("plain.csv", "md,incl,azi")}"\n'
                            'md_column = "md"\ninclination_column = "incl"\n'
                            'azimuth_column = "azi"\n', "plain.toml")
    with pytest.raises(ConfigError, match=r"survey\.file \(.*plain\.csv\): the angles look like "
                                          "radians"):
        load_well_model(unstated)
    stated = _with_survey(tmp_path, f'file = "{csv("rad.csv", "md_m,incl_rad,azi_rad")}"\n'
                          'inclination_column = "incl_rad"\nazimuth_column = "azi_rad"\n',
                          "stated.toml")
    assert load_well_model(stated).survey.tvd[-1] == pytest.approx(
        load_well_model(EXAMPLE).survey.tvd[-1], rel=1e-12)
    contradicting = _with_survey(tmp_path, f'file = "{csv("rad2.csv", "md_m,incl_rad,azi_rad")}"'
                                 '\nangle_unit = "deg"\ninclination_column = "incl_rad"\n'
                                 'azimuth_column = "azi_rad"\n', "contra.toml")
    with pytest.raises(ConfigError, match="'deg' contradicts the column 'incl_rad'"):
        load_well_model(contradicting)


# -- passwords ----------------------------------------------------------------------------

@pytest.mark.parametrize("section", ["sources.mqtt", "publish.mqtt"])
def test_password_keys_are_exclusive(tmp_path: Path, section: str) -> None:
    # [publish.mqtt] is `true` or a table: the table's problem is reported, not "not a bool"
    with pytest.raises(ConfigError) as caught:
        load_daemon_config(_daemon(tmp_path, f'[{section}]\npassword = "a"\n'
                                             'password_file = "pw"\n'))
    assert caught.value.key == section
    assert caught.value.reason == ("give one of password, password_env and password_file, "
                                   "not password and password_file")


def test_unset_password_variable_of_the_publisher_is_named(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("TDMON_TEST_UNSET_PW", raising=False)
    with pytest.raises(ConfigError) as caught:
        load_daemon_config(_daemon(tmp_path, '[publish.mqtt]\npassword_env = '
                                             '"TDMON_TEST_UNSET_PW"\n'))
    assert (caught.value.key, caught.value.reason) == (
        "publish.mqtt.password_env", "environment variable TDMON_TEST_UNSET_PW is not set")
    monkeypatch.setenv("TDMON_TEST_UNSET_PW", "pw")
    config = load_daemon_config(_daemon(tmp_path, '[publish.mqtt]\npassword_env = '
                                                  '"TDMON_TEST_UNSET_PW"\n'))
    assert isinstance(config.publish.mqtt, MqttConfig)
    assert config.publish.mqtt.resolved_password() == "pw"


def test_password_file_is_relative_to_the_daemon_file_and_read_per_connection(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    secret = tmp_path / "mqtt.pw"
    secret.write_text("s3cret\n")
    secret.chmod(0o600)
    with caplog.at_level(logging.WARNING):
        config = load_daemon_config(_daemon(tmp_path, '[publish.mqtt]\npassword_file = '
                                                      '"mqtt.pw"\n'))
    assert not caplog.records
    assert isinstance(config.publish.mqtt, MqttConfig)
    assert config.publish.mqtt.password_file == secret
    assert config.publish.mqtt.resolved_password() == "s3cret"
    secret.write_text("changed\n")
    assert config.publish.mqtt.resolved_password() == "changed"


def test_missing_password_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as caught:
        load_daemon_config(_daemon(tmp_path, '[publish.mqtt]\npassword_file = "absent.pw"\n'))
    assert caught.value.key == "publish.mqtt.password_file"
    assert caught.value.reason == f"{tmp_path / 'absent.pw'}: no such file"
    (tmp_path / "empty.pw").write_text("\n")
    with pytest.raises(ConfigError, match=r"empty\.pw: the first line is empty"):
        load_daemon_config(_daemon(tmp_path, '[publish.mqtt]\npassword_file = "empty.pw"\n'))


def test_clear_text_password_readable_by_others_is_one_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    secret = tmp_path / "mqtt.pw"
    secret.write_text("s3cret\n")
    secret.chmod(0o644)
    with caplog.at_level(logging.WARNING, logger="tdmon.config.daemon"):
        load_daemon_config(_daemon(tmp_path, '[publish.mqtt]\npassword_file = "mqtt.pw"\n'))
    assert [r.getMessage() for r in caplog.records] == [
        f"{secret} holds a clear-text password (publish.mqtt.password_file) and is readable by "
        f"others (mode 644): chmod 600 {secret}"]
    caplog.clear()
    # the daemon file itself, when it holds `password = "..."`
    path = _daemon(tmp_path, '[publish.mqtt]\npassword = "s3cret"\n')
    path.chmod(0o640)
    with caplog.at_level(logging.WARNING, logger="tdmon.config.daemon"):
        load_daemon_config(path)
    assert len(caplog.records) == 1 and "(password)" in caplog.records[0].getMessage()
    caplog.clear()
    path.chmod(0o600)
    with caplog.at_level(logging.WARNING, logger="tdmon.config.daemon"):
        load_daemon_config(path)
    assert not caplog.records


def test_tls_file_missing_is_named_with_its_resolved_path(tmp_path: Path) -> None:
    data = {"prefix": "rig/T1", "sources": {"mqtt": {"tls": {"ca_file": "certs/ca.crt"}}}}
    with pytest.raises(ConfigError) as caught:
        parse_daemon_config(data, tmp_path / "d.toml")
    assert caught.value.key == "sources.mqtt.tls.ca_file"
    assert caught.value.reason == f"no such file: {(tmp_path / 'certs' / 'ca.crt').resolve()}"


def test_scenario_absolute_noise_is_per_channel_with_its_unit(tmp_path: Path) -> None:
    head = ('[scenario]\nwell = "w.toml"\nbit_depth = "100 m"\n'
            '[[phase]]\nkind = "static"\nduration = "10 s"\n')
    path = tmp_path / "s.toml"
    path.write_text(head + '[noise.channels.bit_depth]\nabsolute = "5 mm"\n'
                    '[noise.channels.hookload]\nabsolute = "2 kN"\n')
    noise = load_scenario(path).noise
    assert noise.for_channel("bit_depth").absolute == pytest.approx(0.005)
    assert noise.for_channel("hookload").absolute == pytest.approx(2000.0)
    path.write_text(head + "[noise.channels.bit_depth]\nabsolute = 0.005\n")
    with pytest.raises(ConfigError, match=r'noise\.channels\.bit_depth\.absolute: 0\.005 has '
                                          r'no unit; write the unit, e\.g\. absolute = "0\.005 m"'):
        load_scenario(path)
    path.write_text(head + "[noise]\nabsolute = 0.005\n")
    with pytest.raises(ConfigError, match=r"noise\.absolute: the absolute noise is in each "
                                          r"channel's unit"):
        load_scenario(path)
