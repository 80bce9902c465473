"""WITSML 1.4.1.1 import: the Volve F-4 time log against the CSV route, the drafted well file
against config/wells/volve-f4.toml, null values and chunks, and the one-line errors."""

from __future__ import annotations

import io
import json
import math
import re
from pathlib import Path

import pytest

from tdmon.cli import main
from tdmon.config.well import load_well
from tdmon.errors import IngestError
from tdmon.ingest.witsml import DataRow, LogBlock, iter_log, pint_unit
from tdmon.ingest.witsml_well import choose_tubular, draft_well, read_objects
from tdmon.model.torque_drag import Operation, WellModel
from tdmon.record.reader import read_messages
from tdmon.replay.importers import import_volve
from tdmon.replay.witsml_import import import_witsml

REPO = Path(__file__).resolve().parents[2]
WITSML = REPO / "data" / "volve-f4" / "witsml"
TIME_LOG = WITSML / "GwdTime-2016-10-03-to-05.xml"
TRIP_OUT_CSV = REPO / "data" / "volve-f4" / "trip-out-2016-10-04.csv"


def _series(path: Path) -> dict[str, dict[float, float]]:
    """channel -> {t: value} of the /tdmon/raw payloads of an imported file."""
    series: dict[str, dict[float, float]] = {}
    for message in read_messages(path, "/tdmon/raw"):
        payload = json.loads(message.message["payload"])
        channel = message.message["topic"].rsplit("/", 1)[-1]
        assert payload["t"] not in series.setdefault(channel, {}), "a time written twice"
        series[channel][payload["t"]] = payload["value"]
    return series


@pytest.fixture(scope="module")
def volve_routes(tmp_path_factory: pytest.TempPathFactory
                 ) -> tuple[dict[str, dict[float, float]], dict[str, dict[float, float]]]:
    folder = tmp_path_factory.mktemp("volve")
    import_volve(TRIP_OUT_CSV, folder / "csv.mcap")
    result = import_witsml([TIME_LOG], folder / "witsml.mcap", prefix="rig/F4")
    assert result.curves["hookload"] == "HKLD [N]"
    assert result.curves["torque"] == "TORQUE [N.m]"
    assert result.curves["bit_depth"] == "BITDEP [m]"
    assert result.rows == 7106 and result.duplicates == 0
    return _series(folder / "csv.mcap"), _series(folder / "witsml.mcap")


# The CSV holds kN, kN m and m with 4 decimals (half a unit of the last place: 0.05 N, 0.05 N m,
# 0.05 mm); both routes then write each value with 7 significant digits (raw_input), half a unit
# of the 7th digit each. So |csv - witsml| <= 0.05 (in N, N m, 1e-3 m) + 1e-6 |value|.
TOLERANCE = {"hookload": 0.05, "torque": 0.05, "bit_depth": 5e-5}


@pytest.mark.parametrize("channel", ["hookload", "torque", "bit_depth"])
def test_trip_out_equals_the_csv_route(volve_routes: tuple[dict[str, dict[float, float]], ...],
                                       channel: str) -> None:
    csv, witsml = volve_routes
    expected = csv[channel]
    first, last = min(expected), max(expected)
    window = {t: v for t, v in witsml[channel].items() if first <= t <= last}
    assert len(expected) > 1200
    assert sorted(window) == sorted(expected)  # same samples, same timestamps
    worst = max(abs(window[t] - value) - 1e-6 * abs(value) for t, value in expected.items())
    assert worst <= TOLERANCE[channel], worst
    if channel == "torque":
        # not rotating while tripping out: the log's 5.186344 N m, 0.0052 kN m in the CSV
        assert set(expected.values()) == {5.2} and set(window.values()) == {5.186344}
    else:  # the values vary: the comparison has something to compare
        assert max(expected.values()) - min(expected.values()) > 1e4 * TOLERANCE[channel]


def test_rig_activity_and_source_carry_over(tmp_path: Path) -> None:
    out = tmp_path / "w.mcap"
    import_witsml([TIME_LOG], out, prefix="rig/F4", note="test note")
    source = [m.message for m in read_messages(out, "/reference/source")]
    assert len(source) == 1
    assert source[0]["licence"].startswith("Equinor Open Data Licence")
    assert source[0]["attribution"] == "Equinor and the former Volve licence partners"
    assert source[0]["well"] == "NO 15/9-F-4" and source[0]["log_uid"] == "36VIRG33"
    assert source[0]["note"] == "test note" and source[0]["rows"] == 7106
    activity = [m.message for m in read_messages(out, "/reference/rig_activity")]
    assert len(activity) == 7106 and activity[-1]["code"] == 116


def test_drafted_well_gives_the_static_hook_load(tmp_path: Path) -> None:
    files = [WITSML / name for name in ("trajectory.xml", "tubular-1.xml", "tubular-2.xml",
                                        "tubular-3.xml", "wbGeometry.xml", "rig.xml")]
    handles = [(path.open("rb"), path.name) for path in files]
    try:
        objects = read_objects(handles)
    finally:
        for handle, _ in handles:
            handle.close()
    with pytest.raises(IngestError, match="several tubulars"):
        draft_well(objects)
    # what WITSML lacks, filled in as config/wells/volve-f4.toml has it
    draft = draft_well(objects, tubular=choose_tubular(objects, "15VIRG33"),
                       block_weight="655 kN", fluid_density="1.08 sg")
    assert not any(item.startswith(("fluid.density", "well.block_weight"))
                   for item in draft.missing)
    assert any(item.startswith("hole[*].friction") for item in draft.missing)
    path = tmp_path / "draft.toml"
    path.write_text(draft.text)
    drafted = WellModel(load_well(path).to_model(path))
    reference = WellModel(load_well(REPO / "config" / "wells" / "volve-f4.toml").to_model())
    for bit_depth in (300.0, 1000.0, 1800.0, 2500.0):
        ours, _ = drafted.evaluate(Operation.STATIC, bit_depth, 0.0)
        theirs, _ = reference.evaluate(Operation.STATIC, bit_depth, 0.0)
        assert ours == pytest.approx(theirs, rel=0.005), bit_depth
        assert theirs > 700e3  # block weight plus string: a real comparison


def test_draft_without_fill_lists_what_is_missing_and_does_not_load(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "d.toml"
    code = main(["import", "witsml", str(WITSML / "trajectory.xml"),
                 str(WITSML / "tubular-3.xml"), str(WITSML / "wbGeometry.xml"),
                 "--well-out", str(out)])
    assert code == 0
    err = capsys.readouterr().err
    assert "fluid.density" in err and "well.block_weight" in err
    text = out.read_text()
    assert "# NOT READ FROM THE WITSML" in text and "# density =" in text
    from tdmon.errors import ConfigError

    with pytest.raises(ConfigError, match="fluid"):
        load_well(out)


#: a placeholder of the draft: a commented ``key = value`` line marked FILL IN
PLACEHOLDER = re.compile(r"(?m)^# (\w+ = [^#\n]+?)  # FILL IN\b.*$")


def test_draft_loads_once_its_placeholders_take_the_suggested_values(tmp_path: Path) -> None:
    """Every placeholder of a draft with nothing given beyond the WITSML (Volve's objects:
    no fluids report, no block weight, no connection OD, no grade) is a commented line with a
    suggested value; uncommenting them all gives a file that loads and models."""
    out = tmp_path / "draft.toml"
    assert main(["import", "witsml", str(WITSML / "trajectory.xml"),
                 str(WITSML / "tubular-3.xml"), str(WITSML / "wbGeometry.xml"),
                 str(WITSML / "rig.xml"), "--well-out", str(out)]) == 0
    draft = out.read_text()
    filled = PLACEHOLDER.sub(r"\1", draft)
    keys = [match.group(1).split(" = ")[0] for match in PLACEHOLDER.finditer(draft)]
    assert sorted(keys) == sorted(["block_weight", "density", "tool_joint_od",
                                   "yield_strength"] + ["friction"] * 4)
    assert "FILL IN" not in "\n".join(line for line in filled.splitlines()
                                       if not line.startswith("#"))
    path = tmp_path / "filled.toml"
    path.write_text(filled)
    config = load_well(path)
    # the suggestions, as loaded: 40 t of block (a force: 40 000 kg x g), 1.2 sg of mud,
    # L-80's yield, the body OD as torque radius, 0.25 cased and 0.30 open hole
    assert config.well.block_weight == pytest.approx(40_000 * 9.80665, rel=1e-9)
    assert config.fluid.density == pytest.approx(1200.0, rel=1e-9)
    [pipe] = config.string
    assert pipe.yield_strength == pytest.approx(552e6)
    assert pipe.tool_joint_od == pytest.approx(pipe.od, rel=1e-9)
    assert [section.friction.coefficients for section in config.hole] == [
        {"mu": 0.25}, {"mu": 0.25}, {"mu": 0.25}, {"mu": 0.30}]
    model = WellModel(config.to_model(path))
    hook_load, _ = model.evaluate(Operation.STATIC, 2000.0, 0.0)
    assert hook_load > 40_000 * 9.80665 + 500e3  # the block and some 2000 m of 29 lb/ft tubing


# -- synthetic logs ----------------------------------------------------------------------------

def _log(rows: list[str], *, uid: str = "L1", hookload_null: str | None = "-1",
         log_null: str = "-999.25", mnemonics: str = "TIME,HKLA,TQ,BDEP,RPM",
         units: str = "s,kkgf,kN.m,ft,rpm", name: str = "synthetic") -> bytes:
    curve_null = f"<nullValue>{hookload_null}</nullValue>" if hookload_null else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<logs xmlns="http://www.witsml.org/schemas/1series" version="1.4.1.1">
 <log uid="{uid}"><nameWell>Test</nameWell><name>{name}</name>
  <indexType>date time</indexType><indexCurve>TIME</indexCurve><nullValue>{log_null}</nullValue>
  <logCurveInfo uid="TIME"><mnemonic>TIME</mnemonic><unit>s</unit></logCurveInfo>
  <logCurveInfo uid="HKLA"><mnemonic>HKLA</mnemonic><classWitsml>hkldAv</classWitsml>
   <unit>kkgf</unit>{curve_null}</logCurveInfo>
  <logCurveInfo uid="TQ"><mnemonic>TQ</mnemonic><unit>kN.m</unit></logCurveInfo>
  <logCurveInfo uid="BDEP"><mnemonic>BDEP</mnemonic><unit>ft</unit></logCurveInfo>
  <logCurveInfo uid="RPM"><mnemonic>RPM</mnemonic><unit>rpm</unit></logCurveInfo>
  <logData><mnemonicList>{mnemonics}</mnemonicList><unitList>{units}</unitList>
   {''.join(f'<data>{row}</data>' for row in rows)}
  </logData></log></logs>""".encode()


def test_null_values_and_chunks(tmp_path: Path) -> None:
    first = tmp_path / "a.xml"
    second = tmp_path / "b.xml"
    # chunk a: 00:00:00-00:00:20; chunk b overlaps at 00:00:20 (a duplicate) and goes on
    first.write_bytes(_log([
        "2020-01-01T00:00:00Z,100,1.5,1000,60",
        "2020-01-01T00:00:10Z,-1,-999.25,1001,",       # curve null, log null, empty
        "2020-01-01T00:00:20Z,102,-999.250,1002,60",  # the log's null written differently
    ]))
    second.write_bytes(_log([
        "2020-01-01T00:00:20Z,555,9,9999,9",           # same time: this file is given first
        "2020-01-01T00:00:30Z,103,2.0,-999.25,-999.25",
        "2020-01-01T00:00:40Z,-999.25,2.5,1004,30",    # -999.25 is not HKLA's null: a value
    ]))
    out = tmp_path / "o.mcap"
    # given in reverse order: the rows are merged by time; on equal times the file given
    # first wins (here b's row at 00:00:20, a's is the duplicate)
    result = import_witsml([second, first], out, prefix="rig/T")
    assert result.rows == 5 and result.duplicates == 1
    series = _series(out)
    t0 = 1577836800.0
    kgf = 9.80665
    assert series["hookload"] == pytest.approx({t0: 100e3 * kgf, t0 + 20: 555e3 * kgf,
                                                t0 + 30: 103e3 * kgf,
                                                t0 + 40: -999.25e3 * kgf})
    assert series["torque"] == pytest.approx({t0: 1500.0, t0 + 20: 9000.0, t0 + 30: 2000.0,
                                          t0 + 40: 2500.0})
    assert series["bit_depth"] == pytest.approx({t0: 304.8, t0 + 10: 1001 * 0.3048,
                                                 t0 + 20: 9999 * 0.3048, t0 + 40: 1004 * 0.3048})
    assert series["rpm"] == pytest.approx({t0: 2 * math.pi, t0 + 20: 0.3 * math.pi,
                                           t0 + 40: math.pi})


def test_reader_streams_blocks_then_rows() -> None:
    events = list(iter_log(io.BytesIO(_log(["2020-01-01T00:00:00Z,1,2,3,4"] * 3)), "x.xml"))
    assert isinstance(events[0], LogBlock) and events[0].mnemonics[1] == "HKLA"
    assert all(isinstance(item, DataRow) for item in events[1:]) and len(events) == 4


def test_unit_table() -> None:
    assert pint_unit("c/s") == "rps"
    assert pint_unit("kN.m") == "kN*m"
    assert pint_unit("g/cm3") == "g/cm**3"
    assert pint_unit("unitless") is None


# -- errors: one line, exit code 2 -------------------------------------------------------------

def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    code = main(["import", "witsml", *args])
    return code, capsys.readouterr().err


def test_not_xml(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.xml"
    bad.write_text("time,hookload\n1,2\n")
    code, err = _run(capsys, str(bad), "--out", str(tmp_path / "o.mcap"))
    assert code == 2 and err.count("\n") == 1
    assert str(bad) in err and "not well-formed XML" in err


def test_xml_but_not_witsml(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "page.xml"
    bad.write_text("<html><body>no</body></html>")
    code, err = _run(capsys, str(bad), "--out", str(tmp_path / "o.mcap"))
    assert code == 2 and err.count("\n") == 1
    assert str(bad) in err and "not a WITSML object file" in err


def test_truncated_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "cut.xml"
    bad.write_bytes(_log(["2020-01-01T00:00:00Z,1,2,3,4"] * 3)[:-40])
    code, err = _run(capsys, str(bad), "--out", str(tmp_path / "o.mcap"))
    assert code == 2 and err.count("\n") == 1 and "not well-formed XML" in err
    assert not (tmp_path / "o.mcap").exists()


def test_log_without_the_needed_curves(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                       ) -> None:
    bad = tmp_path / "nohook.xml"
    bad.write_bytes(_log(["2020-01-01T00:00:00Z,1,2,3,4"], mnemonics="TIME,XX,TQ,BDEP,RPM"))
    code, err = _run(capsys, str(bad), "--out", str(tmp_path / "o.mcap"))
    assert code == 2 and err.count("\n") == 1
    assert str(bad) in err and "no curve for hookload" in err and "--curve" in err
    # naming the curve by hand makes it import
    code, _ = _run(capsys, str(bad), "--out", str(tmp_path / "o.mcap"),
                   "--curve", "hookload=TQ:kN")
    assert code == 0


def test_unknown_uom_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "uom.xml"
    bad.write_bytes(_log(["2020-01-01T00:00:00Z,1,2,3,4"], units="s,blorp,kN.m,ft,rpm")
                    .replace(b"<unit>kkgf</unit>", b"<unit>blorp</unit>"))
    code, err = _run(capsys, str(bad), "--out", str(tmp_path / "o.mcap"))
    assert code == 2 and err.count("\n") == 1 and "blorp" in err and "HKLA" in err


def test_empty_log_and_two_logs_are_errors(tmp_path: Path) -> None:
    empty = tmp_path / "empty.xml"
    empty.write_bytes(_log([]))
    with pytest.raises(IngestError, match="no data rows"):
        import_witsml([empty], tmp_path / "o.mcap", prefix="rig/T")
    assert not (tmp_path / "o.mcap").exists()
    # two logs (another name), not two chunks of one: refused, naming both
    one, other = tmp_path / "one.xml", tmp_path / "other.xml"
    one.write_bytes(_log(["2020-01-01T00:00:00Z,1,2,3,4"], uid="A"))
    other.write_bytes(_log(["2020-01-01T00:00:10Z,1,2,3,4"], uid="B", name="mudlog"))
    with pytest.raises(IngestError, match="import one log at a time") as error:
        import_witsml([one, other], tmp_path / "o.mcap", prefix="rig/T")
    assert "'mudlog' (uid B" in str(error.value) and "'synthetic' (uid A" in str(error.value)
    assert not (tmp_path / "o.mcap").exists()


def test_cli_imports_log_and_drafts_well_in_one_call(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "log.xml"
    log.write_bytes(_log(["2020-01-01T00:00:00Z,1,2,3,4", "2020-01-01T00:00:15Z,1,2,3,4"]))
    code = main(["import", "witsml", str(WITSML / "wbGeometry.xml"), str(log),
                 str(WITSML / "trajectory.xml"), str(WITSML / "tubular-3.xml"),
                 "--out", str(tmp_path / "o.mcap"), "--well-out", str(tmp_path / "d.toml"),
                 "--prefix", "rig/T", "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["log"]["rows"] == 2 and summary["log"]["curves"]["hookload"] == "HKLA [kkgf]"
    assert any(item.startswith("fluid.density") for item in summary["well"]["missing"])
    topics = {m.message["topic"] for m in read_messages(tmp_path / "o.mcap", "/tdmon/raw")}
    assert topics == {"rig/T/hookload", "rig/T/torque", "rig/T/bit_depth", "rig/T/rpm"}


def test_curve_map_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "log.xml"
    log.write_bytes(_log(["2020-01-01T00:00:00Z,1,2,3,4"], mnemonics="TIME,XX,TQ,BDEP,RPM"))
    curve_map = tmp_path / "map.toml"
    curve_map.write_text('prefix = "rig/M"\n[curves.hookload]\nmnemonic = "XX"\nunit = "klbf"\n')
    assert main(["import", "witsml", str(log), "--out", str(tmp_path / "o.mcap"),
                 "--map", str(curve_map)]) == 0
    series = _series(tmp_path / "o.mcap")
    assert series["hookload"] == pytest.approx({1577836800.0: 4448.222})
    topics = {m.message["topic"] for m in read_messages(tmp_path / "o.mcap", "/tdmon/raw")}
    assert "rig/M/hookload" in topics
    capsys.readouterr()
    curve_map.write_text('[curves.hookpoint]\nmnemonic = "XX"\n')
    assert main(["import", "witsml", str(log), "--out", str(tmp_path / "o.mcap"),
                 "--map", str(curve_map)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "map.toml" in err and "hookpoint" in err


def test_review_fixes_draft_states_degrees_and_override_units_read_as_witsml(
        tmp_path: Path) -> None:
    """A near-vertical well heading north drafts to a file that loads (the draft states its
    angle unit, so the radians check does not refuse it); a curve unit given on the command
    line is read like a WITSML uom (1/min is rev/min, not rad/min)."""
    import io

    from tdmon.config.well import load_well_model
    from tdmon.ingest.witsml import block_samples, iter_log, resolve_curves
    from tdmon.ingest.witsml_well import (
        GeometrySection,
        Station,
        Trajectory,
        Tubular,
        TubularComponent,
        WellboreGeometry,
        WellObjects,
        draft_well,
    )

    trajectory = Trajectory("t", "traj", "x.xml", (Station(0, 0, 0), Station(500, 0.3, 0),
                            Station(1000, 1.5, 2.0), Station(1500, 2.5, 4.0)), "md m")
    component = TubularComponent("c1", "drill pipe", 1, 1400, 0.127, 0.1086, 29.0, 0.168, 5.5e8)
    tubular = Tubular("tb", "dp", "x.xml", "drilling", "", (component,))
    geometry = WellboreGeometry("g", "geo", "x.xml", (
        GeometrySection("casing", 0, 800, 0.22, 0.244), GeometrySection("open hole", 800, 1500,
                                                                        0.216)))
    draft = draft_well(WellObjects("W", trajectory, (tubular,), geometry, None, None),
                       block_weight="655 kN", fluid_density="1.2 sg")
    path = tmp_path / "draft.toml"
    path.write_text(draft.text.replace("# friction = ", "friction = "))
    assert load_well_model(path).survey.md[-1] == pytest.approx(1500.0)

    xml = b"""<logs xmlns="http://www.witsml.org/schemas/1series"><log uid="L1">
<nameWell>W</nameWell><indexType>date time</indexType><indexCurve>TIME</indexCurve>
<logCurveInfo><mnemonic>TIME</mnemonic><unit>s</unit></logCurveInfo>
<logCurveInfo><mnemonic>HKLD</mnemonic><unit>kN</unit></logCurveInfo>
<logCurveInfo><mnemonic>BITDEP</mnemonic><unit>m</unit></logCurveInfo>
<logCurveInfo><mnemonic>RPM</mnemonic><unit>unitless</unit></logCurveInfo>
<logData><mnemonicList>TIME,HKLD,BITDEP,RPM</mnemonicList><unitList>s,kN,m,unitless</unitList>
<data>2020-01-01T00:00:00Z,1000,100,60</data></logData></log></logs>"""
    block, rows = list(iter_log(io.BytesIO(xml), "x"))[:2]
    for unit in ("rpm", "1/min"):
        curves = resolve_curves(block, "x", overrides={"rpm": ("RPM", unit)})
        assert dict(block_samples(rows, curves, "x"))["rpm"] == pytest.approx(2 * math.pi)
