"""The daemon's well file (tdmon/config/well_file.py): read once into the validated file, the
model's well reaching the bottom of the hole, the tally and the digest a reload compares."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from tdmon.config.daemon import parse_daemon_config
from tdmon.config.well import WellConfig
from tdmon.config.well_file import read_well_file, read_well_path
from tdmon.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
WELL = ROOT / "replays" / "scenarios" / "wells" / "example-7-1-weights.toml"


def test_the_file_its_tally_and_its_digest() -> None:
    well_file = read_well_path(WELL)
    assert isinstance(well_file.config, WellConfig) and well_file.path == WELL
    assert well_file.digest == hashlib.sha256(WELL.read_bytes()).hexdigest()
    # 120 m of collars, 150 m of HWDP and 3330 m of drill pipe in the file; the model's string
    # reaches the bottom of the hole, the tally stays the file's
    assert well_file.tally_length == pytest.approx(3600.0)
    assert well_file.well.string.length == pytest.approx(well_file.well.hole_bottom)


def test_the_daemon_files_well(tmp_path: Path) -> None:
    base = {"prefix": "sim/x", "sources": {"mcap": {"path": "x.mcap"}}}
    assert read_well_file(parse_daemon_config(base, tmp_path / "daemon.toml")) is None
    copy = tmp_path / "well.toml"
    copy.write_bytes(WELL.read_bytes())
    config = parse_daemon_config({**base, "well": "well.toml"}, tmp_path / "daemon.toml")
    well_file = read_well_file(config)
    assert well_file is not None and well_file.path == copy  # relative to the daemon file
    assert well_file.digest == read_well_path(WELL).digest  # the same bytes


def test_a_broken_file_is_a_config_error(tmp_path: Path) -> None:
    broken = tmp_path / "broken.toml"
    broken.write_text("[well\n")
    with pytest.raises(ConfigError, match=r"broken\.toml"):
        read_well_path(broken)
