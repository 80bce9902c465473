"""tdmon.channels: one channel check and one prefix rule for the config, ingest and replay."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from tdmon import channels
from tdmon.channels import CHANNEL_UNITS, CHANNELS, ChannelSpec, check_channel, validate_prefix
from tdmon.config.daemon import parse_daemon_config
from tdmon.errors import ConfigError, IngestError
from tdmon.ingest import decode
from tdmon.ingest.publish import parse_columns
from tdmon.units import conversion

ROOT = Path(__file__).resolve().parents[1]


def test_channels_and_their_si_units() -> None:
    assert CHANNELS == ("hookload", "torque", "bit_depth", "hole_depth", "block_position", "rpm",
                        "flow_in", "spp", "wob", "downhole_wob", "downhole_torque",
                        "mud_temp_in", "mud_temp_out", "mud_density")
    # each internal unit is what pint converts to: 1 kN is 1000 N, 1 ft 0.3048 m, 60 rpm 2 pi
    assert conversion("kN", CHANNEL_UNITS["hookload"][0]) == pytest.approx((1000.0, 0.0))
    assert conversion("ft", CHANNEL_UNITS["bit_depth"][0]) == pytest.approx((0.3048, 0.0))
    assert conversion("rpm", CHANNEL_UNITS["rpm"][0])[0] == pytest.approx(2 * 3.141592653589793
                                                                          / 60)
    # the MWD's torque at the bit in the surface torque's unit: 1 kN m is 1000 N m
    assert conversion("kN*m", CHANNEL_UNITS["downhole_torque"][0]) == pytest.approx((1000.0, 0.0))
    assert conversion("degF", CHANNEL_UNITS["mud_temp_in"][0]) == pytest.approx(
        (5 / 9, -32 * 5 / 9))
    # the decoder names the same objects (it used to own them)
    assert decode.CHANNEL_UNITS is CHANNEL_UNITS and decode.ChannelSpec is ChannelSpec


def test_check_channel() -> None:
    assert check_channel("torque") == "torque"
    with pytest.raises(ValueError, match=r"unknown channel 'weather' \(one of hookload, torque,"):
        check_channel("weather")
    # a producer with fewer channels passes its own
    with pytest.raises(ValueError, match=r"^unknown channel 'mud_density' \(one of rpm, spp\)$"):
        check_channel("mud_density", ("rpm", "spp"))


def test_every_unknown_channel_check_is_the_one() -> None:
    config = {"prefix": "rig/F4", "sources": {"mqtt": {}}}
    with pytest.raises(ConfigError, match=r"channels: unknown channel 'weather' \(one of"):
        parse_daemon_config({**config, "channels": {"weather": {}}}, Path("d.toml"))
    with pytest.raises(ConfigError, match=r"align\.wait_for: unknown channel 'x' \(one of"):
        parse_daemon_config({**config, "align": {"wait_for": ["x"]}}, Path("d.toml"))
    with pytest.raises(ValueError, match=r"unknown channel 'weather' \(one of"):
        decode.Decoder("p", [ChannelSpec("weather", "w")])
    with pytest.raises(IngestError, match=r"column map: unknown channel 'speed' \(one of"):
        parse_columns("hookload=hkld:kN,speed=v:m/s")


def _bundled_prefixes() -> list[str]:
    files = [*(ROOT / "config" / "daemon").glob("*.toml"),
             *(ROOT / "replays" / "scenarios").glob("*.toml")]
    prefixes = [tomllib.loads(f.read_text()).get("prefix") for f in files]
    return sorted({p for p in prefixes if p})


def test_the_bundled_prefixes_pass() -> None:
    bundled = _bundled_prefixes()
    assert {"rig/F4", "sim/trip-out", "sim/faults"} <= set(bundled)
    for prefix in bundled:
        assert validate_prefix(prefix) == prefix
    assert validate_prefix("/rig/F4-test/") == "rig/F4-test"
    assert validate_prefix("site_2/rig.7") == "site_2/rig.7"


@pytest.mark.parametrize("prefix", ["", "/", "rig/#", "rig/+/x", "rig/*", "$SYS/rig", "rig F4",
                                    "rig\tF4", "rig//F4", "rig/F4?", "rig/é"])
def test_one_prefix_rule_for_config_and_scenarios(prefix: str) -> None:
    with pytest.raises(ValueError, match="plain topic path"):
        validate_prefix(prefix)
    with pytest.raises(ConfigError, match="prefix"):
        parse_daemon_config({"prefix": prefix, "sources": {"mqtt": {}}}, Path("d.toml"))


def test_scenario_prefix_uses_the_rule() -> None:
    from pydantic import ValidationError

    from tdmon.config.scenario import ScenarioInfo

    info = {"well": "w.toml", "bit_depth": 1000.0}
    assert ScenarioInfo.model_validate({**info, "prefix": "/sim/x/"}).prefix == "sim/x"
    with pytest.raises(ValidationError, match="plain topic path"):
        ScenarioInfo.model_validate({**info, "prefix": "sim/*"})  # refused by the config too


def test_the_module_imports_nothing_of_tdmon() -> None:
    source = Path(channels.__file__).read_text()
    assert "from tdmon" not in source and "import tdmon" not in source
