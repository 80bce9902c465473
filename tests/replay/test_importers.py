"""``tdmon import``: Volve CSV layout and generic CSV with a column map, into MCAP."""

from __future__ import annotations

import csv
import math
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path

import pytest

from tdmon.cli import main
from tdmon.errors import IngestError
from tdmon.ingest.decode import ChannelSpec, Decoder
from tdmon.ingest.mcap_source import iter_raw
from tdmon.ingest.types import Rejected
from tdmon.replay.importers import VOLVE_LAYOUT, parse_rows, rig_activity

from .conftest import VOLVE_DATA, payloads, read_mcap

VOLVE_FILES = ["trip-out-2016-10-04.csv", "trip-in-2016-10-05.csv",
               "circulating-2016-10-05.csv"]

# column, channel, factor to SI
VOLVE_COLUMNS = [
    ("hookload_kN", "hookload", 1e3), ("surface_torque_kNm", "torque", 1e3),
    ("bit_depth_m", "bit_depth", 1.0), ("hole_depth_m", "hole_depth", 1.0),
    ("block_pos_comp_m", "block_position", 1.0), ("surface_rpm", "rpm", 2 * math.pi / 60),
    ("flow_in_Lpm", "flow_in", 1e-3 / 60), ("spp_bar", "spp", 1e5), ("wob_kN", "wob", 1e3),
]

def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def _unix(text: str) -> float:
    return datetime.strptime(text, "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=UTC).timestamp()


@pytest.mark.parametrize("name", VOLVE_FILES)
def test_volve_import_counts_units_and_times(name: str, tmp_path: Path) -> None:
    source = VOLVE_DATA / name
    out = tmp_path / "volve.mcap"
    assert main(["import", "volve", str(source), "--out", str(out)]) == 0
    rows = _rows(source)
    messages = read_mcap(out)
    channels = payloads(messages, "rig/F4")
    for column, channel, factor in VOLVE_COLUMNS:
        cells = [(row["time_utc"], row[column]) for row in rows if row[column].strip()]
        sent = channels.get(channel, [])
        assert len(sent) == len(cells), channel
        for (time_text, cell), payload in zip(cells[:50], sent[:50], strict=True):
            assert payload["t"] == _unix(time_text)
            assert payload["value"] == pytest.approx(float(cell) * factor, rel=1e-6,
                                                     abs=1e-12)
    activity = [r.message for r in messages if r.topic == "/reference/rig_activity"]
    assert [a["code"] for a in activity] == [int(r["rig_activity_code"]) for r in rows
                                            if r["rig_activity_code"].strip()]
    source_note = next(r.message for r in messages if r.topic == "/reference/source")
    assert source_note["licence"] == "Equinor Open Data Licence (CC BY-NC-SA 4.0 terms)"
    assert source_note["attribution"] == "Equinor and the former Volve licence partners"
    assert source_note["rows"] == len(rows)
    # the log time of each input message is its sample time, in file order
    raw = [r for r in messages if r.topic == "/tdmon/raw"]
    assert all(r.log_time == round(r.message["receive_time"] * 1e9) for r in raw)


def test_volve_hand_values_and_replay(tmp_path: Path) -> None:
    out = tmp_path / "trip-in.mcap"
    assert main(["import", "volve", str(VOLVE_DATA / "trip-in-2016-10-05.csv"), "--out",
                 str(out), "--prefix", "rig/F4-test"]) == 0
    channels = payloads(read_mcap(out), "rig/F4-test")
    # first row: 2016-10-05T00:30:00Z, hook load 645.0371 kN, bit depth 2051 m
    first = channels["hookload"][0]
    assert first == {"t": 1475627400.0, "value": 645037.1, "unit": "N"}
    assert channels["bit_depth"][0]["value"] == 2051.0
    assert channels["torque"][0] == {"t": 1475627400.0, "value": 5.2, "unit": "N*m"}
    decoder = Decoder("rig/F4-test", [ChannelSpec(c, c) for c, _ in (
        (name, None) for _, name, _ in VOLVE_COLUMNS)])
    counts: Counter[str] = Counter()
    with out.open("rb") as handle:
        for _, raw in iter_raw(handle):
            sample = decoder.decode(raw)
            assert not isinstance(sample, Rejected), sample
            counts[sample.channel] += 1
    assert counts["hookload"] == 461


def test_rig_activity_codes() -> None:
    assert rig_activity(116) == {"code": 116, "activity": "tripping in", "circulating": True,
                                 "rotating": True}
    assert rig_activity(4)["activity"] == "in slips"
    assert rig_activity(107) == {"code": 107, "activity": "tripping out", "circulating": False,
                                 "rotating": True}


def test_empty_cells_send_nothing() -> None:
    header = VOLVE_LAYOUT.columns
    row = dict.fromkeys(header, "")
    row.update({"time_utc": "2016-10-05T00:30:00Z", "hookload_kN": "650", "spp_bar": "nan"})
    records = list(parse_rows([(2, row)], VOLVE_LAYOUT, "rig/F4"))
    assert [r[2]["topic"] for r in records] == ["rig/F4/hookload"]


GENERIC_MAP = """
prefix = "rig/X"
delimiter = ";"
missing = ["-999.25"]

[time]
column = "TIME"
format = "%d/%m/%Y %H:%M:%S"
utc_offset = "2 h"

[channels.hookload]
column = "HKLD"
unit = "klbf"

[channels.bit_depth]
column = "DBTM"
unit = "ft"

[channels.spp]
column = "SPP"
unit = "psi"

[channels.flow_in]
column = "FLOW"
unit = "gal/min"

[channels.rpm]
column = "RPM"
unit = "rpm"

[channels.mud_temp_out]
column = "TMPO"
unit = "degF"
"""

GENERIC_CSV = """TIME;HKLD;DBTM;SPP;FLOW;RPM;TMPO;COMMENT
05/10/2016 02:30:00;300;8000;2000;500;60;140;first
05/10/2016 02:30:10;301.5;8001;;500;60;-999.25;
05/10/2016 02:30:20;302;8002;2010;nan;0;141;third
"""


def test_generic_csv_with_a_map(tmp_path: Path) -> None:
    (tmp_path / "map.toml").write_text(GENERIC_MAP)
    (tmp_path / "log.csv").write_text(GENERIC_CSV)
    out = tmp_path / "log.mcap"
    assert main(["import", "csv", str(tmp_path / "log.csv"), "--map", str(tmp_path / "map.toml"),
                 "--out", str(out)]) == 0
    channels = payloads(read_mcap(out), "rig/X")
    assert {name: len(v) for name, v in channels.items()} == {
        "hookload": 3, "bit_depth": 3, "spp": 2, "flow_in": 2, "rpm": 3, "mud_temp_out": 2}
    # 02:30 at UTC+2 is 00:30Z
    t0 = datetime(2016, 10, 5, 0, 30, tzinfo=UTC).timestamp()
    assert [p["t"] for p in channels["hookload"]] == [t0, t0 + 10, t0 + 20]
    assert channels["hookload"][0]["value"] == pytest.approx(300 * 4448.2216152605, rel=1e-6)
    assert channels["bit_depth"][1]["value"] == pytest.approx(8001 * 0.3048, rel=1e-6)
    assert channels["spp"][0]["value"] == pytest.approx(2000 * 6894.757293, rel=1e-6)
    assert channels["flow_in"][0]["value"] == pytest.approx(500 * 3.785411784e-3 / 60, rel=1e-6)
    assert channels["rpm"][0]["value"] == pytest.approx(2 * math.pi, rel=1e-6)
    assert channels["mud_temp_out"][0]["value"] == pytest.approx(60.0, rel=1e-6)
    assert channels["mud_temp_out"][0]["unit"] == "degC"
    # --prefix overrides the map's
    assert main(["import", "csv", str(tmp_path / "log.csv"), "--map", str(tmp_path / "map.toml"),
                 "--out", str(out), "--prefix", "rig/Y"]) == 0
    assert "hookload" in payloads(read_mcap(out), "rig/Y")


def test_unix_time_formats() -> None:
    from tdmon.replay.importers import ColumnSpec, CsvLayout

    for fmt, text in (("unix", "1475627400.5"), ("unix_ms", "1475627400500")):
        layout = CsvLayout("t", "time", (ColumnSpec.of("v", "hookload", "kN"),),
                           time_format=fmt)
        (record,) = parse_rows([(2, {"time": text, "v": "1"})], layout, "p")
        assert record[0] == 1475627400_500_000_000


@pytest.mark.parametrize(("edit", "message"), [
    (lambda text: text.replace("HKLD;", "HOOK;", 1), "no column 'HKLD'"),
    (lambda text: text.replace("8001", "80o1"), "line 3, column 'DBTM': '80o1' is not a number"),
    (lambda text: text.replace("05/10/2016 02:30:20", "2016-10-05"),
     "line 4, column 'TIME': cannot read time '2016-10-05'"),
    (lambda text: text.replace("05/10/2016 02:30:10", ""), "line 3, column 'TIME': no time"),
    (lambda text: text.replace("301.5", "inf"), "line 3, column 'HKLD': 'inf' is not a finite"),
])
def test_bad_csv_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  edit: object, message: str) -> None:
    (tmp_path / "map.toml").write_text(GENERIC_MAP)
    assert callable(edit)
    (tmp_path / "log.csv").write_text(edit(GENERIC_CSV))
    out = tmp_path / "log.mcap"
    assert main(["import", "csv", str(tmp_path / "log.csv"), "--map", str(tmp_path / "map.toml"),
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()
    assert list(tmp_path.glob("*.partial")) == []


@pytest.mark.parametrize(("edit", "message"), [
    (lambda text: text.replace('unit = "klbf"', 'unit = "kilofoo"'),
     "map.toml: channels.hookload.unit: unknown unit 'kilofoo'"),
    (lambda text: text.replace('unit = "klbf"', 'unit = "bar"'),
     "map.toml: channels.hookload.unit: unit 'bar' cannot be converted to 'N'"),
    (lambda text: text.replace("[channels.rpm]", "[channels.speed]"),
     "map.toml: channels: unknown channel 'speed'"),
    (lambda text: text.replace('column = "TIME"\n', ""), "map.toml: time.column: missing key"),
])
def test_bad_map_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  edit: object, message: str) -> None:
    assert callable(edit)
    (tmp_path / "map.toml").write_text(edit(GENERIC_MAP))
    (tmp_path / "log.csv").write_text(GENERIC_CSV)
    assert main(["import", "csv", str(tmp_path / "log.csv"), "--map", str(tmp_path / "map.toml"),
                 "--out", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_missing_file_and_volve_column(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["import", "volve", str(tmp_path / "nope.csv"), "--out",
                 str(tmp_path / "x.mcap")]) == 2
    assert "cannot read" in capsys.readouterr().err
    (tmp_path / "cut.csv").write_text("time_utc,hookload_kN\n2016-10-05T00:30:00Z,650\n")
    assert main(["import", "volve", str(tmp_path / "cut.csv"), "--out",
                 str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err
    assert "no column 'surface_torque_kNm'" in err and "'rig_activity_code'" in err


def test_parse_rows_raises_ingest_error() -> None:
    row = dict.fromkeys(VOLVE_LAYOUT.columns, "")
    row.update({"time_utc": "2016-10-05T00:30:00Z", "rig_activity_code": "4.5"})
    with pytest.raises(IngestError, match="line 7, column 'rig_activity_code'"):
        list(parse_rows([(7, row)], VOLVE_LAYOUT, "rig/F4"))
