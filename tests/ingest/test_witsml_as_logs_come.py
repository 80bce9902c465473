"""WITSML logs as users have them: one log exported in pieces (runs with their own uids,
overlapping), the WITSML 1.3.1.1 layout, and the import summary that lists every curve with
what became of it. The Volve pieces are small files of tests/ingest/data/witsml (derived from
data/volve-f4/witsml by its derive.py; same licence)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from tdmon.cli import main
from tdmon.errors import IngestError
from tdmon.record.reader import read_messages
from tdmon.replay.witsml_import import import_witsml, scan_log_file

REPO = Path(__file__).resolve().parents[2]
VOLVE_LOG = REPO / "data" / "volve-f4" / "witsml" / "GwdTime-2016-10-03-to-05.xml"
DERIVED = Path(__file__).resolve().parent / "data" / "witsml"
RUN0, RUN1 = DERIVED / "volve-f4-run0.xml", DERIVED / "volve-f4-run1.xml"
OLD_LAYOUT = DERIVED / "volve-f4-1.3.1.1.xml"
WINDOW = (1475600400.0, 1475602200.0)  # 2016-10-04 17:00:00 to 17:30:00 UTC


def _series(path: Path) -> dict[str, list[tuple[float, float]]]:
    """channel -> [(t, value)] of an imported file's input messages, in order."""
    series: dict[str, list[tuple[float, float]]] = {}
    for message in read_messages(path, "/tdmon/raw"):
        payload = json.loads(message.message["payload"])
        series.setdefault(message.message["topic"].rsplit("/", 1)[-1], []).append(
            (payload["t"], payload["value"]))
    return series


@pytest.fixture(scope="module")
def whole(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[tuple[float, float]]]:
    """The same half hour imported from the original Volve file, in one piece."""
    out = tmp_path_factory.mktemp("whole") / "whole.mcap"
    import_witsml([VOLVE_LOG], out, prefix="rig/F4")
    return {channel: [(t, v) for t, v in values if WINDOW[0] <= t <= WINDOW[1]]
            for channel, values in _series(out).items()}


def test_runs_of_one_log_join_in_time_order_with_overlaps_counted(
        tmp_path: Path, whole: dict[str, list[tuple[float, float]]]) -> None:
    out = tmp_path / "runs.mcap"
    # given in any order: run 1 and run 2 (one file), run 0 (the other); overlaps 21 + 1 rows
    result = import_witsml([RUN1, RUN0], out, prefix="rig/F4")
    assert result.rows == 121 and result.duplicates == 22 and result.out_of_order == 0
    assert result.log_uids == ("36VIRG33-r1", "36VIRG33-r2", "36VIRG33-r0")
    assert _series(out) == whole  # every sample of the half hour, once, as in one piece
    assert sum(len(values) for values in whole.values()) > 1000
    [source] = [m.message for m in read_messages(out, "/reference/source")]
    assert source["log_uids"] == ["36VIRG33-r1", "36VIRG33-r2", "36VIRG33-r0"]
    assert source["runs"] == ["1", "2", "0"] and source["rows"] == 41 + 21 + 81  # in the files
    assert source["layout"] == "witsml-1.4.1.1" and source["log_name"] == "GwdTime"
    assert source["licence"].startswith("Equinor Open Data Licence")


def test_the_scan_finds_each_chunk_even_across_reads(tmp_path: Path) -> None:
    # white space before the second <log> puts the 1 MB read boundary inside its uid
    text = RUN1.read_text()
    second = text.index("<log ", text.index("<log ") + 1)
    padding = " " * ((1 << 20) - text.index('uid="36VIRG33-r2"') - 8)
    padded = tmp_path / "padded.xml"
    padded.write_text(text[:second] + padding + text[second:])
    assert padded.read_bytes()[(1 << 20) - 8:(1 << 20) + 8] == b'uid="36VIRG33-r2"'[:16]
    assert scan_log_file(RUN1) == scan_log_file(padded)
    assert scan_log_file(RUN1).uids == ("36VIRG33-r1", "36VIRG33-r2")
    assert scan_log_file(RUN1).rows == 41 + 21


def test_witsml_1311_reads_as_the_same_log(
        tmp_path: Path, whole: dict[str, list[tuple[float, float]]]) -> None:
    """Columns by columnIndex (in another order than the logCurveInfo elements), no
    mnemonicList or unitList, times without a zone (taken as UTC)."""
    out = tmp_path / "old.mcap"
    result = import_witsml([OLD_LAYOUT], out, prefix="rig/F4")
    assert result.version == "1.3.1.1" and result.rows == 121
    assert result.curves["torque"] == "TORQUE [N.m]" and result.curves["rpm"] == "SURF_RPM [c/s]"
    assert _series(out) == whole
    [source] = [m.message for m in read_messages(out, "/reference/source")]
    assert source["layout"] == "witsml-1.3.1.1"


def _old_log(curves: str, rows: str = "<data>2020-01-01T00:00:00,1,2</data>") -> bytes:
    return f"""<logs xmlns="http://www.witsml.org/schemas/131" version="1.3.1.1">
<log uid="L"><nameWell>W</nameWell><name>old</name><indexType>date time</indexType>
<indexCurve columnIndex="1">TIME</indexCurve>{curves}<logData>{rows}</logData></log>
</logs>""".encode()


@pytest.mark.parametrize(("curves", "reason"), [
    ("<logCurveInfo><mnemonic>TIME</mnemonic><columnIndex>1</columnIndex></logCurveInfo>"
     "<logCurveInfo><mnemonic>HKLD</mnemonic><unit>kN</unit></logCurveInfo>",
     "nor a columnIndex in every logCurveInfo (1.3.1.1) (none in HKLD)"),
    ("<logCurveInfo><mnemonic>TIME</mnemonic><columnIndex>1</columnIndex></logCurveInfo>"
     "<logCurveInfo><mnemonic>HKLD</mnemonic><columnIndex>1</columnIndex></logCurveInfo>",
     "curves 'TIME' and 'HKLD' both have columnIndex 1"),
])
def test_witsml_1311_column_mistakes_are_named(tmp_path: Path, curves: str, reason: str) -> None:
    bad = tmp_path / "old.xml"
    bad.write_bytes(_old_log(curves))
    with pytest.raises(IngestError) as error:
        import_witsml([bad], tmp_path / "o.mcap", prefix="rig/T")
    assert reason in str(error.value) and str(bad) in str(error.value)


def test_a_curve_with_column_index_0_has_no_values_and_is_listed(tmp_path: Path) -> None:
    log = tmp_path / "old.xml"
    log.write_bytes(_old_log(
        "<logCurveInfo><mnemonic>TIME</mnemonic><columnIndex>1</columnIndex></logCurveInfo>"
        "<logCurveInfo><mnemonic>HKLD</mnemonic><unit>kN</unit><columnIndex>3</columnIndex>"
        "</logCurveInfo><logCurveInfo><mnemonic>BITDEP</mnemonic><unit>m</unit>"
        "<columnIndex>2</columnIndex></logCurveInfo><logCurveInfo><mnemonic>SPARE</mnemonic>"
        "<columnIndex>0</columnIndex></logCurveInfo>",
        "<data>2020-01-01T00:00:00,1500.5,640</data>"))
    result = import_witsml([log], tmp_path / "o.mcap", prefix="rig/T")
    fates = {fate.mnemonic: fate.note for fate in result.curve_report}
    assert fates == {"TIME": "the index (time)", "BITDEP": "taken as bit_depth (mnemonic)",
                     "HKLD": "taken as hookload (mnemonic)",
                     "SPARE": "no values in the data rows"}
    series = _series(tmp_path / "o.mcap")
    assert series == {"bit_depth": [(1577836800.0, 1500.5)],
                      "hookload": [(1577836800.0, 640_000.0)]}


# -- the import summary ------------------------------------------------------------------------

def _rich_log(torque: str, torque_description: str) -> bytes:
    """A time log with the _AVG curves of a richer export, a block position, a hook-load
    maximum, a gas curve and a torque curve under the given mnemonic."""
    curves = [("TIME", "s", ""), ("HKLD_AVG", "kN", "Hookload average"),
              ("WOB_AVG", "kN", "Weight on bit average"),
              ("BLOCKCOMP", "m", "Block position, heave compensated"),
              ("BITDEP", "m", "Bit depth"), (torque, "kN.m", torque_description),
              ("HKLD_MAX", "kN", "Hookload maximum"), ("GASX", "%", "Total gas")]
    infos = "".join(f"<logCurveInfo><mnemonic>{m}</mnemonic><unit>{u}</unit>"
                    f"<curveDescription>{d}</curveDescription></logCurveInfo>"
                    for m, u, d in curves)
    return f"""<logs xmlns="http://www.witsml.org/schemas/1series" version="1.4.1.1">
<log uid="R1"><nameWell>W</nameWell><name>rich</name><indexType>date time</indexType>
<indexCurve>TIME</indexCurve>{infos}<logData>
<mnemonicList>{','.join(m for m, _, _ in curves)}</mnemonicList>
<unitList>{','.join(u for _, u, _ in curves)}</unitList>
<data>2020-01-01T00:00:00Z,1200,50,12.5,2500,18,1300,0.4</data>
</logData></log></logs>""".encode()


def _import(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[str, dict[str, Any]]:
    """The command's text summary and, run again with --json, its JSON summary."""
    assert main(["import", "witsml", *args]) == 0
    text = capsys.readouterr().out
    assert main(["import", "witsml", *args, "--json"]) == 0
    return text, json.loads(capsys.readouterr().out)["log"]


def test_the_summary_lists_every_curve_and_says_what_would_take_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "rich.xml"
    log.write_bytes(_rich_log("STRQ", "Surface torque"))
    out = str(tmp_path / "o.mcap")
    text, summary = _import(capsys, str(log), "--out", out)
    notes = {item["mnemonic"]: item["note"] for item in summary["curve_report"]}
    assert notes == {
        "TIME": "the index (time)",
        "HKLD_AVG": "taken as hookload (mnemonic)",
        "WOB_AVG": "taken as wob (mnemonic)",
        "BLOCKCOMP": "taken as block_position (mnemonic)",
        "BITDEP": "taken as bit_depth (mnemonic)",
        "STRQ": "not mapped: looks like torque; add --curve torque=STRQ",
        "HKLD_MAX": "not mapped: an extreme of hookload? (the model compares averages; "
                    "--curve hookload=HKLD_MAX takes it)",
        "GASX": "not mapped (no channel of tdmon)",
    }
    assert [item["mnemonic"] for item in summary["curve_report"]] == [
        "TIME", "HKLD_AVG", "WOB_AVG", "BLOCKCOMP", "BITDEP", "STRQ", "HKLD_MAX", "GASX"]
    # the text summary has one line per curve, each with its note
    assert "curves of the log (WITSML 1.4.1.1), 8:" in text
    assert re.search(r"\n    STRQ \[kN\.m\] +not mapped: looks like torque; add --curve "
                     r"torque=STRQ\n", text), text
    # following the advice takes it
    _, summary = _import(capsys, str(log), "--out", out, "--curve", "torque=STRQ")
    notes = {item["mnemonic"]: item["note"] for item in summary["curve_report"]}
    assert notes["STRQ"] == "taken as torque (--curve)"
    assert summary["per_channel"]["torque"] == 1
    values = {channel: v for channel, [(_, v)] in _series(Path(out)).items()}
    assert values == {"hookload": 1.2e6, "wob": 5e4, "block_position": 12.5,
                      "bit_depth": 2500.0, "torque": 18e3}


def test_average_mnemonics_of_richer_exports_are_taken(tmp_path: Path) -> None:
    log = tmp_path / "rich.xml"
    log.write_bytes(_rich_log("TORQUE_AVG", "Surface torque average"))
    result = import_witsml([log], tmp_path / "o.mcap", prefix="rig/T")
    assert result.curves == {"hookload": "HKLD_AVG [kN]", "torque": "TORQUE_AVG [kN.m]",
                             "block_position": "BLOCKCOMP [m]", "wob": "WOB_AVG [kN]",
                             "bit_depth": "BITDEP [m]"}
