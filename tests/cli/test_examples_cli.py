"""``tdmon examples DIR`` (issue 33, item 3): the example files reachable from an installed
tdmon, copied out with the checkout's layout so that the README's commands run from there.

From a checkout ``tdmon/examples/`` links to ``config/``, ``data/`` and ``replays/``; a wheel
carries their files as package data (CI's wheel check installs one in a fresh environment and
runs the README's quick start from the copied folder: docs/ci.md).
"""

from __future__ import annotations

import glob
import json
import tomllib
from pathlib import Path

import pytest

import tdmon.cli.examples as examples
from tdmon.cli import main
from tdmon.config.daemon import load_daemon_config

REPO = Path(__file__).resolve().parents[2]
FOLDERS = ("config", "data", "replays")


def _checkout_files() -> dict[str, bytes]:
    return {path.relative_to(REPO).as_posix(): path.read_bytes()
            for folder in FOLDERS for path in (REPO / folder).rglob("*") if path.is_file()}


def test_every_example_file_is_copied_as_it_is(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "tdmon-examples"
    assert main(["examples", str(target)]) == 0
    copied = {path.relative_to(target).as_posix(): path.read_bytes()
              for path in target.rglob("*") if path.is_file()}
    checkout = _checkout_files()
    assert copied == checkout
    assert {"config/wells/aadnoy-example-7-1.toml", "config/daemon/zenoh-local.toml",
            "data/volve-f4/trip-out-2016-10-04.csv", "replays/trip-out-tight-spot.mcap",
            "replays/expectations/trip-out-tight-spot.toml"} <= set(copied)
    out = capsys.readouterr().out
    assert out.startswith(f"{target}: {len(checkout)} example files, ")
    replays = sum(1 for path in checkout if path.startswith("replays/"))
    assert f"  replays/  {replays:3d} files: recordings, scenarios, expectations" in out


def test_the_copy_keeps_the_relative_paths_between_the_files(tmp_path: Path) -> None:
    target = tmp_path / "ex"
    assert main(["examples", str(target)]) == 0
    config = load_daemon_config(target / "config" / "daemon" / "zenoh-local.toml")
    assert config.well is not None
    assert config.resolve(config.well).resolve() == (
        target / "config/wells/volve-f4.toml").resolve()
    expectation = tomllib.loads(
        (target / "replays/expectations/trip-out-tight-spot.toml").read_text())
    daemon_file = (target / "replays/expectations" / expectation["config"]).resolve()
    assert daemon_file.is_file() and daemon_file.is_relative_to(target.resolve())


def test_a_model_command_runs_from_the_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "ex"
    assert main(["examples", str(target)]) == 0
    monkeypatch.chdir(target)
    capsys.readouterr()
    assert main(["model", "loads", "--well", "config/wells/aadnoy-example-7-1.toml",
                 "--mu", "0.15", "--method", "aadnoy", "--json"]) == 0
    loads = json.loads(capsys.readouterr().out)
    # the thesis's Example 7.1 at mu 0.15 (docs/reference-values.md): pick-up 1486.5 kN
    assert loads["hookload_N"]["pick_up"] == pytest.approx(1486.5e3, abs=100)


def test_files_of_other_contents_are_not_overwritten_without_force(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "ex"
    assert main(["examples", str(target)]) == 0
    capsys.readouterr()
    assert main(["examples", str(target)]) == 0  # again: nothing to do
    assert f"({len(_checkout_files())} already there)" in capsys.readouterr().out
    edited = target / "config" / "daemon" / "zenoh-local.toml"
    edited.write_text("# mine\n")
    (target / "data" / "lab" / "glydril-tribometer.csv").write_text("mine\n")
    capsys.readouterr()
    assert main(["examples", str(target)]) == 2
    err = capsys.readouterr().err
    assert "already there with other contents: give --force" in err
    assert "and 1 more" in err
    assert edited.read_text() == "# mine\n"
    assert main(["examples", str(target), "--force"]) == 0
    assert edited.read_bytes() == (REPO / "config/daemon/zenoh-local.toml").read_bytes()


def test_an_installation_without_example_files_says_so(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "package").mkdir()
    monkeypatch.setattr(examples, "files", lambda name: tmp_path / "package")
    assert main(["examples", str(tmp_path / "ex")]) == 2
    assert "has no example files" in capsys.readouterr().err
    assert not (tmp_path / "ex").exists()


def test_the_wheel_takes_every_example_file() -> None:
    # pyproject.toml's package data, globbed as setuptools globs it, from tdmon/
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    patterns = project["tool"]["setuptools"]["package-data"]["tdmon"]
    packaged = {path for pattern in patterns if pattern.startswith("examples/")
                for path in glob.glob(pattern, root_dir=REPO / "tdmon", recursive=True)
                if (REPO / "tdmon" / path).is_file()}
    assert {path.removeprefix("examples/") for path in packaged} == set(_checkout_files())
    assert set(examples.example_files()) == set(_checkout_files())
