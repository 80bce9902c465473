"""Well-file conveniences (issue 17): ``length = "rest"``, components without od/id when their
weight is buoyed, ``[fluid] buoyancy_factor``, ``[string_defaults] tool_joint_od``, the column
map's ``format = "iso"``, did-you-mean for a misspelt key, and ``broomstick --start``.

Each is checked against the same well written out in full (Aadnoy's Example 7.1, whose loads
are in docs/reference-values.md): the shorthand must give the same hook load and torque."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from tdmon.cli import main
from tdmon.config.column_map import load_column_map_config
from tdmon.config.daemon import load_daemon_config
from tdmon.config.well import load_well_model
from tdmon.errors import ConfigError
from tdmon.model.string import STEEL_DENSITY
from tdmon.model.torque_drag import WellModel

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "config" / "wells" / "aadnoy-example-7-1.toml"
TD = 4223.5988


def _write(tmp_path: Path, text: str, name: str = "well.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _edit(tmp_path: Path, *pairs: tuple[str, str]) -> Path:
    text = EXAMPLE.read_text()
    for old, new in pairs:
        assert old in text, old
        text = text.replace(old, new)
    return _write(tmp_path, text, f"well-{len(list(tmp_path.glob('well-*')))}.toml")


def _loads(path: Path, depth: float = TD, mu: float = 0.15) -> tuple[float, ...]:
    model = WellModel(load_well_model(path))
    return tuple(float(model.evaluate(operation, depth, mu)[index])
                 for operation, index in (("pick_up", 0), ("slack_off", 0), ("static", 0),
                                          ("rotating", 1)))


def test_rest_of_the_string_is_the_hand_computed_length(tmp_path: Path) -> None:
    rest = _edit(tmp_path, ('length = "4023.5988 m"', 'length = "rest"'))
    well = load_well_model(rest)
    assert well.string.components[1].length == pytest.approx(TD - 200.0)
    full = _loads(EXAMPLE)
    assert _loads(rest) == pytest.approx(full, rel=1e-12)
    assert full[0] == pytest.approx(1461.5e3, abs=0.5e3)  # soft-string pick-up at TD, mu 0.15


def test_rest_only_on_top_and_only_when_something_is_left(tmp_path: Path) -> None:
    lower = _edit(tmp_path, ('length = "200 m"', 'length = "rest"'))
    with pytest.raises(ConfigError, match=re.escape(
            'string[0].length: only the top (last) component can be "rest"')):
        load_well_model(lower)
    too_long = _edit(tmp_path, ('length = "200 m"', 'length = "4300 m"'),
                     ('length = "4023.5988 m"', 'length = "rest"'))
    with pytest.raises(ConfigError, match=re.escape(
            'string[1].length: "rest" leaves -76.4012 m: the other components (4300 m) reach '
            'the bottom of the hole (4223.6 m)')):
        load_well_model(too_long)


def test_buoyed_weights_need_no_od_id_or_density(tmp_path: Path) -> None:
    # od, id and every tool_joint_od gone; the torque radius given once; no [fluid]
    text = EXAMPLE.read_text()
    for key in ("od", "id", "tool_joint_od"):
        text = re.sub(rf"\n{key} = [^\n]*", "", text)
    text = re.sub(r"\n\[fluid\]\n[^\n]*\n", "\n", text)
    text = text.replace("[[string]]", '[string_defaults]\ntool_joint_od = "0.16 m"\n\n[[string]]',
                        1)
    bare = _write(tmp_path, text)
    assert "od =" not in text.replace("tool_joint_od =", "") and "[fluid]" not in text
    well = load_well_model(bare)
    assert all(c.torque_radius == pytest.approx(0.08) for c in well.string.components)
    assert math.isnan(well.fluid.density) and math.isnan(well.string.components[0].area)
    assert _loads(bare) == pytest.approx(_loads(EXAMPLE), rel=1e-12)
    # the tensile limit needs the steel area: unknown, so not checked (no crash, no alarm)
    assert main(["model", "loads", "--well", str(bare), "--bit-depth", "4000 m", "--mu",
                 "0.2"]) == 0


def test_missing_dimensions_are_named(tmp_path: Path) -> None:
    no_radius = _edit(tmp_path, ('od = "5 in"\nid = "4.276 in"\n', ""),
                      ('buoyed_weight = "0.3 kN/m"\ntool_joint_od = "0.16 m"',
                       'buoyed_weight = "0.3 kN/m"'))
    with pytest.raises(ConfigError, match=re.escape(
            "string[1].tool_joint_od: missing key (without od the torque radius comes from it; "
            "or give it once in [string_defaults])")):
        load_well_model(no_radius)
    in_air = _edit(tmp_path, ('od = "5 in"\nid = "4.276 in"\n', ""),
                   ('buoyed_weight = "0.3 kN/m"', 'weight = "0.35 kN/m"'))
    with pytest.raises(ConfigError, match=re.escape("string[1].od: missing key (a weight in air")):
        load_well_model(in_air)
    no_fluid = _edit(tmp_path, ('buoyed_weight = "0.3 kN/m"', 'weight = "0.35 kN/m"'),
                     ('[fluid]\ndensity = "1.2 sg"', '[fluid]'))
    with pytest.raises(ConfigError, match=re.escape(
            "fluid.density: missing key (string[1] has a weight in air to buoy")):
        load_well_model(no_fluid)


def test_buoyancy_factor_buoys_weights_in_air(tmp_path: Path) -> None:
    # the drill pipe given in air (0.3 / 0.85 kN/m) with a buoyancy factor of 0.85 weighs what
    # the example's 0.3 kN/m buoyed weight does
    factor = _edit(tmp_path, ('buoyed_weight = "0.3 kN/m"', f'weight = "{0.3 / 0.85} kN/m"'),
                   ('[fluid]\ndensity = "1.2 sg"', "[fluid]\nbuoyancy_factor = 0.85"))
    well = load_well_model(factor)
    assert well.string.components[1].buoyed_weight == pytest.approx(300.0)
    assert well.fluid.density == pytest.approx(0.15 * STEEL_DENSITY)  # 1177.5 kg/m3
    assert _loads(factor) == pytest.approx(_loads(EXAMPLE), rel=1e-9)
    # without the factor, eq 35 at 1.2 sg gives 1 - 1200/7850 = 0.847: a lighter string
    eq35 = _edit(tmp_path, ('buoyed_weight = "0.3 kN/m"', f'weight = "{0.3 / 0.85} kN/m"'))
    assert _loads(eq35)[2] < _loads(factor)[2]


def test_iso_is_a_synonym_of_iso8601(tmp_path: Path) -> None:
    body = '\n[channels.hookload]\ncolumn = "hl"\nunit = "kN"\n'
    for word in ("iso", "ISO", "iso8601"):
        path = _write(tmp_path, f'[time]\ncolumn = "t"\nformat = "{word}"\n{body}', "map.toml")
        assert load_column_map_config(path).time.format == "iso8601"
    csv = _write(tmp_path, "t,hl\n2016-10-04T12:00:00Z,1000\n2016-10-04T12:00:01Z,1001\n",
                 "rig.csv")
    path = _write(tmp_path, f'[time]\ncolumn = "t"\nformat = "iso"\n{body}', "map.toml")
    out = tmp_path / "out.mcap"
    assert main(["import", "csv", str(csv), "--map", str(path), "--out", str(out)]) == 0
    from tdmon.record.reader import read_messages

    times = [m.message["receive_time"] for m in read_messages(out) if m.topic == "/tdmon/raw"]
    assert times == [1475582400.0, 1475582401.0]  # 2016-10-04T12:00:00Z and a second later


def test_a_misspelt_key_is_named_with_its_likely_meaning(tmp_path: Path) -> None:
    body = '\n[channels.hookload]\ncolumn = "hl"\nunit = "kN"\n'
    path = _write(tmp_path, f'[time]\ncolum = "t"\n{body}', "map.toml")
    with pytest.raises(ConfigError) as caught:
        load_column_map_config(path)
    assert str(caught.value) == (f"{path}: time.colum: unknown key 'colum', did you mean "
                                 "'column'?")
    # an optional key (nothing missing), in a list of tables of the well file
    well = _edit(tmp_path, ('buoyed_weight = "0.3 kN/m"', 'buoyed_wieght = "0.3 kN/m"'))
    with pytest.raises(ConfigError) as caught:
        load_well_model(well)
    assert str(caught.value) == (f"{well}: string[1].buoyed_wieght: unknown key "
                                 "'buoyed_wieght', did you mean 'buoyed_weight'?")
    # the daemon file, in a nested table
    daemon = _write(tmp_path, 'prefix = "rig/F4"\n[sources.mqtt]\nhots = "127.0.0.1"\n',
                    "daemon.toml")
    with pytest.raises(ConfigError, match=re.escape(
            "sources.mqtt.hots: unknown key 'hots', did you mean 'host'?")):
        load_daemon_config(daemon)
    # nothing close: the key alone
    odd = _write(tmp_path, f'[time]\ncolumn = "t"\nzzz = 1\n{body}', "map.toml")
    with pytest.raises(ConfigError, match=re.escape("time.zzz: unknown key 'zzz'")) as caught:
        load_column_map_config(odd)
    assert "did you mean" not in str(caught.value)


def test_broomstick_starts_where_asked(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                       ) -> None:
    assert main(["model", "broomstick", "--well", str(EXAMPLE), "--mu", "0.15", "--step",
                 "500 m", "--start", "2000 m", "--json"]) == 0
    document = json.loads(capsys.readouterr().out)
    depths = document["bit_depth_m"]
    assert depths[0] == pytest.approx(2000.0) and depths[1] == pytest.approx(2500.0)
    assert depths[-1] == pytest.approx(TD)
    assert main(["model", "broomstick", "--well", str(EXAMPLE), "--start", "5000 m"]) == 2
    assert ("--start: 5000 m is not between 0 and the deepest bit depth (4223.6 m)"
            in capsys.readouterr().err)
