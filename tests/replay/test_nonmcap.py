"""``tdmon replay`` on something that is not a finished MCAP file: one line naming the file and
what it is, exit code 2, no output file; never a daemon retrying the source for ever."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tdmon.cli import main
from tdmon.record.mcap_recorder import McapRecorder
from tdmon.replay.driver import describe_start

from .conftest import REPO

CONFIG = REPO / "config" / "daemon" / "replay-sim-trip-in.toml"
REPLAY = REPO / "replays" / "trip-in-noisy.mcap"


def _unfinished(folder: Path) -> Path:
    """A real recording whose writer never finished it (its footer cut off)."""
    whole = folder / "whole.mcap"
    with McapRecorder(path=whole, background_flush=False) as recorder:
        for i in range(50):
            recorder.write("/tdmon/alarm", 1_700_000_000_000_000_000 + i,
                           {"t": 1.7e9 + i, "kind": "band", "severity": "info",
                            "message": str(i)})
    data = whole.read_bytes()
    cut = folder / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    return cut


def _cases(folder: Path) -> list[tuple[Path, list[str]]]:
    csv = folder / "f4.csv"
    csv.write_text("time,hookload_kN,torque_kNm,bit_depth_m\n2016-10-04T10:00:00Z,900,12,2000\n")
    empty = folder / "empty.mcap"
    empty.write_bytes(b"")
    binary = folder / "image.mcap"
    binary.write_bytes(bytes(range(200, 256)) * 4)
    return [
        (csv, ["not an MCAP file", "starts with 'time,hookload_kN", "tdmon import csv"]),
        (folder / "missing.mcap", ["replay not found", "no such file"]),
        (folder, ["is a folder, not an MCAP file"]),
        (empty, ["empty file (0 bytes)"]),
        (binary, ["not an MCAP file", "starts with bytes c8 c9 ca"]),
        (_unfinished(folder), ["unfinished MCAP file", "tdmon recover"]),
    ]


def test_cli_replay_refuses_what_is_not_a_finished_mcap(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    for path, wanted in _cases(inputs):
        out = tmp_path / "out.mcap"
        assert main(["replay", str(path), "--config", str(CONFIG), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"tdmon: error: {path}: "), err
        for text in wanted:
            assert text in err[0], (text, err[0])
        assert not out.exists(), f"{path.name}: an output was left"
        # the file is named before the configuration is looked at (none given here)
        assert main(["replay", str(path), "--out", str(out)]) == 2
        assert str(path) in capsys.readouterr().err


def test_replay_of_a_csv_exits_in_a_real_process(tmp_path: Path) -> None:
    """What the user saw hang: the CSV also given to `tdmon publish`, as a subprocess."""
    csv = tmp_path / "f4.csv"
    csv.write_text("time,hookload\n1,2\n")
    out = tmp_path / "out.mcap"
    done = subprocess.run([sys.executable, "-m", "tdmon", "replay", str(csv), "--config",
                           str(CONFIG), "--out", str(out)], capture_output=True, text=True,
                          timeout=120, cwd=REPO, check=False)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"tdmon: error: {csv}: not an MCAP file (starts with 'time,hookload...'); for CSV use "
        "`tdmon import csv` (or `tdmon import volve`) first"]
    assert not out.exists()


def test_a_finished_replay_passes_the_check(tmp_path: Path) -> None:
    from tdmon.replay.driver import check_replay_file

    check_replay_file(REPLAY)  # no exception


def test_describe_start() -> None:
    assert describe_start(b"time,hookload\n1,2\n") == "'time,hookload...'"
    assert describe_start(b"abc") == "'abc'"
    assert describe_start(b"\x00\x01\x02") == "bytes 00 01 02"
