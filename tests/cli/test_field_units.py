"""Field units in and out: flags with units, ``--units field`` tables, report and Rerun views,
JSON and recordings staying SI.

Conversion factors here are written out independently of pint (exact definitions: 1 ft =
0.3048 m, 1 lbf = 4.4482216152605 N, degF = degC * 1.8 + 32).
"""

from __future__ import annotations

import json
import math
import re
from collections import defaultdict
from pathlib import Path
from typing import Any

import pytest
from rerun.chunk import RrdReader

from tdmon.cli import main
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.record.reader import read_messages
from tdmon.record.synthetic import T0, T0_NS, synthetic_messages

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"
APAK = ROOT / "config" / "wells" / "thesis-case2-apak.toml"
FT = 0.3048  # m
LBF = 4.4482216152605  # N
KLBF = 1e3 * LBF
KFTLBF = 1e3 * FT * LBF  # N m


def _json(capsys: pytest.CaptureFixture[str], *argv: str) -> dict[str, Any]:
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def _text(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    assert main(list(argv)) == 0
    return capsys.readouterr().out


def _exit_error(capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    with pytest.raises(SystemExit) as exit_info:
        main(list(argv))
    assert exit_info.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    return err


# -- flags with units ------------------------------------------------------------------------


def test_bit_depth_wob_and_bit_torque_with_units_equal_the_si_numbers(capsys):
    with_units = _json(capsys, "model", "loads", "--well", str(EXAMPLE), "--mu", "0.2",
                       "--bit-depth", "10000 ft", "--wob", "20 klbf", "--bit-torque",
                       "5 kft*lbf", "--json")
    si = _json(capsys, "model", "loads", "--well", str(EXAMPLE), "--mu", "0.2",
               "--bit-depth", str(10000 * FT), "--wob", str(20 * KLBF),
               "--bit-torque", str(5 * KFTLBF), "--json")
    assert with_units["bit_depth_m"] == pytest.approx(3048.0, rel=1e-12)
    assert with_units["hookload_N"] == pytest.approx(si["hookload_N"], rel=1e-9)
    assert with_units["torque_Nm"] == pytest.approx(si["torque_Nm"], rel=1e-9)
    # the on-bottom hook load is the rotating one less the WOB (the string's weight is shared)
    hookload = with_units["hookload_N"]
    assert hookload["rotating"] - hookload["on_bottom"] == pytest.approx(20 * KLBF, rel=1e-6)
    assert with_units["torque_Nm"]["on_bottom"] > with_units["torque_Nm"]["rotating"]


def test_oilfield_fraction_and_metric_units_are_read(capsys):
    fraction = _json(capsys, "model", "loads", "--well", str(EXAMPLE), "--bit-depth",
                     "9000 1/2 ft", "--json")
    metres = _json(capsys, "model", "loads", "--well", str(EXAMPLE), "--bit-depth",
                   "2.7447 km", "--json")
    assert fraction["bit_depth_m"] == pytest.approx(9000.5 * FT, rel=1e-12)
    assert metres["bit_depth_m"] == pytest.approx(2744.7, rel=1e-12)


def test_step_flags_take_units(capsys):
    document = _json(capsys, "model", "broomstick", "--well", str(EXAMPLE), "--mu", "0.2",
                     "--step", "1000 ft", "--json")
    assert document["bit_depth_m"][:3] == pytest.approx([304.8, 609.6, 914.4], rel=1e-12)
    out = _text(capsys, "model", "temperature", "--well", str(APAK), "--step", "5000 ft",
                "--units", "field")
    assert "about every 5000 ft" in out


@pytest.mark.parametrize(("flag", "value", "expected"), [
    ("--bit-depth", "6500 furlongz", "unknown unit 'furlongz'"),
    ("--bit-depth", "6500 klbf", "cannot be converted to 'm'"),
    ("--wob", "twenty klbf", "'twenty klbf'"),
    ("--bit-torque", "inf", "not finite"),
])
def test_bad_values_are_one_line_naming_the_flag_with_an_example(capsys, flag, value, expected):
    err = _exit_error(capsys, "model", "loads", "--well", str(EXAMPLE), flag, value)
    assert f"argument {flag}" in err and expected in err and "e.g. '" in err, err


def test_bad_units_option_and_environment(capsys, monkeypatch):
    err = _exit_error(capsys, "model", "loads", "--well", str(EXAMPLE), "--units", "imperial")
    assert "--units" in err and "'field'" in err
    monkeypatch.setenv("TDMON_UNITS", "imperial")
    assert main(["model", "loads", "--well", str(EXAMPLE)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [err] and "TDMON_UNITS='imperial'" in err


# -- tables ----------------------------------------------------------------------------------


def _loads_table(out: str) -> dict[str, float]:
    """``{"bit depth": ..., "block weight": ..., "<section> <row>": value}`` of the text."""
    first = out.splitlines()[0]
    values = {
        "bit depth": float(re.search(r"bit at ([\d.]+) ", first)[1]),
        "block weight": float(re.search(r"block weight ([\d.]+) ", first)[1]),
    }
    section = ""
    for line in out.splitlines()[1:]:
        name, _, number = line.strip().rpartition(" ")
        try:
            values[f"{section} {name.strip()}"] = float(number)
        except ValueError:
            section = name.strip() or number
    return values


def test_loads_table_in_field_units_is_the_si_table_converted(capsys):
    common = ["model", "loads", "--well", str(EXAMPLE), "--mu", "0.15", "--bit-depth",
              "3500", "--wob", "80 kN", "--bit-torque", "6 kN*m"]
    si_out = _text(capsys, *common)
    field_out = _text(capsys, *common, "--units", "field")
    assert "kN" in si_out and "klbf" not in si_out
    assert "klbf" in field_out and "kft lbf" in field_out and "ft MD" in field_out
    assert "kN" not in field_out
    si, field = _loads_table(si_out), _loads_table(field_out)
    assert len(si) == len(field) == 2 + 5 + 2
    for (key, si_value), field_value in zip(si.items(), field.values(), strict=True):
        if key == "bit depth":
            expected, tolerance = si_value / FT, 0.05 / FT + 0.05
        elif "torque" in key:
            expected, tolerance = si_value * 1e3 / KFTLBF, 0.005 * 1e3 / KFTLBF + 0.005
        else:
            expected, tolerance = si_value * 1e3 / KLBF, 0.05 * 1e3 / KLBF + 0.05
        assert field_value == pytest.approx(expected, abs=tolerance), key


def test_broomstick_text_in_field_units_matches_the_json(capsys):
    argv = ["model", "broomstick", "--well", str(EXAMPLE), "--mu", "0.1,0.3", "--step", "500"]
    document = _json(capsys, *argv, "--json")
    out = _text(capsys, *argv, "--units", "field")
    lines = out.splitlines()
    assert lines[0] == ("hook load in klbf (PU pick-up, SO slack-off), off-bottom torque T in "
                        "kft lbf")
    assert lines[1].split()[:3] == ["bit", "depth", "ft"]
    rows = [[float(x) for x in line.split()] for line in lines[2:]]
    assert len(rows) == len(document["bit_depth_m"])
    for j, row in enumerate(rows):
        assert row[0] == pytest.approx(document["bit_depth_m"][j] / FT, abs=0.05)
        for i in range(2):
            pick_up, slack_off, torque = row[1 + 3 * i: 4 + 3 * i]
            assert pick_up == pytest.approx(
                document["hookload_N"]["pick_up"][i][j] / KLBF, abs=0.05)
            assert slack_off == pytest.approx(
                document["hookload_N"]["slack_off"][i][j] / KLBF, abs=0.05)
            assert torque == pytest.approx(
                document["torque_Nm"]["rotating"][i][j] / KFTLBF, abs=0.005)
        rotating = document["hookload_N"]["rotating"]
        rotating = rotating[0] if isinstance(rotating[0], list) else rotating
        assert row[-1] == pytest.approx(rotating[j] / KLBF, abs=0.05)


def test_temperature_table_in_field_units(capsys, monkeypatch):
    document = _json(capsys, "model", "temperature", "--well", str(APAK), "--json")
    monkeypatch.setenv("TDMON_UNITS", "field")  # the environment chooses when --units does not
    out = _text(capsys, "model", "temperature", "--well", str(APAK), "--step", "1000")
    bottom = document["bottom"]
    assert (f"annulus {bottom['annulus_C'] * 1.8 + 32:.2f} degF "
            f"({bottom['annulus_C']:.2f} degC)") in out
    row = out.splitlines()[-2].split()
    assert float(row[0]) == pytest.approx(document["md_m"][-1] / FT, abs=0.05)
    assert float(row[3]) == pytest.approx(document["annulus_C"][-1] * 1.8 + 32, abs=0.005)
    # --units beats the environment
    assert "degC" in _text(capsys, "model", "temperature", "--well", str(APAK), "--units", "si")


def test_json_stays_si_whatever_the_units(capsys, monkeypatch):
    argv = ["model", "loads", "--well", str(EXAMPLE), "--bit-depth", "3000", "--json"]
    si = _json(capsys, *argv)
    assert _json(capsys, *argv, "--units", "field") == si
    monkeypatch.setenv("TDMON_UNITS", "field")
    assert _json(capsys, *argv) == si
    assert set(si) >= {"bit_depth_m", "hookload_N", "torque_Nm", "block_weight_N"}
    broom = ["model", "broomstick", "--well", str(EXAMPLE), "--mu", "0.2", "--json"]
    assert _json(capsys, *broom, "--units", "field") == _json(capsys, *broom, "--units", "si")


# -- report and Rerun views ----------------------------------------------------------------


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Five minutes of every topic in one finished MCAP file."""
    folder = tmp_path_factory.mktemp("recording")
    with McapRecorder(folder) as recorder:
        for item in synthetic_messages(duration_s=300):
            recorder.write(*item)
        # then a minute rotating off bottom at 3000 m: the report draws rotating torque only
        for second in range(300, 360):
            ns, t = T0_NS + second * 10**9, T0 + second
            recorder.write("/tdmon/state", ns, {"t": t, "state": "rotating_off_bottom",
                                                "steady": True, "bit_depth_m": 3000.0})
            recorder.write("/tdmon/model", ns, {
                "t": t, "bit_depth_m": 3000.0,
                "hookload_N": {"pick_up": 1.1e6, "slack_off": 0.9e6, "rotating": 1.0e6},
                "torque_Nm": {"rotating": 9.0e3},
                "band": {"mu": [0.2], "pick_up_N": [1.1e6], "slack_off_N": [0.9e6]},
                "measured": {"hookload_N": 1.0e6, "torque_Nm": 9.1e3},
                "residual": {"hookload_N": 0.0, "torque_Nm": 100.0}})
    [path] = recorder.stats.files
    return Path(path)


def _cells(html_text: str, header: str) -> list[list[str]]:
    """Rows of the HTML table whose header contains ``header``."""
    for table in re.findall(r"<table>(.*?)</table>", html_text, re.S):
        if header in table:
            body = table.split("<tbody>")[1]
            return [re.findall(r"<td>(.*?)</td>", row) for row in body.split("<tr>")[1:]]
    raise AssertionError(f"no table with {header}")


def test_report_in_field_units(tmp_path, capsys, monkeypatch, recording):
    import tdmon.record.report as report

    labels: list[str] = []
    save = report._save

    def keep_labels(figure: Any, path: Path) -> Path:
        for axes in figure.axes:
            labels.extend((axes.get_xlabel(), axes.get_ylabel()))
        return save(figure, path)

    monkeypatch.setattr(report, "_save", keep_labels)
    out = tmp_path / "field"
    assert main(["report", str(recording), "--out", str(out), "--units", "field"]) == 0
    capsys.readouterr()
    assert "Hook load [klbf]" in labels and "Torque [kft lbf]" in labels
    assert "Bit depth [ft MD]" in labels and "Bit depth [ft]" in labels
    assert not [label for label in labels if "kN" in label or "[m" in label], labels

    # the loads table: values of the messages, converted here
    models = [m for _, _, m in read_messages(recording, ["/tdmon/model"])]
    page = (out / "report.html").read_text()
    assert "measured hook load [klbf]" in page and "bit depth [ft]" in page
    rows = _cells(page, "measured hook load")
    assert sum(int(row[1]) for row in rows) == len(models)
    deepest = max(float(row[2].split(" - ")[1]) for row in rows)
    assert deepest == pytest.approx(max(m["bit_depth_m"] for m in models) / FT, abs=0.05)
    all_states = [float(row[3]) * int(row[1]) for row in rows]
    mean_klbf = sum(m["measured"]["hookload_N"] for m in models) / len(models) / KLBF
    assert sum(all_states) / len(models) == pytest.approx(mean_klbf, abs=0.05)
    # estimates.csv stays SI (the unit in its column names), the same as an SI report
    assert main(["report", str(recording), "--out", str(tmp_path / "si")]) == 0
    assert (out / "estimates.csv").read_text() == (tmp_path / "si" / "estimates.csv").read_text()
    assert "measured hook load [kN]" in (tmp_path / "si" / "report.html").read_text()


def _rrd(path: Path) -> tuple[dict[str, list[float]], dict[str, set[str]], set[str]]:
    """Scalars per entity, static series names per entity, and the blueprint's view names."""
    reader = RrdReader(path)
    scalars: dict[str, list[float]] = defaultdict(list)
    names: dict[str, set[str]] = defaultdict(set)
    for chunk in reader.stream().to_chunks():
        batch = chunk.to_record_batch()
        for column in batch.schema.names:
            if column == "Scalars:scalars":
                scalars[chunk.entity_path] += [v[0] for v in batch.column(column).to_pylist()]
            elif column.endswith(":names"):
                names[chunk.entity_path].update(v[0] for v in batch.column(column).to_pylist())
    views: set[str] = set()
    for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
        batch = chunk.to_record_batch()
        for column in batch.schema.names:
            if column.endswith(":display_name"):
                views.update(str(v[0]) for v in batch.column(column).to_pylist() if v)
    return dict(scalars), dict(names), views


def test_rerun_views_in_field_units(tmp_path, capsys, recording):
    rrd = tmp_path / "field.rrd"
    assert main(["view", str(recording), "--rrd", str(rrd), "--no-progress",
                 "--units", "field"]) == 0
    capsys.readouterr()
    scalars, names, views = _rrd(rrd)
    models = [m for _, _, m in read_messages(recording, ["/tdmon/model"])]
    hookload = [m["measured"]["hookload_N"] / KLBF for m in models]
    torque = [m["measured"]["torque_Nm"] / KFTLBF for m in models]
    pick_up = [m["hookload_N"]["pick_up"] / KLBF for m in models]
    assert scalars["/hookload_klbf/measured"] == pytest.approx(hookload, rel=1e-9)
    assert scalars["/torque_kftlbf/measured"] == pytest.approx(torque, rel=1e-9)
    assert scalars["/hookload_klbf/model/pick_up"] == pytest.approx(pick_up, rel=1e-9)
    # against bit depth the rows come in depth order
    assert sorted(scalars["/vs_depth/hookload_klbf/measured"]) == pytest.approx(
        sorted(hookload), rel=1e-9)
    states = [m for _, _, m in read_messages(recording, ["/tdmon/state"])]
    assert scalars["/bit_depth_ft"] == pytest.approx([s["bit_depth_m"] / FT for s in states],
                                                     rel=1e-9)
    samples = [m for _, _, m in read_messages(recording, ["/tdmon/sample"])
               if m["channel"] == "hookload"]
    assert sorted(scalars["/samples/hookload"]) == pytest.approx(
        sorted(s["value"] / KLBF for s in samples), rel=1e-9)
    assert names["/samples/hookload"] == {"hookload [klbf]"}
    assert not [e for e in scalars if "kN" in e or e.endswith("_m")], sorted(scalars)
    assert {"Hook load [klbf]", "Torque [kft lbf]", "Hook load vs bit depth [klbf]",
            "Against bit depth (select timeline bit_depth_in)"} <= views
    # the depth timeline in whole inches
    reader = RrdReader(rrd)
    timelines = {name for chunk in reader.stream().to_chunks()
                 if chunk.entity_path.startswith("/vs_depth/") for name in chunk.timeline_names}
    assert timelines == {"bit_depth_in"}


def test_rerun_views_in_si_are_as_before(tmp_path, capsys, recording):
    rrd = tmp_path / "si.rrd"
    assert main(["view", str(recording), "--rrd", str(rrd), "--no-progress"]) == 0
    capsys.readouterr()
    scalars, names, views = _rrd(rrd)
    models = [m for _, _, m in read_messages(recording, ["/tdmon/model"])]
    assert scalars["/hookload_kN/measured"] == pytest.approx(
        [m["measured"]["hookload_N"] / 1e3 for m in models], rel=1e-12)
    samples = [m["value"] for _, _, m in read_messages(recording, ["/tdmon/sample"])
               if m["channel"] == "hookload"]
    assert sorted(scalars["/samples/hookload"]) == pytest.approx(sorted(samples), rel=1e-12)
    assert names["/samples/hookload"] == {"hookload [N]"}
    assert {"Hook load [kN]", "Torque [kN m]", "Decoded samples (SI)"} <= views


def _daemon_file(tmp_path: Path, display: str) -> Path:
    text = (ROOT / "config" / "daemon" / "replay-sim-trip-in.toml").read_text()
    text = text.replace('"../../', f'"{ROOT}/') + display
    path = tmp_path / "daemon.toml"
    path.write_text(text)
    return path


def test_daemon_files_display_units_reach_the_replays_rerun_views(tmp_path, capsys):
    config = _daemon_file(tmp_path, '\n[display]\nunits = "field"\n')
    replay = ROOT / "replays" / "trip-in-noisy.mcap"
    out, rrd = tmp_path / "field.mcap", tmp_path / "field.rrd"
    assert main(["replay", str(replay), "--config", str(config), "--out", str(out), "--rrd",
                 str(rrd), "--recorder", "inline", "--no-progress", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rrd"] == str(rrd)
    scalars, _, views = _rrd(rrd)
    models = [m for _, _, m in read_messages(out, ["/tdmon/model"])]
    measured = [m["measured"]["hookload_N"] for m in models]
    assert scalars["/hookload_klbf/measured"] == pytest.approx(
        [v / KLBF for v in measured if v is not None and math.isfinite(v)], rel=1e-9)
    assert "Hook load [klbf]" in views
    # the recording itself is SI whatever the display: the same as with --units si
    si_out, si_rrd = tmp_path / "si.mcap", tmp_path / "si.rrd"
    assert main(["replay", str(replay), "--config", str(config), "--out", str(si_out),
                 "--rrd", str(si_rrd), "--recorder", "inline", "--no-progress", "--units",
                 "si"]) == 0
    capsys.readouterr()
    assert "/hookload_kN/measured" in _rrd(si_rrd)[0]

    def content(path: Path) -> list[tuple[str, Any]]:
        skip = {"/tdmon/status"}  # wall-clock lag and rates
        return [(topic, message) for topic, _, message in read_messages(path)
                if topic not in skip]

    assert content(out) == content(si_out)


def test_bad_display_units_in_the_daemon_file(tmp_path, capsys):
    config = _daemon_file(tmp_path, '\n[display]\nunits = "imperial"\n')
    assert main(["run", "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [err] and "display.units" in err and str(config) in err


def test_unit_system_conversions_against_exact_definitions():
    from tdmon.display import current, unit_system, using

    field, si = unit_system("field"), unit_system("si")
    assert field.depth(1000.0) == pytest.approx(1000 / FT, rel=1e-12)
    assert field.force(KLBF) == pytest.approx(1.0, rel=1e-12)
    assert field.torque(KFTLBF) == pytest.approx(1.0, rel=1e-12)
    assert field.temperature(100.0) == pytest.approx(212.0, rel=1e-12)
    assert field.density(1198.264) == pytest.approx(10.0, rel=1e-5)  # 10 ppg
    assert field.pressure(6894.757) == pytest.approx(1.0, rel=1e-6)
    assert field.flow(3.785411784e-3 / 60) == pytest.approx(1.0, rel=1e-9)  # US gal/min
    assert field.rotation(2 * math.pi) == pytest.approx(60.0, rel=1e-12)
    assert si.force(1234.0) == 1.234 and si.pressure(1e5) == 1.0
    assert si.flow(1e-3 / 60) == pytest.approx(1.0, rel=1e-12)
    assert field.label("torque") == "kft lbf" and si.label("torque") == "kN m"
    assert field.unit("depth").inverse(field.depth(123.4)) == pytest.approx(123.4)
    assert current() is si
    with using(field):
        assert current() is field
    assert current() is si
