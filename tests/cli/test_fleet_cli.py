"""``tdmon fleet``: the board's rules, and a fleet topology of real processes on 127.0.0.1 (the
operations centre as a Zenoh router, three rig daemons as its clients, rig data from a
bundled replay)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

import pytest
import zenoh
from rerun.chunk import RrdReader

from tdmon.cli import main
from tdmon.daemon.fleet_board import FleetBoard, duration_text, render_table, split_key
from tdmon.ingest.publish import recording_messages
from tdmon.vocabulary import RigState

ROOT = Path(__file__).resolve().parents[2]
REPLAY = ROOT / "replays" / "drill-ream-stuck-torque.mcap"
RIG_CONFIG = ROOT / "config" / "daemon" / "replay-sim-drill.toml"
HOLD = 600.0


def _alarm(t: float, kind: str, severity: str = "warning") -> dict[str, Any]:
    return {"t": t, "kind": kind, "severity": severity, "message": kind, "value": None,
            "limit": None}


def test_keys_name_the_rig_and_the_result() -> None:
    assert split_key("rig/A/tdmon/state") == ("rig/A", "state")
    assert split_key("ops/north/rig7/tdmon/alarm") == ("ops/north/rig7", "alarm")
    assert split_key("rig/A/hookload") is None
    assert split_key("tdmon/state") is None


def test_durations_read_in_a_short_unit() -> None:
    assert [duration_text(s) for s in (0.5, 119.0, 150.0, 7300.0, 86_086_629.8)] == [
        "0.5 s", "119.0 s", "2.5 min", "2.0 h", "996.4 d"]


def test_the_board_keeps_state_friction_and_open_alarms() -> None:
    board = FleetBoard(hold=HOLD, stale=10.0)
    board.update("rig/A/tdmon/state", {"t": 1000.0, "state": "reaming", "steady": True,
                                       "bit_depth_m": 2500.0}, received=50.0)
    # a profile estimate stands in until a window estimate comes, then no longer wins
    board.update("rig/A/tdmon/estimate", {"t": 1001.0, "kind": "profile", "mu": 0.2,
                                          "mu_std": 0.05, "operation": "all"}, received=51.0)
    assert board.rigs["rig/A"].mu == 0.2
    board.update("rig/A/tdmon/estimate", {"t": 1002.0, "kind": "window", "mu": 0.27,
                                          "mu_std": 0.01, "operation": "reaming"}, received=52.0)
    board.update("rig/A/tdmon/estimate", {"t": 1003.0, "kind": "profile", "mu": 0.3,
                                          "mu_std": 0.05}, received=53.0)
    rig = board.rigs["rig/A"]
    assert (rig.mu, rig.mu_std, rig.operation) == (0.27, 0.01, "reaming")
    # open: warning or critical, the latest of its kind, within the hold of the newest result
    board.update("rig/A/tdmon/alarm", _alarm(1000.0, "band"), received=53.0)
    board.update("rig/A/tdmon/alarm", _alarm(1004.0, "sensor_stale", "critical"), received=54)
    board.update("rig/A/tdmon/alarm", _alarm(1004.0, "recording_recovered", "info"), 54.0)
    assert [a["kind"] for a in rig.open_alarms(HOLD)] == ["sensor_stale", "band"]
    board.update("rig/A/tdmon/alarm", _alarm(1005.0, "recorder_failed"), received=55.0)
    board.update("rig/A/tdmon/alarm", _alarm(1006.0, "recorder_resumed", "info"), 56.0)
    board.update("rig/A/tdmon/status", {"t": 9e9, "lag_s": 0.5, "samples_in": 10,
                                        "dropped": 0}, received=57.0)  # daemon's clock
    assert [a["kind"] for a in rig.open_alarms(HOLD)] == ["sensor_stale", "band"]
    board.update("rig/A/tdmon/state", {"t": 1000.0 + HOLD + 2.0, "state": "reaming",
                                       "steady": True, "bit_depth_m": 2500.0}, received=57.0)
    assert [a["kind"] for a in rig.open_alarms(HOLD)] == ["sensor_stale"]  # band too old
    board.update("rig/B/tdmon/model", {"t": 1.0}, received=57.0)  # not read by the board
    assert sorted(board.rigs) == ["rig/A"] and board.skipped == 1
    table = render_table(board, now=60.0).splitlines()
    assert table[0].split()[:2] == ["RIG", "STATE"]
    assert "reaming (steady)" in table[1] and "2,500.0 m" in table[1]
    assert "0.270 ± 0.010 reaming" in table[1] and "1: sensor_stale!" in table[1]
    assert table[1].endswith("0.5 s  3 s ago")  # the lag, then when the last result came
    assert "silent" in render_table(board, now=70.0).splitlines()[1]  # 13 s without results


def test_the_board_shows_no_prior_as_friction_and_dates_old_data() -> None:
    board = FleetBoard(hold=HOLD, stale=10.0)
    t = 1_709_251_200.0  # 2024-03-01 00:00 UTC
    prior = {"t": t, "kind": "profile", "mu": 0.25, "mu_std": 0.1,
             "informed": [False, False, False]}
    board.update("rig/A/tdmon/estimate", prior, received=1.0)
    rig = board.rigs["rig/A"]
    assert rig.mu is None  # every bin the prior: no friction to show
    board.update("rig/A/tdmon/estimate", {**prior, "t": t + 1, "mu": 0.21,
                                          "informed": [True, False, True]}, received=2.0)
    assert (rig.mu, rig.informed) == (0.21, (2, 3))
    # the rig's data are 996 days older than the centre's clock: a date, not a lag
    board.update("rig/A/tdmon/status", {"t": t + 86_086_630.0, "lag_s": 86_086_629.8},
                 received=3.0)
    cells = render_table(board, now=4.0).splitlines()[1]
    assert "0.210 ± 0.100 profile, 2/3 bins informed" in cells
    assert "data of 2024-03-01" in cells and " d " not in cells
    board.update("rig/A/tdmon/status", {"t": t + 2, "lag_s": 3600.0}, received=5.0)
    assert "60.0 min" in render_table(board, now=6.0)  # a real delay stays a duration


def test_fleet_needs_somewhere_to_listen_or_connect(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["fleet", "--once"]) == 2
    assert "--listen" in capsys.readouterr().err
    assert main(["fleet", "--connect", "127.0.0.1:7447", "--once"]) == 2
    assert "not a Zenoh endpoint" in capsys.readouterr().err


def test_once_prints_one_plain_table(capsys: pytest.CaptureFixture[str],
                                     free_tcp_port: Callable[[], int]) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    assert main(["fleet", "--listen", endpoint, "--once", "--duration", "0.3 s"]) == 0
    captured = capsys.readouterr()
    blocks = captured.out.strip().split("\n\n")
    assert len(blocks) == 1 and "\x1b" not in captured.out  # not a terminal: plain text
    lines = blocks[0].splitlines()
    assert lines[0].endswith("0 rigs") and lines[2] == "(no rig yet)"
    assert f"router on {endpoint}, watching rig/*/tdmon/**" in captured.err


def _rig_config(folder: Path, prefix: str, router: str) -> Path:
    """The bundled drill replay's daemon file, as a rig's daemon: a Zenoh client of the
    operations centre's router, publishing its results there."""
    text = RIG_CONFIG.read_text()
    head, _, rest = text.partition("[align]")
    well = (RIG_CONFIG.parent / "../../replays/scenarios/wells/example-7-1-glydril.toml").resolve()
    path = folder / f"{prefix.replace('/', '_')}.toml"
    path.write_text(f'prefix = "{prefix}"\nwell = "{well}"\n\n'
                    f'[sources.zenoh]\nmode = "client"\nconnect = ["{router}"]\n\n'
                    '[publish]\nzenoh = true\nstatus_interval = "0.5 s"\n\n[align]' + rest)
    assert "[sources.mcap]" in head  # what was replaced
    return path


def _tdmon(*args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "tdmon", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)


def _wait(predicate: Callable[[], bool], timeout: float, what: str,
          processes: list[subprocess.Popen[str]]) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        for process in processes:
            if process.poll() is not None:
                raise AssertionError(f"{process.args!r} ended ({process.returncode}) while "
                                     f"waiting for {what}: {process.stderr.read()[-2000:]}"
                                     if process.stderr else what)
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.05)


def _lines(stream: IO[str] | None) -> tuple[list[str], threading.Thread]:
    """The lines of a child's pipe as they come, read by a thread (ends at the pipe's end)."""
    assert stream is not None
    lines: list[str] = []

    def read() -> None:
        for line in stream:
            lines.append(line)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    return lines, reader


def _newest_cells(results: dict[str, list[dict[str, Any]]], rig: str) -> tuple[str, str]:
    """What ``rig``'s row shows of its newest messages: the rig state, the friction cell."""
    windows = [m for m in results[f"{rig}/tdmon/estimate"] if m["kind"] == "window"]
    assert windows, f"{rig} sent no friction estimate"
    state = RigState(results[f"{rig}/tdmon/state"][-1]["state"]).value
    return state, f"{windows[-1]['mu']:.3f} ± {windows[-1]['mu_std']:.3f}"


def _last_table_shows(out: list[str], cells: dict[str, tuple[str, str]]) -> bool:
    """Whether the last table drawn whole shows each rig's row with its cells."""
    drawn = "".join(out).split("\n\n")[:-1]  # the part after the last blank line is unfinished
    if not drawn:
        return False
    rows = {line.split()[0]: line for line in drawn[-1].splitlines()[2:] if line.strip()}
    return all(cell in rows.get(rig, "") for rig, row in cells.items() for cell in row)


def _friction_series(rrd: Path) -> dict[str, list[float]]:
    series: dict[str, list[float]] = defaultdict(list)
    for chunk in RrdReader(rrd).stream().to_chunks():
        batch = chunk.to_record_batch()
        if "Scalars:scalars" in batch.schema.names:
            series[chunk.entity_path] += [v[0] for v in
                                          batch.column("Scalars:scalars").to_pylist()]
    return dict(series)


def test_operations_centre_router_and_three_rig_daemons(
        tmp_path: Path, free_tcp_port: Callable[[], int]) -> None:
    router = f"tcp/127.0.0.1:{free_tcp_port()}"
    rigs = ["rig/r1", "rig/r2", "rig/r3"]
    rrd = tmp_path / "fleet.rrd"
    centre = _tdmon("fleet", "--listen", router, "--interval", "2 s", "--duration", "300 s",
                    "--rerun-file", str(rrd))
    centre_out, centre_reader = _lines(centre.stdout)
    centre_err, _ = _lines(centre.stderr)
    processes = [centre]
    results: dict[str, list[dict[str, Any]]] = defaultdict(list)
    session = None
    try:
        _wait(lambda: any("watching rig/*/tdmon/**" in line for line in centre_err), 60,
              "the operations centre", processes)
        daemons = [_tdmon("run", "--config", str(_rig_config(tmp_path, rig, router)),
                          "--log-level", "warning") for rig in rigs]
        processes += daemons
        conf = zenoh.Config()
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("connect/endpoints", json.dumps([router]))
        session = zenoh.open(conf)
        session.declare_subscriber(
            "rig/*/tdmon/**",
            lambda s: results[str(s.key_expr)].append(json.loads(s.payload.to_bytes())))
        _wait(lambda: all(results[f"{rig}/tdmon/status"] for rig in rigs), 120,
              "a status from every rig daemon", processes)
        # the daemons' subscriptions have reached the router (was: a 0.5 s pause)
        probes = [session.declare_publisher(f"{rig}/hookload") for rig in rigs]
        _wait(lambda: all(p.matching_status.matching for p in probes), 120,
              "the daemons' subscriptions", processes)
        for probe in probes:
            probe.undeclare()
        messages = list(recording_messages(REPLAY))
        block = zenoh.CongestionControl.BLOCK
        for rig in rigs:  # the rigs' data through the router, as their WITS gateways would
            for _, topic, body in messages:
                session.put(f"{rig}/{topic.rsplit('/', 1)[-1]}", body,
                            congestion_control=block)
        _wait(lambda: all(results[f"{rig}/tdmon/status"][-1]["samples_in"] == len(messages)
                          for rig in rigs), 240, "every rig's samples processed", processes)
        for daemon in daemons:
            daemon.send_signal(signal.SIGTERM)
        for daemon in daemons:
            assert daemon.wait(60) == 0
        # the centre has taken the daemons' last estimates and drawn them (was: a 2.5 s pause)
        last_cells = {rig: _newest_cells(results, rig) for rig in rigs}
        _wait(lambda: _last_table_shows(centre_out, last_cells), 120,
              "the centre's table of the rigs' last estimates", [centre])
        centre.send_signal(signal.SIGTERM)
        assert centre.wait(60) == 0, "".join(centre_err)
        centre_reader.join(60)
        out = "".join(centre_out)
    finally:
        if session is not None:
            session.close()
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
    last = out.strip().split("\n\n")[-1].splitlines()
    print("\n".join(last))  # with -s: the table docs/fleet.md shows
    assert last[0].startswith("tdmon fleet") and last[0].endswith("3 rigs")
    rows = {line.split()[0]: line for line in last[2:]}
    assert sorted(rows) == rigs
    series = _friction_series(rrd)
    for rig in rigs:
        windows = [m for m in results[f"{rig}/tdmon/estimate"] if m["kind"] == "window"]
        assert windows, f"{rig} sent no friction estimate"
        state = results[f"{rig}/tdmon/state"][-1]
        alarms = {m["kind"]: m for m in results[f"{rig}/tdmon/alarm"]}
        newest = max(m["t"] for name, found in results.items() if name.startswith(rig + "/")
                     and not name.endswith("/status") for m in found)
        open_kinds = {kind for kind, m in alarms.items()
                      if m["severity"] in ("warning", "critical") and newest - m["t"] <= HOLD}
        assert open_kinds, f"{rig}: the replay's stuck-torque alarm should be open"
        cells = rows[rig].split("  ")
        assert RigState(state["state"]).value in rows[rig]
        assert f"{windows[-1]['mu']:.3f} ± {windows[-1]['mu_std']:.3f}" in rows[rig]
        alarm_cell = next(cell for cell in cells if cell.strip().startswith(f"{len(open_kinds)}:"))
        assert {k.strip(" !") for k in alarm_cell.split(":", 1)[1].split(",")} == open_kinds
        assert series[f"/fleet/{rig}/friction"][-1] == pytest.approx(windows[-1]["mu"])
