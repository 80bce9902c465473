"""Model coverage (docs/daemon.md): a string tally shorter than the bit depth raises a critical
``model_coverage`` alarm at once and the model goes on with the top component taken to surface;
``[[runs]]`` switch the well file at a rig time; a new well is recorded on ``/tdmon/well``.
The replay is replays/model-error-tally.mcap: the rig's string is 3630 m (180 m of HWDP), the
well file's 3600 m (150 m), and the trip starts with the bit at 3630 m."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path
from typing import Any

import pytest

from tdmon.config.daemon import load_daemon_config
from tdmon.config.well_file import read_well_path
from tdmon.daemon.pipeline import Frame
from tdmon.daemon.steps.coverage import CoverageStep
from tdmon.errors import ConfigError
from tdmon.model.torque_drag import WellModel
from tdmon.record.reader import RecordedMessage, read_messages
from tdmon.replay.driver import replay

ROOT = Path(__file__).resolve().parents[2]
REPLAY = ROOT / "replays" / "model-error-tally.mcap"
WELL = ROOT / "replays" / "scenarios" / "wells" / "example-7-1-weights.toml"
START = 1709640000.0  # the replay's start, 2024-03-05T12:00:00Z
TALLY = 3600.0  # [m], the well file's string
TRUE_TALLY = 3630.0  # [m], the rig's


def _config(folder: Path, runs: str = "") -> Path:
    path = folder / "daemon.toml"
    path.write_text(f"""
prefix = "sim/model-error"
well = "{WELL}"
[sources.mcap]
path = "{REPLAY}"
speed = "max"
[align]
stale_timeout = "20 s"
max_wait = "0.25 s"
[monitor]
mu = 0.25
band_mu = [0.1, 0.2, 0.3, 0.4]
method = "soft-string"
grid_step = "10 m"
[calibration]
enabled = true
in_slips_margin = "150 kN"
{runs}
""")
    return path


def _true_well_file(folder: Path) -> Path:
    """The well file with the rig's tally: 180 m of HWDP."""
    text = WELL.read_text()
    assert 'length = "150 m"' in text
    path = folder / "true-tally.toml"
    path.write_text(text.replace('length = "150 m"', 'length = "180 m"'))
    return path


def _replayed(folder: Path, runs: str = "") -> list[RecordedMessage]:
    config = load_daemon_config(_config(folder, runs))
    out = folder / "out.mcap"
    result = asyncio.run(replay(REPLAY, config, out))
    assert result.step_errors == 0
    return list(read_messages(out, ["/tdmon/alarm", "/tdmon/model", "/tdmon/well",
                                    "/tdmon/estimate"]))


def _of(messages: list[RecordedMessage], topic: str) -> list[dict[str, Any]]:
    return [m.message for m in messages if m.topic == topic]


def test_short_tally_alarms_at_once_and_the_model_goes_on(tmp_path: Path) -> None:
    messages = _replayed(tmp_path)
    coverage = [a for a in _of(messages, "/tdmon/alarm") if a["kind"] == "model_coverage"]
    assert len(coverage) == 1  # once per well file, not per frame
    [alarm] = coverage
    assert alarm["severity"] == "critical"
    assert alarm["t"] - START < 5.0  # on the first frames, not after a window
    assert alarm["message"].startswith(
        "string tally 30.0 m shorter than bit depth 3630.0 m: the top component (drill pipe) "
        "is taken to surface; check the well file example-7-1-weights.toml")
    assert alarm["limit"] == pytest.approx(TALLY)
    # model output and estimates below the file's tally: the drill pipe taken to surface
    deep_models = [m for m in _of(messages, "/tdmon/model") if m["bit_depth_m"] > TALLY + 1]
    assert len(deep_models) > 100
    paper = read_well_path(WELL).well
    assert paper.string.length == pytest.approx(paper.hole_bottom)
    model = WellModel(paper)
    for message in deep_models[::40]:
        bit = message["bit_depth_m"]
        expected, _ = model.evaluate("rotating", bit, 0.25)
        assert message["hookload_N"]["rotating"] == pytest.approx(expected, rel=1e-3)
    windows = [e for e in _of(messages, "/tdmon/estimate")
               if e["kind"] == "window" and e["bit_depth_m"] > TALLY + 1]
    assert {e["operation"] for e in windows} >= {"pick_up"}
    [well] = _of(messages, "/tdmon/well")
    assert well["string_length_m"] == pytest.approx(TALLY)
    assert well["file"] == WELL.name and well["change"] == "start"


def test_runs_switch_the_well_file_at_their_start(tmp_path: Path) -> None:
    true_file = _true_well_file(tmp_path)
    switch = START + 300.0
    messages = _replayed(tmp_path, f"""
[[runs]]
start = {switch}
well = "{true_file}"
""")
    first, second = _of(messages, "/tdmon/well")
    assert first["change"] == "start" and first["string_length_m"] == pytest.approx(TALLY)
    assert second["file"] == true_file.name
    assert second["string_length_m"] == pytest.approx(TRUE_TALLY)
    assert second["change"] == "run 2 from 2024-03-05T12:05:00Z"
    assert switch <= second["t"] < switch + 2.0
    assert second["md_m"] == first["md_m"]  # the same hole
    alarms = [a for a in _of(messages, "/tdmon/alarm") if a["kind"] == "model_coverage"]
    assert [a["severity"] for a in alarms] == ["critical", "info"]
    assert alarms[1]["message"] == (
        "run 2 from 2024-03-05T12:05:00Z: well file true-tally.toml in use (was "
        "example-7-1-weights.toml): string tally 3600.0 m -> 3630.0 m, fluid 1400 -> 1400 "
        "kg/m3, block 300 -> 300 kN")
    # the monitor models the file in use: before the switch the file's string, after it the
    # rig's (30 m more HWDP: heavier in the tangent)
    paper = WellModel(read_well_path(WELL).well)
    rig = WellModel(read_well_path(true_file).well)
    models = _of(messages, "/tdmon/model")
    for message in models[::50]:
        bit = message["bit_depth_m"]
        which = rig if message["t"] >= second["t"] else paper
        other = paper if which is rig else rig
        expected, _ = which.evaluate("rotating", bit, 0.25)
        assert message["hookload_N"]["rotating"] == pytest.approx(expected, rel=1e-3)
        assert not math.isclose(message["hookload_N"]["rotating"],
                                other.evaluate("rotating", bit, 0.25)[0], rel_tol=3e-3)


def test_run_sections_are_checked(tmp_path: Path) -> None:
    true_file = _true_well_file(tmp_path)
    runs = f"""
[[runs]]
start = "2024-03-05T12:10:00Z"
well = "{true_file}"
[[runs]]
start = "2024-03-05T12:05:00Z"
well = "{true_file}"
"""
    with pytest.raises(ConfigError, match=r"runs\[1\]\.start: each run must start after"):
        load_daemon_config(_config(tmp_path, runs))
    missing = f"""
[[runs]]
start = "2024-03-05T12:10:00Z"
well = "{tmp_path / 'nowhere.toml'}"
"""
    with pytest.raises(ConfigError, match=r"runs\[0\]\.well: file not found"):
        load_daemon_config(_config(tmp_path, missing))
    with pytest.raises(ConfigError, match=r"runs\[0\]\.start"):
        load_daemon_config(_config(tmp_path, f"""
[[runs]]
start = "yesterday"
well = "{true_file}"
"""))
    config = load_daemon_config(_config(tmp_path, runs.replace("12:05", "12:15")))
    assert [run.start for run in config.runs] == [START + 600.0, START + 900.0]


def _frame(t: float, bit: float) -> Frame:
    return Frame(t=t, log_time_ns=int(t * 1e9), values={"bit_depth": bit}, ages={})


def _step(tmp_path: Path) -> tuple[CoverageStep, list[tuple[str, dict[str, Any]]], Path,
                                   list[str]]:
    well = tmp_path / "well.toml"
    well.write_text(WELL.read_text())
    taken: list[str] = []
    step = CoverageStep(read_well_path(well), reader=read_well_path,
                        targets=[lambda new, why: taken.append(f"{new.path.name}: {why}")])
    sent: list[tuple[str, dict[str, Any]]] = []
    return step, sent, well, taken


def test_reload_takes_a_new_string_and_leaves_an_unchanged_file(tmp_path: Path) -> None:
    step, sent, well, taken = _step(tmp_path)
    emit = lambda topic, message: sent.append((topic, message))  # noqa: E731
    step.on_frame(_frame(START, 3000.0), emit)
    step.request_reload()
    step.on_frame(_frame(START + 1, 3000.0), emit)
    assert sent == [] and taken == []  # the same bytes: nothing to do
    well.write_text(well.read_text().replace('length = "3330 m"', 'length = "3000 m"'))
    step.request_reload()
    step.on_frame(_frame(START + 2, 3000.0), emit)
    assert taken == ["well.toml: reload (SIGHUP)"]
    [(topic, alarm)] = sent
    assert topic == "alarm"
    assert alarm["severity"] == "info" and "string tally 3600.0 m -> 3270.0 m" in alarm["message"]
    # the new tally is shorter than the bit: critical on the next deeper frame
    step.on_frame(_frame(START + 3, 3300.0), emit)
    assert sent[-1][1]["severity"] == "critical"
    assert "string tally 30.0 m shorter than bit depth 3300.0 m" in sent[-1][1]["message"]


def test_a_new_hole_or_a_broken_file_keeps_the_old_well(tmp_path: Path) -> None:
    step, sent, well, taken = _step(tmp_path)
    emit = lambda topic, message: sent.append((topic, message))  # noqa: E731
    before = step.well_file
    well.write_text(well.read_text().replace('element_length = "10 m"',
                                             'element_length = "20 m"'))
    step.request_reload()
    step.on_frame(_frame(START, 3000.0), emit)
    assert "changes the hole" in sent[-1][1]["message"]
    assert sent[-1][1]["severity"] == "critical"
    well.write_text("[well\n")
    step.request_reload()
    step.on_frame(_frame(START + 1, 3000.0), emit)
    assert "cannot read the well file well.toml" in sent[-1][1]["message"]
    assert step.well_file is before and taken == []


def test_the_model_well_reaches_the_hole_bottom() -> None:
    well_file = read_well_path(WELL)
    assert well_file.tally_length == pytest.approx(TALLY)
    components = well_file.well.string.components
    bottom = well_file.well.hole_bottom
    assert well_file.well.string.length == pytest.approx(bottom)
    # only the top component is longer: by the hole's depth less the tally
    assert [c.length for c in components] == pytest.approx([120.0, 150.0,
                                                            3330.0 + bottom - TALLY])


VOLVE_HEADER = ("time_utc,hole_depth_m,bit_depth_m,hookload_kN,surface_torque_kNm,surface_rpm,"
                "bit_rpm,flow_in_Lpm,flow_out_Lpm,spp_bar,wob_kN,rop_mph,rig_activity_code,"
                "block_pos_comp_m,block_pos_uncomp_m,rig_heave_m,bit_depth_5s_m")


def _volve_rows(first: int, last: int) -> str:
    """Rows in the layout of the Volve F-4 logs: a pull of 0.5 m per 15 s row from 2500 m."""
    rows = [VOLVE_HEADER]
    for i in range(first, last):
        minute, second = divmod(15 * i, 60)
        hour, minute = divmod(minute, 60)
        rows.append(f"2016-10-04T{17 + hour:02d}:{minute:02d}:{second:02d}Z,3510,"
                    f"{2500 - 0.5 * i:.1f},{1600 + i % 5},0.0052,0.23,0.23,0,36,-0.4,5.4,0,7,"
                    f"{12 + 0.5 * (i % 20):.1f},12.8,-0.08,2500")
    return "\n".join(rows) + "\n"


def _wait_for(path: Path, text: str, timeout: float = 30) -> None:
    import time

    deadline = time.monotonic() + timeout
    while text not in path.read_text():
        assert time.monotonic() < deadline, f"'{text}' never appeared: {path.read_text()}"
        time.sleep(0.05)


def test_sighup_reloads_the_well_file_of_a_running_daemon(
        tmp_path: Path, free_tcp_port: Any) -> None:
    """``tdmon run`` over Zenoh: half a trip, the well file edited (string 2574 m -> 2400 m),
    SIGHUP, the other half; the recording holds both wells on /tdmon/well."""
    import signal
    import subprocess
    import sys
    import time

    volve = (ROOT / "config" / "wells" / "volve-f4.toml").read_text()
    survey = ROOT / "data" / "volve-f4" / "trajectory.csv"
    assert 'file = "../../data/volve-f4/trajectory.csv"' in volve
    assert 'length = "2574 m"' in volve
    well = tmp_path / "volve.toml"
    well.write_text(volve.replace('file = "../../data/volve-f4/trajectory.csv"',
                                  f'file = "{survey}"'))
    port = free_tcp_port()
    config = tmp_path / "daemon.toml"
    config.write_text(f"""
prefix = "rig/F4"
well = "{well}"
[sources.zenoh]
listen = ["tcp/127.0.0.1:{port}"]
[channels.hookload]
unit = "kN"
[rig_state]
in_slips_hookload = "800 kN"
[align]
stale_timeout = "30 s"            # rows 15 s apart
[recorder]
enabled = true
output = "{tmp_path / 'rec'}"
[publish]
zenoh = true
names = ["status"]
status_interval = "0.2 s"
""")
    parts = []
    for name, rows in (("first", (0, 50)), ("second", (50, 100))):
        part = tmp_path / f"{name}.csv"
        part.write_text(_volve_rows(*rows))
        parts.append(part)
    tdmon = [sys.executable, "-m", "tdmon"]
    import json

    import zenoh

    # the daemon's published status: how many samples it has counted (was: a 0.5 s pause)
    conf = zenoh.Config()
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    watch = zenoh.open(conf)
    status: dict[str, Any] = {}
    watch.declare_subscriber("rig/F4/tdmon/status",
                             lambda s: status.update(json.loads(s.payload.to_bytes())))
    log = tmp_path / "daemon.log"
    with log.open("w") as err:
        daemon = subprocess.Popen([*tdmon, "run", "--config", str(config)], stderr=err,
                                  stdout=subprocess.DEVNULL)
        try:
            _wait_for(log, "daemon running")
            for number, part in enumerate(parts):
                published = subprocess.run([*tdmon, "publish", str(part), "--config",
                                            str(config)], capture_output=True, text=True,
                                           timeout=60)
                assert published.returncode == 0, published.stderr
                if number == 0:
                    sent = int(published.stderr.split("published ")[1].split()[0])
                    deadline = time.monotonic() + 60
                    while status.get("samples_in", 0) < sent:  # the first half processed
                        assert time.monotonic() < deadline, f"counted {status}, sent {sent}"
                        time.sleep(0.05)
                    well.write_text(well.read_text().replace('length = "2574 m"',
                                                             'length = "2400 m"'))
                    daemon.send_signal(signal.SIGHUP)
                    _wait_for(log, "SIGHUP received")
            _wait_for(log, "reload (SIGHUP): well file")
            daemon.send_signal(signal.SIGINT)
            assert daemon.wait(30) == 0, log.read_text()
        finally:
            if daemon.poll() is None:
                daemon.kill()
            watch.close()
    assert "Traceback" not in log.read_text()
    [recording] = sorted((tmp_path / "rec").glob("*.mcap"))
    messages = list(read_messages(recording, ["/tdmon/well", "/tdmon/alarm"]))
    first, second = _of(messages, "/tdmon/well")
    assert first["change"] == "start" and first["string_length_m"] == pytest.approx(2574.0)
    assert second["change"] == "reload (SIGHUP)"
    assert second["string_length_m"] == pytest.approx(2400.0)
    assert second["file"] == "volve.toml" and second["md_m"] == first["md_m"]
    # the second half starts at 2475 m, 75 m below the new tally
    coverage = [a for a in _of(messages, "/tdmon/alarm") if a["kind"] == "model_coverage"]
    assert [a["severity"] for a in coverage] == ["info", "critical"]
    assert coverage[1]["message"].startswith("string tally 75.0 m shorter than bit depth "
                                             "2475.0 m")
