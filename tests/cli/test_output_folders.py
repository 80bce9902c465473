"""Every command that writes a file creates its missing parent folders (and says so in one
line when it cannot)."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from tdmon.cli import main

ROOT = Path(__file__).resolve().parents[2]
WELL = ROOT / "config" / "wells" / "aadnoy-example-7-1.toml"


def test_missing_folders_are_created(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "a" / "b" / "broom.png"
    table = tmp_path / "c" / "d" / "broom.csv"
    temperature = tmp_path / "e" / "temperature.png"
    recovered = tmp_path / "f" / "g" / "copy.mcap"
    assert main(["model", "broomstick", "--well", str(WELL), "--mu", "0.2,0.3",
                 "--png", str(png)]) == 0
    assert main(["model", "broomstick", "--well", str(WELL), "--mu", "0.2,0.3",
                 "--csv", str(table)]) == 0
    assert main(["model", "temperature", "--well",
                 str(ROOT / "config" / "wells" / "thesis-case2-apak.toml"),
                 "--png", str(temperature)]) == 0
    capsys.readouterr()
    assert png.read_bytes()[:8] == temperature.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with table.open() as handle:
        header = next(csv.reader(handle))
    assert "pick_up_hookload_N_mu0.2" in header and "pick_up_hookload_N_mu0.3" in header
    # recover --out of a killed (footer-less) recording: a copy in a new folder
    source = ROOT / "replays" / "trip-in-noisy.mcap"
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(source.read_bytes()[: source.stat().st_size // 2])
    assert main(["recover", str(cut), "--out", str(recovered)]) == 0
    assert recovered.stat().st_size > 0


def test_a_folder_that_cannot_be_made_is_one_line(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert main(["model", "broomstick", "--well", str(WELL), "--mu", "0.2",
                 "--csv", str(blocker / "x.csv")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"tdmon: error: --csv: cannot create the folder of {blocker / 'x.csv'}: "
                   "File exists"]
