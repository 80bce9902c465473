"""``tdmon run``'s status line: what it says (numbers of the messages it saw), how it prints
(in place on a terminal, lines otherwise), and a real daemon run printing it."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

from tdmon.cli.status import StatusLine

ROOT = Path(__file__).resolve().parents[2]


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _feed(status: StatusLine) -> None:
    status.write("/tdmon/state", 0, {"t": 1.0, "state": "pick_up", "bit_depth_m": 2450.25})
    status.write("/tdmon/estimate", 0, {"kind": "window", "operation": "pick_up", "mu": 0.2764,
                                        "mu_std": 0.0021})
    status.write("/tdmon/estimate", 0, {"kind": "profile", "operation": "pick_up", "mu": 0.9})
    status.write("/tdmon/alarm", 0, {"kind": "window_rejected", "severity": "info"})
    status.write("/tdmon/alarm", 0, {"kind": "friction_jump", "severity": "warning"})
    status.write("/tdmon/status", 0, {"samples_in": 90})


def test_status_says_rate_state_friction_and_alarms() -> None:
    status = StatusLine(10.0, stream=io.StringIO())
    assert "waiting for data" in status.line()
    _feed(status)
    start = status._rate_from[0]
    line = status.line(now=start + 4.0)
    # 90 samples in 4 s; the window estimate (not the profile) is the latest friction
    assert line.split(" | ")[1:] == [
        "22.5 samples/s", "pick_up at 2450.2 m", "mu pick_up 0.276 ± 0.002",
        "alarms 2, 1 warning or critical (last: warning friction_jump)"]
    # the next rate counts from this status on: no new sample, 0 per second
    assert "| 0.0 samples/s |" in status.line(now=start + 6.0)


def test_terminal_line_is_rewritten_and_a_file_gets_lines() -> None:
    terminal = _Terminal()
    status = StatusLine(10.0, stream=terminal)
    _feed(status)
    status.show()
    status.show()
    status.close()
    text = terminal.getvalue()
    assert text.count("\r") == 2 and text.count("\n") == 1 and text.endswith("\n")
    plain = io.StringIO()
    status = StatusLine(10.0, stream=plain)
    status.show()
    status.show()
    status.close()
    assert "\r" not in plain.getvalue() and plain.getvalue().count("\n") == 2


def test_tdmon_run_prints_status_lines(tmp_path: Path) -> None:
    config = tmp_path / "daemon.toml"
    config.write_text(f"""
prefix = "sim/trip-out"
well = "{ROOT / 'replays/scenarios/wells/example-7-1-glydril.toml'}"
[sources.mcap]
path = "{ROOT / 'replays/trip-out-tight-spot.mcap'}"
speed = "max"
[align]
stale_timeout = "20 s"
max_wait = "0.25 s"
[monitor]
method = "soft-string"
[calibration]
enabled = true
in_slips_margin = "150 kN"
""")
    done = subprocess.run([sys.executable, "-m", "tdmon", "run", "--config", str(config),
                           "--status-every", "0.5", "--log-level", "warning"],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path, check=False)
    assert done.returncode == 0, done.stderr
    lines = [x for x in done.stderr.splitlines() if "samples/s" in x]
    assert lines, done.stderr
    assert "\r" not in done.stderr  # not a terminal: plain lines
    # the last status, printed as the daemon stops: the rig state at the end of the trip
    # (3950 m), the latest window's friction and the replay's three alarms (two warnings:
    # the friction jump and the make-up torque; replays/expectations/trip-out-tight-spot.toml)
    assert re.fullmatch(r"tdmon: \d\d:\d\d:\d\d \| \d+\.\d samples/s \| \w+ at 3950\.0 m \| "
                        r"mu (pick_up|rotating) 0\.2\d\d ± 0\.0\d\d \| alarms 3, 2 warning or "
                        r"critical \(last: \w+ \w+\)", lines[-1]), lines
    assert done.stderr.splitlines()[-1].startswith("tdmon: stopped: ")
    quiet = subprocess.run([sys.executable, "-m", "tdmon", "run", "--config", str(config),
                            "--status-every", "0", "--log-level", "warning"],
                           capture_output=True, text=True, timeout=300, cwd=tmp_path,
                           check=False)
    assert quiet.returncode == 0 and "samples/s" not in quiet.stderr
