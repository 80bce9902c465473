"""One reader for every TOML file (tdmon.config.common.load_model): the error mapping, the prefix
rule, and every bundled scenario, expectations, daemon and well file read through it."""

from __future__ import annotations

from pathlib import Path

import pytest
from pydantic import Field

from tdmon.channels import validate_prefix
from tdmon.config.column_map import load_column_map_config
from tdmon.config.common import StrictModel, load_model
from tdmon.config.daemon import load_daemon_config
from tdmon.config.expectations import load_expectations
from tdmon.config.scenario import CHANNELS, PHASE_KINDS, load_scenario
from tdmon.errors import ConfigError
from tdmon.vocabulary import RigState

REPO = Path(__file__).resolve().parents[2]


class _Item(StrictModel):
    name: str
    size: float = Field(gt=0)


class _File(StrictModel):
    items: list[_Item]
    count: int = 1


def _load(tmp_path: Path, text: str) -> _File:
    path = tmp_path / "f.toml"
    path.write_text(text)
    return load_model(_File, path)


def test_reader_validates_and_names_file_key_and_reason(tmp_path: Path) -> None:
    loaded = _load(tmp_path, '[[items]]\nname = "a"\nsize = 2.5\n')
    assert loaded.items[0].size == 2.5 and loaded.count == 1
    cases = {
        '[[items]]\nname = "a"\nsize = -1\n': "items[0].size: Input should be greater than 0",
        '[[items]]\nsize = 1\n': "items[0].name: missing key",
        '[[items]]\nname = "a"\nsize = 1\ncolour = 3\n': "items[0].colour: unknown key",
        'count = 1\n': "items: missing key",
        '[[items]]\nsize = -1\n': "items[0].name: missing key (and 1 more problem)",
        'items = [\n': "not valid TOML",
    }
    for text, message in cases.items():
        with pytest.raises(ConfigError) as caught:
            _load(tmp_path, text)
        assert str(tmp_path / "f.toml") in str(caught.value)
        assert message in str(caught.value), (text, str(caught.value))
    with pytest.raises(ConfigError, match="no such file"):
        load_model(_File, tmp_path / "absent.toml")


def test_expectations_and_scenarios_report_mistakes_alike(tmp_path: Path) -> None:
    """The expectations file had its own mapping (``friction.0``, pydantic's "Field required");
    it now reads like every other file."""
    bad = tmp_path / "bad.toml"
    bad.write_text('replay = "x"\nconfig = "y"\n[[friction]]\nmin = 0.2\n')
    with pytest.raises(ConfigError, match=r"bad\.toml: friction\[0\]\.operation: missing key"):
        load_expectations(bad)
    bad.write_text('replay = "x"\nconfig = "y"\n[states]\nrequired = ["tripping"]\n')
    with pytest.raises(ConfigError, match=r"states\.required\[0\]: Input should be 'in_slips'"):
        load_expectations(bad)
    bad.write_text('[scenario]\nwell = "w.toml"\nbit_depth = "100 m"\n[[phase]]\nkind = "fly"\n')
    with pytest.raises(ConfigError, match=r"bad\.toml: phase\[0\]\.kind: Input should be"):
        load_scenario(bad)


@pytest.mark.parametrize("prefix", ["rig/F4", "sim/trip-out", "/sim/drill/", "rig_1/F-4.b"])
def test_prefix_rule_accepts_plain_topic_paths(prefix: str) -> None:
    assert validate_prefix(prefix) == prefix.strip("/")


@pytest.mark.parametrize("prefix", ["", "/", "rig/#", "rig/+/x", "rig/*", "$SYS/rig", "rig F4",
                                    "rig/F4\t"])
def test_prefix_rule_refuses_wildcards_and_white_space(prefix: str) -> None:
    with pytest.raises(ValueError, match="plain topic path"):
        validate_prefix(prefix)


def test_one_prefix_rule_in_daemon_and_scenario_files(tmp_path: Path) -> None:
    daemon = tmp_path / "d.toml"
    daemon.write_text('prefix = "rig F4"\n[sources.mqtt]\n')
    with pytest.raises(ConfigError, match="prefix: prefix 'rig F4' must be a plain topic path"):
        load_daemon_config(daemon)
    scenario = tmp_path / "s.toml"
    scenario.write_text('[scenario]\nwell = "w.toml"\nbit_depth = "100 m"\nprefix = "sim/*"\n'
                        '[[phase]]\nkind = "static"\nduration = "10 s"\n')
    with pytest.raises(ConfigError,
                       match=r"scenario\.prefix: prefix 'sim/\*' must be a plain topic path"):
        load_scenario(scenario)


def test_every_bundled_scenario_and_expectations_file_reads() -> None:
    scenarios = sorted((REPO / "replays" / "scenarios").glob("*.toml"))
    assert len(scenarios) == 16
    prefixes = {load_scenario(path).scenario.prefix for path in scenarios}
    assert prefixes == {"sim/trip-out", "sim/trip-in", "sim/faults", "sim/drill",
                        "sim/model-error", "sim/sheave", "sim/shallow", "sim/fluids",
                        "sim/fluids-pill", "sim/fluids-ream", "sim/drilling"}
    for path in sorted((REPO / "replays" / "expectations").glob("*.toml")):
        expectations = load_expectations(path)
        assert expectations.replay_path.exists(), path
        assert expectations.config_path.exists(), path
        if expectations.states is not None:
            assert all(isinstance(state, RigState) for state in expectations.states.required)
    for path in sorted((REPO / "config" / "daemon").glob("*.toml")):
        assert load_daemon_config(path).prefix in {"rig/F4", "sim/trip-out", "sim/trip-in",
                                                    "sim/faults", "sim/drill",
                                                    "sim/model-error", "sim/sheave",
                                                    "sim/shallow", "sim/fluids",
                                                    "sim/fluids-pill", "sim/fluids-ream",
                                                    "sim/drilling",
                                                    "rig"}, path  # rig: fleet-zenoh.toml's root


def test_scenario_words() -> None:
    assert CHANNELS[:3] == ("hookload", "torque", "bit_depth") and len(CHANNELS) == 12
    assert "back_ream" in PHASE_KINDS and len(PHASE_KINDS) == 9


def test_column_map_reads_through_the_same_reader(tmp_path: Path) -> None:
    path = tmp_path / "map.toml"
    path.write_text('[time]\ncolumn = "TIME"\nutc_offset = "2 h"\n'
                    '[channels.hookload]\ncolumn = "HKLD"\nunit = "klbf"\n')
    config = load_column_map_config(path)
    assert config.time.utc_offset == 7200.0
    assert config.channels["hookload"].unit == "klbf"
    path.write_text('[time]\ncolumn = "TIME"\n[channels.weather]\ncolumn = "W"\nunit = "m"\n')
    with pytest.raises(ConfigError, match=r"map\.toml: channels: unknown channel 'weather'"):
        load_column_map_config(path)
