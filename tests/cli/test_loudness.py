"""``tdmon -q`` and ``tdmon -v`` (issue 33, item 8): one pair of options for every command.

The daemon runs the bundled noisy trip in from its MCAP source (flat out, it stops by itself:
965 samples), as a user runs it; what it writes on stderr is compared.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "config" / "daemon" / "replay-sim-trip-in.toml"
REPLAY = ROOT / "replays" / "trip-in-noisy.mcap"
STOPPED = "tdmon: stopped: 965 samples, 0 rejected"


def _tdmon(*args: str, cwd: Path = ROOT) -> tuple[int, str, str]:
    done = subprocess.run([sys.executable, "-m", "tdmon", *args], capture_output=True,
                          text=True, timeout=300, cwd=cwd,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    return done.returncode, done.stdout, done.stderr


def _levels(stderr: str) -> set[str]:
    """The levels of the log lines (``2026-... INFO tdmon.x: ...``)."""
    return {line.split()[2] for line in stderr.splitlines()
            if line[:2] == "20" and len(line.split()) > 3}


def test_run_logs_info_and_status_by_default_none_with_q_debug_with_v() -> None:
    code, _, default = _tdmon("run", "--config", str(CONFIG))
    assert code == 0 and STOPPED in default
    assert _levels(default) == {"INFO"}
    assert "tdmon daemon running" in default and "samples/s" in default  # the status line

    code, _, quiet = _tdmon("-q", "run", "--config", str(CONFIG))
    assert code == 0
    # the summary is a result, not a log line: it stays; nothing else
    assert quiet.splitlines() == [line for line in default.splitlines()
                                  if line.startswith("tdmon: stopped:")]

    code, _, verbose = _tdmon("-v", "run", "--config", str(CONFIG), "--log-level", "error")
    assert code == 0 and STOPPED in verbose
    # -v is over --log-level: info and (of tdmon's loggers only) debug may show
    assert "INFO" in _levels(verbose) and _levels(verbose) <= {"INFO", "DEBUG", "WARNING"}
    assert not any(" DEBUG asyncio" in line for line in verbose.splitlines())


def test_v_shows_a_replays_info_log_that_is_otherwise_silent(tmp_path: Path) -> None:
    args = ("replay", str(REPLAY), "--config", str(CONFIG), "--out", str(tmp_path / "o.mcap"))
    code, _, plain = _tdmon(*args)
    assert code == 0 and "load model for" not in plain
    code, _, verbose = _tdmon("-v", *args)
    assert code == 0
    assert any(" INFO tdmon.daemon.wellmodel: load model for " in line
               for line in verbose.splitlines())


@pytest.mark.parametrize("args", [["-q", "-v", "model", "loads"], ["model", "-q", "loads"]])
def test_q_and_v_go_before_the_command_and_not_together(args: list[str]) -> None:
    code, _, err = _tdmon(*args)
    assert code == 2 and len(err.splitlines()) == 1
